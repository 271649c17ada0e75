"""Run logs (`eval table --record-dir`, docs/logs.md) for the plotting scripts: MCAP files of JSON
messages, each stamped in its `header.stamp_ns`. One reader for the scripts that draw from them
and one writer for their tests, which make small logs of the same format. Needs mcap
(scripts/setup.sh installs it).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from pathlib import Path


def messages(path: Path, topics: list[str]) -> Iterator[tuple[str, float, dict]]:
    """(topic, stamp in s, message) of `topics` in `path`, in the log's order."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(topics=topics):
            d = json.loads(message.data)
            yield channel.topic, d["header"]["stamp_ns"] / 1e9, d


def write(path: Path, channels: dict[str, str], records: Iterable[tuple[str, dict]]) -> None:
    """A log at `path` with `channels` (topic: schema name) and `records` (topic, message), each
    message stamped by its `header.stamp_ns`, in the order given."""
    from mcap.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        ids = {}
        for topic, schema in channels.items():
            schema_id = w.register_schema(name=schema, encoding="jsonschema", data=b"{}")
            ids[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
        for topic, message in records:
            stamp = message["header"]["stamp_ns"]
            w.add_message(ids[topic], log_time=stamp, publish_time=stamp, data=json.dumps(message).encode())
        w.finish()

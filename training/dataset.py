"""Reader of the demonstrations `eval record` writes (format: training/DATASET.md).

    import dataset
    d = dataset.load("data/demos")
    d.index["dataset_id"], len(d)
    d.fields["camera"]          # list of memory-mapped arrays, one per shard (N_i x H x W x 3)
    d.field("label")            # one array, concatenated (copies; fine for the small fields)
    d.sample(1234)              # dict of one sample's values

Nothing is read into memory until it is used: every shard file is opened with
`np.load(..., mmap_mode="r")`.

    python training/dataset.py DIR     # prints a summary
"""

from __future__ import annotations

import bisect
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

FORMAT = "intention-fleet-demonstrations"
VERSION = 1


@dataclass
class Dataset:
    root: Path
    index: dict
    # field name -> one memory-mapped array per shard
    fields: dict[str, list[np.ndarray]] = field(default_factory=dict)
    # cumulative sample counts: offsets[i] is the first sample of shard i
    offsets: list[int] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.index["samples"])

    def field(self, name: str) -> np.ndarray:
        """All shards of one field concatenated (a copy in memory)."""
        parts = self.fields[name]
        return np.concatenate(parts) if len(parts) > 1 else np.asarray(parts[0])

    def sample(self, i: int) -> dict[str, np.ndarray]:
        """Sample `i` (0 <= i < len) from every field, read from the maps."""
        if not 0 <= i < len(self):
            raise IndexError(f"sample {i} of {len(self)}")
        shard = bisect.bisect_right(self.offsets, i) - 1
        k = i - self.offsets[shard]
        return {name: arrays[shard][k] for name, arrays in self.fields.items()}


def parse_source(source: str | Path) -> tuple[Path, float]:
    """`DIR` or `DIR@FRACTION`: a recording, or an evenly spaced share of its shards (whole
    shards, so episodes stay whole but for the two at a cut). A share keeps several recordings
    in memory together (training preloads the images) and keeps the mix between them chosen."""
    text = str(source)
    head, sep, tail = text.rpartition("@")
    if not sep:
        return Path(text), 1.0
    try:
        fraction = float(tail)
    except ValueError:
        raise ValueError(f"{text}: the share after '@' must be a number in (0, 1], not {tail!r}") from None
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"{text}: the share after '@' must be in (0, 1], not {fraction}")
    return Path(head), fraction


def shard_share(count: int, fraction: float) -> list[int]:
    """Indices of an evenly spaced `fraction` of `count` shards (at least one)."""
    chosen = [k for k in range(count) if int((k + 1) * fraction) > int(k * fraction)]
    return chosen or [count - 1]


def load(source: str | Path) -> Dataset:
    """Opens a recording (`DIR`, or `DIR@FRACTION` for a share of its shards, see
    `parse_source`): index.json and every chosen shard's arrays, memory-mapped and checked
    against the index (count, dtype, shape)."""
    root, fraction = parse_source(source)
    index = json.loads((root / "index.json").read_text())
    if index.get("format") != FORMAT or index.get("version") != VERSION:
        raise ValueError(
            f"{root}: not a {FORMAT} v{VERSION} dataset "
            f"(format {index.get('format')!r}, version {index.get('version')!r})"
        )
    if fraction < 1.0:
        # The share is a dataset of its own: its id says so, and its count is what it holds.
        shards = [index["shards"][k] for k in shard_share(len(index["shards"]), fraction)]
        index = {**index, "shards": shards, "samples": sum(int(s["samples"]) for s in shards),
                 "dataset_id": f"{index['dataset_id']}@{fraction:g}", "shard_fraction": fraction}
    ds = Dataset(root=root, index=index)
    start = 0
    for shard in index["shards"]:
        ds.offsets.append(start)
        n = int(shard["samples"])
        for name, spec in index["fields"].items():
            a = np.load(root / shard["files"][name], mmap_mode="r")
            want = (n, *spec["shape"])
            if a.dtype != np.dtype(spec["dtype"]) or a.shape != want:
                raise ValueError(
                    f"{root / shard['files'][name]}: {a.dtype}{a.shape}, "
                    f"index says {spec['dtype']}{want}"
                )
            ds.fields.setdefault(name, []).append(a)
        start += n
    if start != len(ds):
        raise ValueError(f"{root}: shards hold {start} samples, index says {len(ds)}")
    return ds


def summary(ds: Dataset) -> str:
    ix = ds.index
    lines = [
        f"dataset {ix['dataset_id']} in {ds.root}: {len(ds)} samples in {len(ix['shards'])} shards, "
        f"images {ix['image_px']} px, seed {ix['seed']}, noise {ix['noise']}",
        f"  command: {ix.get('command', '')}",
    ]
    if len(ds) == 0:
        return "\n".join(lines)
    label = ds.field("label")
    executed = ds.field("executed")
    dlm = ds.field("dlm")
    scenario = ds.field("scenario")
    episode = ds.field("episode")
    noisy = ds.field("noisy").astype(bool)
    names = [s["name"] for s in ix["scenarios"]]
    lines.append(f"  episodes: {len(np.unique(episode))}, noisy samples: {noisy.mean():.1%}")
    counts = np.bincount(scenario, minlength=len(names))
    lines.append("  per scenario: " + ", ".join(f"{n} {c}" for n, c in zip(names, counts)))
    dcounts = np.bincount(dlm, minlength=4)
    lines.append("  per DLM: " + ", ".join(f"{n} {c}" for n, c in zip(ix["dlm"], dcounts)))
    lines.append(
        f"  label v: mean {label[:, 0].mean():+.3f} std {label[:, 0].std():.3f}; "
        f"omega: mean {label[:, 1].mean():+.3f} std {label[:, 1].std():.3f}"
    )
    if "target" in ds.fields:
        target = ds.field("target")
        lines.append(
            f"  target v: mean {target[:, 0].mean():+.3f}; above the label v by 0.2 or more in "
            f"{(target[:, 0] >= label[:, 0] + 0.2).mean():.1%} of the samples (setting off)"
        )
    perturbed = np.abs(executed[:, 1] - label[:, 1]) > 1e-6
    lines.append(f"  samples whose executed command differs from the label: {perturbed.sum()}")
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(f"usage: {sys.argv[0]} DIR")
    print(summary(load(sys.argv[1])))

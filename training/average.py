"""Averages the weights of exported models of one lineage into one model, with its card.

    python -m training.average --model models/lpe.onnx:0.5 --model out/models-g3/lpe.onnx:0.5 \\
        --out out/models-s1/lpe.onnx [--card-json out/models-s1/lpe.card.json] [--closed-loop T.json]

Fine-tuning a network on a few rounds of new data can pull it away from what it learned on the
rounds before (docs/evaluation.md, rounds 7 and 11); averaging the weights of the model before
and after the fine-tune (WiSE-FT, Wortsman et al., CVPR 2022; "model soups", ICML 2022) often
keeps what each got right. It only works between models of one lineage (one warm-started from
the other), whose weights lie in one basin; the closed-loop table decides whether it did.

`--keep-first PREFIX` (repeatable) leaves the initializers under a name prefix as the first
model's, e.g. `heads.0` and `heads.1`, a DLM-Net's `turn_left` and `turn_right` heads (round 54:
to tell whether what a fine-tune broke lives in those heads or in the shared layers).

The average is taken over the ONNX initializers as exported, with batch norms folded into the
convolutions: a weighted mean of each member's folded weights. That is a model of its own, not
the fold of averaged unfolded weights, and it is what the table measured and what ships.

* inputs: two or more models with the same graph (the same nodes in the same order, the same
  initializer names, shapes and types) and the same card for every key the agent reads except
  `dataset_id` and `validation_loss`; weights >= 0, normalised to sum 1 (default: equal);
* card: the first model's agent keys; `dataset_id` joins the members' ids; `validation_loss` is
  the weighted mean of the members' (each on its own split: the average was not validated on
  recorded frames, its closed-loop table is the judge, `--closed-loop`); `averaged_from` lists
  each member's file, SHA-256, weight, dataset id and recipe; `deviations` the first member's
  plus the averaging;
* checks, failing loudly: the card passes the agent's rules; the graph's inputs and outputs
  match the card; onnxruntime runs it; the file is at most 20 MB; it is written atomically.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnx import numpy_helper

from training import card as card_mod
from training import data
from training.card import closed_loop_summary
from training.export import check_contract

MAX_MB = 20.0
# Keys that differ between members by nature: joined or averaged instead of compared.
MERGED = ("dataset_id", "validation_loss")


class AverageError(SystemExit):
    """A member that cannot be averaged with the others, or a bad weight (the message says which)."""


def parse_member(text: str) -> tuple[Path, float | None]:
    """`PATH` or `PATH:WEIGHT`."""
    path, sep, weight = text.rpartition(":")
    if sep and path and not weight.startswith(("/", "\\")):
        try:
            return Path(path), float(weight)
        except ValueError:
            pass
    return Path(text), None


def card_of(proto: onnx.ModelProto) -> dict[str, str]:
    return {p.key: p.value for p in proto.metadata_props}


def agent_keys(card: dict[str, str]) -> list[str]:
    """The keys the agent reads that every member must share."""
    keys = [k for k in card_mod.REQUIRED if k not in MERGED]
    keys += [k for k in ("lpe_rendering", "lpe_image_px", "dlm_measure", "dlm_params") if k in card]
    return keys


def agent_value(card: dict[str, str], key: str):
    """What the agent (and the planner) read from `key`: the DLM parameters as parameters, those the
    planner gained after a card was written at their "as before" value, so a card that spells one
    out at that value reads as one that does not."""
    value = card.get(key)
    if key == "dlm_params" and value is not None:
        return data.with_added(json.loads(value))
    return value


def same_graph(a: onnx.ModelProto, b: onnx.ModelProto, name_b: str) -> None:
    """Raises AverageError naming the first difference between the two graphs."""
    na, nb = a.graph.node, b.graph.node
    if len(na) != len(nb):
        raise AverageError(f"average: {name_b} has {len(nb)} graph nodes, the first model {len(na)}")
    for i, (x, y) in enumerate(zip(na, nb)):
        if (x.op_type, list(x.input), list(x.output)) != (y.op_type, list(y.input), list(y.output)):
            raise AverageError(f"average: {name_b}'s node {i} is {y.op_type}{list(y.input)}, "
                               f"the first model's {x.op_type}{list(x.input)}")
    ia = {t.name: t for t in a.graph.initializer}
    ib = {t.name: t for t in b.graph.initializer}
    if sorted(ia) != sorted(ib):
        only = sorted(set(ia) ^ set(ib))[:3]
        raise AverageError(f"average: {name_b}'s initializers differ from the first model's (e.g. {only})")
    for k, t in ia.items():
        u = ib[k]
        if (list(t.dims), t.data_type) != (list(u.dims), u.data_type):
            raise AverageError(f"average: initializer {k} is {list(u.dims)} in {name_b}, {list(t.dims)} in the first model")


def kept(name: str, keep_first: list[str]) -> bool:
    """Whether initializer `name` lies under one of the `keep_first` prefixes (`heads.0` keeps
    `heads.0.0.weight`, not `heads.01...`)."""
    return any(name == k or name.startswith(k + ".") for k in keep_first)


def average(members: list[tuple[Path, float | None]], out: Path, card_json: Path | None = None,
            closed_loop: list[str | Path] | None = None, max_mb: float = MAX_MB,
            keep_first: list[str] | None = None) -> dict[str, str]:
    """Averages, checks and writes `out`; returns the card. Initializers under a `keep_first`
    prefix are the first member's, not averaged."""
    keep_first = list(keep_first or [])
    if len(members) < 2:
        raise AverageError("average: give at least two --model")
    given = [w for _, w in members]
    if all(w is None for w in given):
        weights = np.full(len(members), 1.0 / len(members))
    elif any(w is None for w in given):
        raise AverageError("average: give a weight to every --model (PATH:WEIGHT) or to none")
    else:
        weights = np.array(given, dtype=np.float64)
        bad = [(str(p), w) for (p, _), w in zip(members, weights) if not (np.isfinite(w) and w >= 0)]
        if bad:
            raise AverageError(f"average: weight {bad[0][1]} of {bad[0][0]} must be a number >= 0")
        if weights.sum() <= 0:
            raise AverageError("average: the weights sum to 0")
        weights = weights / weights.sum()

    protos, cards, blobs = [], [], []
    for path, _ in members:
        if not path.is_file():
            raise AverageError(f"average: --model {path}: no such file")
        blob = path.read_bytes()
        proto = onnx.load_from_string(blob)
        card = card_of(proto)
        try:
            card_mod.check(card)
        except ValueError as e:
            raise AverageError(f"average: {path}: {e}") from None
        protos.append(proto)
        cards.append(card)
        blobs.append(blob)
    first, first_card = protos[0], cards[0]
    for (path, _), proto, card in zip(members[1:], protos[1:], cards[1:]):
        same_graph(first, proto, str(path))
        for key in agent_keys(first_card):
            if agent_value(card, key) != agent_value(first_card, key):
                raise AverageError(f"average: card key {key} is {card.get(key)!r} in {path}, "
                                   f"{first_card.get(key)!r} in {members[0][0]}")

    names = [t.name for t in first.graph.initializer]
    for k in keep_first:
        if not any(kept(n, [k]) for n in names):
            raise AverageError(f"average: --keep-first {k}: no initializer of {members[0][0]} lies under it "
                               f"(e.g. {', '.join(names[:4])})")
    arrays = [{t.name: numpy_helper.to_array(t) for t in p.graph.initializer} for p in protos]
    merged = onnx.ModelProto()
    merged.CopyFrom(first)
    for t in merged.graph.initializer:
        if kept(t.name, keep_first):
            continue
        values = [a[t.name] for a in arrays]
        if values[0].dtype.kind == "f":
            mean = np.tensordot(weights, np.stack(values).astype(np.float64), axes=1)
            t.CopyFrom(numpy_helper.from_array(mean.astype(values[0].dtype), t.name))
        elif any(not np.array_equal(v, values[0]) for v in values[1:]):
            # Integer initializers are shapes and indices: they must agree, not be averaged.
            raise AverageError(f"average: integer initializer {t.name} differs between the models")

    ids: list[str] = []
    for c in cards:
        ids += [i for i in c["dataset_id"].split("+") if i not in ids]
    card = {k: first_card[k] for k in agent_keys(first_card)}
    card["dataset_id"] = "+".join(ids)
    card["validation_loss"] = repr(float(sum(w * float(c["validation_loss"]) for w, c in zip(weights, cards))))
    card["validation_loss_definition"] = (
        "weighted mean of the averaged models' validation losses, each on its own split; the average itself "
        "was not validated on recorded frames (closed_loop is the judge)")
    card["averaged_from"] = json.dumps([
        {"file": str(path), "sha256": hashlib.sha256(blob).hexdigest(), "weight": round(float(w), 6),
         "dataset_id": c["dataset_id"], "recipe": c.get("recipe"), "samples_seen": c.get("samples_seen"),
         "validation_loss": c["validation_loss"]}
        for (path, _), blob, w, c in zip(members, blobs, weights, cards)
    ], separators=(",", ":"))
    # The recipe of an average is the averaging; each member's own recipe stays beside it.
    card["recipe"] = json.dumps({
        "method": "weighted mean of the initializers of exported models of one lineage (WiSE-FT)",
        "weights": [round(float(w), 6) for w in weights],
        **({"kept_from_first": keep_first} if keep_first else {}),
        "member_recipes": [json.loads(c["recipe"]) if c.get("recipe") else None for c in cards],
    }, separators=(",", ":"), sort_keys=True)
    note = (f"weights: the weighted mean of {len(members)} exported models of one lineage "
            f"({', '.join(f'{float(w):g}' for w in weights)}; WiSE-FT), batch norms folded before averaging"
            + (f"; the initializers under {', '.join(keep_first)} are the first model's" if keep_first else ""))
    card["deviations"] = "; ".join(x for x in (first_card.get("deviations"), note) if x)
    if "parameters" in first_card:
        card["parameters"] = first_card["parameters"]
    if closed_loop:
        card["closed_loop"] = closed_loop_summary(closed_loop, card["kind"])
    card["producer"] = "intention-fleet training/average.py"
    card_mod.check(card)

    del merged.metadata_props[:]
    onnx.helper.set_model_props(merged, card)
    merged.producer_name = "intention-fleet training/average.py"
    onnx.checker.check_model(merged, full_check=True)
    blob = merged.SerializeToString()
    size_mb = len(blob) / 1e6
    if size_mb > max_mb:
        raise AverageError(f"average: {size_mb:.1f} MB exceeds {max_mb:g} MB; {out} not written")
    sess = ort.InferenceSession(blob, providers=["CPUExecutionProvider"])
    check_contract(sess, card)
    rng = np.random.default_rng(0)
    feeds = {i.name: rng.normal(0, 1, [2 if not isinstance(d, int) else d for d in i.shape]).astype(np.float32)
             for i in sess.get_inputs()}
    control = sess.run(["control"], feeds)[0]
    if not np.all(np.isfinite(control)):
        raise AverageError("average: the averaged model computes non-finite controls")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".onnx.tmp")
    tmp.write_bytes(blob)
    tmp.replace(out)
    if card_json is not None:
        record = dict(card, onnx_mb=f"{size_mb:.3f}")
        tmp = card_json.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
        tmp.replace(card_json)
    print(f"average: {out} ({size_mb:.2f} MB, kind {card['kind']}) from "
          + ", ".join(f"{p} x {float(w):g}" for (p, _), w in zip(members, weights)))
    return card


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.average", description=__doc__.splitlines()[0])
    p.add_argument("--model", action="append", required=True, metavar="ONNX[:WEIGHT]",
                   help="a member (repeat; weights default to equal and are normalised to sum 1)")
    p.add_argument("--out", required=True, help="the .onnx file to write")
    p.add_argument("--card-json", help="also write the card as JSON here")
    p.add_argument("--closed-loop", nargs="+", metavar="TABLE_JSON",
                   help="eval table results (table.json) whose rows for this network go into the card's closed_loop")
    p.add_argument("--max-mb", type=float, default=MAX_MB, help="refuse a larger model (default %(default)s)")
    p.add_argument("--keep-first", action="append", metavar="PREFIX",
                   help="initializers under this name prefix are the first model's, not averaged (repeat; e.g. "
                        "heads.0 and heads.1, DLM-Net's turn_left and turn_right heads, training/data.py DLM_NAMES)")
    args = p.parse_args(argv)
    average([parse_member(m) for m in args.model], Path(args.out),
            Path(args.card_json) if args.card_json else None, args.closed_loop, args.max_mb, args.keep_first)
    return 0


if __name__ == "__main__":
    sys.exit(main())

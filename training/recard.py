"""Puts a newer closed-loop record into a shipped model's card, leaving the network untouched.

    python -m training.recard --model models/dlm.onnx --card-json models/dlm.card.json \
        --closed-loop out/t20/table.json out/beh/table.json \
        --commands "eval table --methods dlm --seeds 20 ..." "eval table --behaviour ..."

A card's `closed_loop` (the network's rows of `eval table`) goes stale when the agent's rules
round a network change (a rotation shim, a recovery) and the table is run again: the weights
are the same, the figures are not. Re-exporting needs the training checkpoint, which stays on
the machine that trained; this rewrites only the ONNX metadata_props key `closed_loop`, and the
same key in the card JSON beside the model (with `--drive-dlm-params`, `dlm_params` and
`dlm_params_trained` too: a planner rule the network is driven on, its weights untouched).

Checked, failing loudly, before anything is written: the model's card and the JSON agree on
every key but `closed_loop` (the JSON also carries the export check's `onnx_*` keys, of which
`onnx_mb`, the file's size, follows the longer or shorter card); the new
card passes the agent's rules (card.py); the rewritten graph is byte for byte the old one
(initializers, nodes, inputs, outputs); onnxruntime reads back the new card. Both files are
written atomically (a temporary file renamed over the old one), the model first.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import onnx
import onnxruntime as ort

from training import card as card_mod
from training.card import closed_loop_summary

# Keys the export writes into the card JSON only: the result of its check against onnxruntime.
JSON_ONLY = ("onnx_max_abs_diff", "onnx_check_inputs", "onnx_mb")


def card_of(proto: onnx.ModelProto) -> dict[str, str]:
    return {p.key: p.value for p in proto.metadata_props}


def write_atomically(path: Path, blob: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(blob)
    tmp.replace(path)


def recard(model: Path, card_json: Path | None, tables: list[str | Path],
           commands: list[str] | None = None, drive_dlm_params: dict | None = None) -> dict[str, str]:
    """Rewrites `closed_loop` in `model` (and `card_json`), and with `drive_dlm_params` the DLM
    parameters a DLM-Net is driven on (`dlm_params`; export's `--drive-dlm-params`, the
    parameters it was trained on kept as `dlm_params_trained`); returns the new card."""
    proto = onnx.load(str(model))
    card = card_of(proto)
    kind = card.get("kind")
    if kind not in ("dlm", "lpe", "none"):
        raise SystemExit(f"{model}: card kind {kind!r} is not a network's (dlm, lpe or none)")
    recorded = None
    if card_json is not None:
        recorded = json.loads(card_json.read_text())
        differ = sorted(k for k in set(card) | (set(recorded) - set(JSON_ONLY))
                        if k != "closed_loop" and card.get(k) != recorded.get(k))
        if differ:
            raise SystemExit(f"{card_json} is not the card of {model}: they differ on {', '.join(differ)}")
    new = dict(card, closed_loop=closed_loop_summary(tables, kind, commands))
    if drive_dlm_params:
        # Here only: the export brings torch with it, which the plain recard does not need.
        from training.export import drive_dlm_with
        trained = card.get("dlm_params_trained")
        drive_dlm_with(new, drive_dlm_params)
        if trained is not None:
            # Driven on other parameters before: what the labels were derived with stays.
            new["dlm_params_trained"] = trained
    changed = ("closed_loop", "dlm_params", "dlm_params_trained")
    try:
        card_mod.check(new)
    except ValueError as e:
        raise SystemExit(f"{model}: {e}") from e

    graph_before = proto.graph.SerializeToString(deterministic=True)
    del proto.metadata_props[:]
    onnx.helper.set_model_props(proto, new)
    blob = proto.SerializeToString()
    again = onnx.load_from_string(blob)
    if again.graph.SerializeToString(deterministic=True) != graph_before:
        raise SystemExit(f"{model}: the graph changed on rewriting the card; nothing written")
    meta = ort.InferenceSession(blob, providers=["CPUExecutionProvider"]).get_modelmeta().custom_metadata_map
    if any(meta.get(k) != v for k, v in new.items()):
        raise SystemExit(f"{model}: onnxruntime reads back a different card than was written; nothing written")

    write_atomically(model, blob)
    if card_json is not None and recorded is not None:
        for key in changed:
            if key in new:
                recorded[key] = new[key]
        if "onnx_mb" in recorded:
            # The export's record of the file's size: the longer card makes the file longer.
            recorded["onnx_mb"] = f"{len(blob) / 1e6:.3f}"
        write_atomically(card_json, (json.dumps(recorded, indent=1, sort_keys=True) + "\n").encode())
    rows = json.loads(new["closed_loop"])["rows"]
    print(f"recard: {model}: closed_loop now {len(rows)} rows from {len(tables)} tables"
          + (f"; {card_json} too" if card_json is not None else ""))
    return new


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.recard", description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="the .onnx model whose card to update")
    p.add_argument("--card-json", help="the card JSON beside it (models/<kind>.card.json), kept the same")
    p.add_argument("--closed-loop", nargs="+", required=True, metavar="TABLE_JSON",
                   help="eval table results (table.json) whose rows for this network become the card's closed_loop")
    p.add_argument("--commands", nargs="+", metavar="COMMAND",
                   help="the command that made each table, in the order of --closed-loop")
    p.add_argument("--drive-dlm-params", metavar="JSON",
                   help="a DLM-Net: drive it on these DLM parameters (a JSON object, e.g. "
                        "'{\"sidestep_ahead_m\": 2.0}'), those it was trained on kept as dlm_params_trained")
    args = p.parse_args(argv)
    drive = None
    if args.drive_dlm_params:
        try:
            drive = json.loads(args.drive_dlm_params)
        except json.JSONDecodeError as e:
            raise SystemExit(f"--drive-dlm-params: not JSON ({e}): {args.drive_dlm_params!r}") from e
        if not isinstance(drive, dict):
            raise SystemExit(f"--drive-dlm-params: a JSON object of DLM parameters, not {args.drive_dlm_params!r}")
    recard(Path(args.model), Path(args.card_json) if args.card_json else None, args.closed_loop, args.commands,
           drive)
    return 0


if __name__ == "__main__":
    sys.exit(main())

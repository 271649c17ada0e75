"""Exports a training checkpoint to the ONNX model the robot agent loads, with its card.

    python -m training.export --checkpoint out/train/dlm/checkpoint_best.pt --out models/dlm.onnx

* graph: `torch.onnx.export`, opset 17, inputs `camera` f32[N,3,H,W] and `intention` f32[N,4]
  (dlm) or `lpe` f32[N,3,P,P] (lpe), output `control` f32[N,2], dynamic batch N;
* card: the ONNX metadata_props (card.py), built from what the checkpoint recorded;
* checks, failing loudly: the card passes the agent's rules; the graph's input/output names and
  shapes match the card (as the agent's check_contract does); onnxruntime agrees with PyTorch to
  1e-4 on 16 real validation samples (from the checkpoint's recordings, or random inputs when
  those are gone) at batch 16 and batch 1; the file is at most --max-mb (default 20 MB).

The legacy TorchScript exporter (`dynamo=False`) is used: it needs no onnxscript and yields a
plain opset-17 graph with IR version 8 like the fixture models.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # see train.py: shared cores

import argparse
import io
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch

from training import card as card_mod
from training import data, model
from training.card import closed_loop_summary

OPSET = 17
MAX_MB = 20.0
TOLERANCE = 1e-4
CHECK_SAMPLES = 16


def load_checkpoint(path: str | Path) -> dict:
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    if ckpt.get("format") != "intention-fleet-checkpoint":
        raise SystemExit(f"{path}: not a training checkpoint of training/train.py")
    return ckpt


def card_for(ckpt: dict) -> dict[str, str]:
    """The card: the keys the agent reads plus the training record (ignored by the agent)."""
    val = ckpt["val"]
    extras = {
        "recipe": ckpt["recipe"],
        "deviations": "; ".join(ckpt["deviations"]),
        "train_loss": repr(float(ckpt["train_loss"])),
        "validation_loss_definition": (
            f"{ckpt['recipe']['loss'].upper()} on (v, omega) in [-1,1], mean over the DLM classes present in the "
            "validation episodes (recorded intentions, no augmentation)"
        ),
        "val_loss_all_frames": repr(val["loss_all"]),
        "val_l1": repr(val["l1"]),
        "val_l1_v": repr(val["l1_v"]),
        "val_l1_omega": repr(val["l1_omega"]),
        "per_intention_val_l1": val["per_intention_l1"],
        "per_intention_val_samples": val["per_intention_count"],
        "samples_seen": str(int(ckpt["samples_seen"])),
        "epoch": str(int(ckpt["epoch"])),
        "training_minutes": f"{ckpt['training_minutes']:.2f}",
        "parameters": str(int(ckpt["parameters"])),
        "datasets": ckpt["data"]["sources"],
        "split": {"train_samples": ckpt["data"]["train_samples"], "val_samples": ckpt["data"]["val_samples"],
                  "val_episodes": len(ckpt["data"]["val_episode_keys"])},
        "seed": str(ckpt["seed"]),
        "producer": f"intention-fleet training/train.py (torch {ckpt['torch_version']})",
        "closed_loop": "not yet measured (eval table)",
    }
    if val.get("intention_effect_omega") is not None:
        extras["intention_effect_omega"] = repr(val["intention_effect_omega"])
    return card_mod.make(ckpt["card_inputs"], val["loss"], extras)


def check_inputs(ckpt: dict, n: int = CHECK_SAMPLES) -> tuple[list[np.ndarray], str]:
    """n validation samples from the checkpoint's recordings as network inputs, or random
    inputs of the right shapes when the recordings cannot be opened."""
    kind, ci = ckpt["card_inputs"]["kind"], ckpt["card_inputs"]
    try:
        pool = data.Pool(ckpt["data"]["dirs"])
        keys = np.asarray(ckpt["data"]["val_episode_keys"], dtype=np.int64)
        idx = np.nonzero(np.isin(pool.episode_key, keys))[0]
        if len(idx) == 0:
            raise ValueError("no validation samples")
        idx = idx[np.linspace(0, len(idx) - 1, min(n, len(idx))).round().astype(np.int64)]
        b = data.Batches(pool, [idx], kind, train=False)[0]
        return [b[name].numpy() for name in model.input_names(kind)], f"{len(idx)} validation samples"
    except Exception as e:  # the recordings moved or were deleted: random inputs still check the graph
        print(f"export: cannot read validation samples ({e}); checking on random inputs", file=sys.stderr)
        rng = np.random.default_rng(0)
        shapes = {"camera": (n, 3, ci["camera_px"], ci["camera_px"]), "lpe": (n, 3, ci["lpe_px"], ci["lpe_px"])}
        feeds = []
        for name in model.input_names(kind):
            if name == "intention":
                feeds.append(np.eye(4, dtype=np.float32)[rng.integers(0, 4, n)])
            else:
                feeds.append(rng.normal(0, 1, shapes[name]).astype(np.float32))
        return feeds, f"{n} random inputs"


def check_contract(sess: ort.InferenceSession, card: dict[str, str]) -> None:
    """Input/output names and shapes as the agent checks them (dynamic dims accept anything)."""
    kind = card["kind"]
    h, w = int(card["image_height_px"]), int(card["image_width_px"])
    want = {"camera": [-1, 3, h, w], "intention": [-1, 4]}
    if kind == "lpe":
        p = card_mod.lpe_input_px(card)
        want["lpe"] = [-1, 3, p, p]
    have = {i.name: i for i in sess.get_inputs()}
    if sorted(have) != sorted(model.input_names(kind)):
        raise SystemExit(f"export: a {kind} model needs inputs {model.input_names(kind)}, the graph has {sorted(have)}")
    outs = {o.name: o for o in sess.get_outputs()}
    if list(outs) != ["control"]:
        raise SystemExit(f"export: the graph's outputs are {list(outs)}, the contract says ['control']")
    for name, t in [*have.items(), ("control", outs["control"])]:
        expected = want.get(name, [-1, 2])
        if t.type != "tensor(float)":
            raise SystemExit(f"export: `{name}` is {t.type}, the contract says f32")
        dims = t.shape
        ok = len(dims) == len(expected) and all(
            e < 0 or (isinstance(d, int) and d == e) for d, e in zip(dims, expected)
        )
        if not ok or isinstance(dims[0], int):
            raise SystemExit(f"export: `{name}` has shape {dims}, expected {expected} with a dynamic batch")


def drive_dlm_with(card: dict[str, str], changes: dict) -> None:
    """Makes the card's `dlm_params` (what `eval table`, `eval record --policy` and the fleet plan
    the DLM with) differ from what the labels were derived with, which `dlm_params_trained`
    keeps. Only keys the DLM has, and not the measure: a network fed another measure than it
    was trained on is `--dlm-measure-over-card`, not a card."""
    if card.get("kind") != "dlm":
        raise SystemExit("--drive-dlm-params: only a DLM-Net's card has DLM parameters")
    params = json.loads(card["dlm_params"])
    # A parameter the planner gained after the card was written reads as its "as before" value.
    known = data.with_added(params)
    for key, value in changes.items():
        if key not in known or key == "measure":
            raise SystemExit(f"--drive-dlm-params: {key!r} is not a DLM parameter this card can change "
                             f"(one of {', '.join(k for k in sorted(known) if k != 'measure')})")
        # The planner's DlmParams::validate: lengths of a window or chord must be positive, the
        # rest may be 0 (first_turn measuring from the robot on: heading_start_m 0).
        positive = key in ("window_m", "heading_chord_m")
        if (not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value)
                or (value <= 0 if positive else value < 0)):
            raise SystemExit(f"--drive-dlm-params: {key} = {value!r} is not a "
                             f"{'positive' if positive else 'non-negative'} number")
        params[key] = float(value)
    card["dlm_params_trained"] = card["dlm_params"]
    card["dlm_params"] = json.dumps(params, sort_keys=True, separators=(",", ":"))


def export_checkpoint(checkpoint: str | Path, out: str | Path, max_mb: float = MAX_MB, card_json: str | Path | None = None,
                      closed_loop: list[str | Path] | None = None, drive_dlm_params: dict | None = None) -> dict:
    """Exports, checks and saves; returns {card, max_abs_diff, size_mb, check_inputs}."""
    ckpt = load_checkpoint(checkpoint)
    config = ckpt["model_config"]
    kind = config["kind"]
    net = model.build(config)
    net.load_state_dict(ckpt["state_dict"])
    net.eval()
    card = card_for(ckpt)
    if drive_dlm_params:
        drive_dlm_with(card, drive_dlm_params)
    if closed_loop:
        card["closed_loop"] = closed_loop_summary(closed_loop, kind)
    card_mod.check(card)

    feeds, what = check_inputs(ckpt)
    names = model.input_names(kind)
    example = tuple(torch.from_numpy(f[:2]) for f in feeds)
    dynamic = {n: {0: "N"} for n in [*names, "control"]}
    buf = io.BytesIO()
    with warnings.catch_warnings():
        # The TorchScript exporter announces its deprecation on every call; it is chosen on purpose.
        warnings.simplefilter("ignore", category=DeprecationWarning)
        warnings.simplefilter("ignore", category=FutureWarning)
        torch.onnx.export(net, example, buf, input_names=names, output_names=["control"],
                          dynamic_axes=dynamic, opset_version=OPSET, dynamo=False, do_constant_folding=True)
    proto = onnx.load_from_string(buf.getvalue())
    proto.graph.name = f"intention_net_{kind}"
    proto.producer_name = "intention-fleet training/export.py"
    onnx.helper.set_model_props(proto, card)
    onnx.checker.check_model(proto, full_check=True)
    blob = proto.SerializeToString()

    sess = ort.InferenceSession(blob, providers=["CPUExecutionProvider"])
    check_contract(sess, card)
    meta = sess.get_modelmeta().custom_metadata_map
    if any(meta.get(k) != v for k, v in card.items()):
        raise SystemExit("export: onnxruntime reads back a different card than was written")
    max_diff = 0.0
    with torch.no_grad():
        for sl in (slice(None), slice(0, 1)):  # the whole batch and batch 1 (dynamic batch)
            ref = net(*(torch.from_numpy(f[sl]) for f in feeds)).numpy()
            got = sess.run(["control"], {n: f[sl] for n, f in zip(names, feeds)})[0]
            if got.shape != ref.shape:
                raise SystemExit(f"export: onnxruntime output shape {got.shape}, torch {ref.shape}")
            max_diff = max(max_diff, float(np.max(np.abs(got - ref))))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not max_diff <= TOLERANCE:
        bad = out.with_suffix(".rejected.onnx")
        bad.write_bytes(blob)
        raise SystemExit(f"export: onnxruntime and torch differ by {max_diff:.3g} > {TOLERANCE} on {what}; "
                         f"graph left in {bad} for inspection, {out} not written")
    size_mb = len(blob) / 1e6
    if size_mb > max_mb:
        raise SystemExit(f"export: {size_mb:.1f} MB exceeds --max-mb {max_mb:g}; {out} not written")
    tmp = out.with_suffix(".onnx.tmp")
    tmp.write_bytes(blob)
    tmp.replace(out)
    record = dict(card, onnx_max_abs_diff=repr(max_diff), onnx_check_inputs=what, onnx_mb=f"{size_mb:.3f}")
    if card_json is not None:
        Path(card_json).write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    print(f"export: {out} ({size_mb:.2f} MB, kind {kind}); onnxruntime vs torch max |diff| {max_diff:.2e} on {what}")
    return {"card": card, "max_abs_diff": max_diff, "size_mb": size_mb, "check_inputs": what}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.export", description=__doc__.splitlines()[0])
    p.add_argument("--checkpoint", required=True, help="checkpoint_best.pt (or any checkpoint) of training/train.py")
    p.add_argument("--out", required=True, help="the .onnx file to write")
    p.add_argument("--card-json", help="also write the card (and the check's result) as JSON here")
    p.add_argument("--closed-loop", nargs="+", metavar="TABLE_JSON",
                   help="eval table results (table.json) whose rows for this network go into the card's closed_loop")
    p.add_argument("--drive-dlm-params", metavar="JSON",
                   help='DLM-Net: plan its DLM with these parameters, e.g. \'{"heading_start_m": 0.5}\', instead of the '
                        "ones its labels were derived with (kept in the card as dlm_params_trained)")
    p.add_argument("--max-mb", type=float, default=MAX_MB, help="refuse a larger model (default %(default)s)")
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    try:
        drive = json.loads(args.drive_dlm_params) if args.drive_dlm_params else None
    except json.JSONDecodeError as e:
        raise SystemExit(f"--drive-dlm-params: not JSON ({e}): {args.drive_dlm_params!r}") from e
    if drive is not None and not isinstance(drive, dict):
        raise SystemExit(f"--drive-dlm-params: a JSON object of DLM parameters, not {args.drive_dlm_params!r}")
    export_checkpoint(args.checkpoint, args.out, args.max_mb, args.card_json, args.closed_loop, drive)
    return 0


if __name__ == "__main__":
    sys.exit(main())

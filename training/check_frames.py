"""Writes the frames and expected outputs with which the Rust agent's tests check the shipped
models (robot-agent/tests/shipped_models.rs).

    python -m training.check_frames --data data/d2 --models models --out models/checks
    python -m training.check_frames --refresh --models models --out models/checks

`--refresh` keeps the frames already in `--out` (with their recorded intention and label) and
recomputes every model's outputs on them: what a new shipped model needs when the recording
the frames came from is not at hand.

From a recording it takes, deterministically, 12 validation-style frames (3 where the expert turns
left under a turn_left intention, 3 turning right under turn_right, 3 go_forward, 3 at random),
stores each camera and LPE image as a PNG at the recorded size (what the agent's area-average
resize of a 224 px frame gives), and runs every shipped model (`<models>/{dlm,lpe,none}.onnx`)
on them with onnxruntime, through the agent's area-average resize to the model's card size
(`resize_area`, a port of `preprocess::resize_area_rgb8`; models of different sizes share the
frames) and the card's normalization. `expected.json` holds, per frame,
the files, the recorded intention, the expert's label and each model's output. The Rust test
must reproduce those outputs to 1e-4 through the agent's own preprocessing (the contract) and
checks the models' turning against the expert's (the behaviour).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import onnxruntime as ort
from PIL import Image

from training import card as card_mod
from training import dataset

KINDS = ("dlm", "lpe", "none")
PER_GROUP = 3
SEED = 20171113


def pick(ds: dataset.Dataset) -> list[int]:
    """Frames of the four groups, spread over the recording (never two of one episode)."""
    dlm = ds.field("dlm").astype(int)
    label = ds.field("label")
    episode = ds.field("episode")
    noisy = ds.field("noisy").astype(bool)
    rng = np.random.default_rng(SEED)
    groups = [
        (dlm == 0) & (label[:, 1] > 0.4) & ~noisy,
        (dlm == 1) & (label[:, 1] < -0.4) & ~noisy,
        (dlm == 2) & (np.abs(label[:, 1]) < 0.1) & (label[:, 0] > 0.5) & ~noisy,
        np.ones(len(dlm), dtype=bool),
    ]
    chosen: list[int] = []
    used_episodes: set[int] = set()
    for mask in groups:
        candidates = rng.permutation(np.nonzero(mask)[0])
        taken = 0
        for i in candidates:
            if int(episode[i]) in used_episodes:
                continue
            chosen.append(int(i))
            used_episodes.add(int(episode[i]))
            taken += 1
            if taken == PER_GROUP:
                break
        if taken < PER_GROUP:
            raise SystemExit(f"only {taken} frames of group {len(chosen) // PER_GROUP} in distinct episodes")
    return chosen


def _taps(src: int, dst: int) -> list[list[tuple[int, np.float32]]]:
    """For each output index the source indices it covers and their weights (the agent's taps)."""
    scale = src / dst
    out = []
    for o in range(dst):
        a, b = o * scale, (o + 1) * scale
        first, last = int(np.floor(a)), min(int(np.ceil(b)), src)
        row = []
        for i in range(first, last):
            overlap = (min(b, i + 1) - max(a, i)) / scale
            if overlap > 1e-9:
                row.append((i, np.float32(overlap)))
        out.append(row)
    return out


def resize_area(img_u8: np.ndarray, out_w: int, out_h: int) -> np.ndarray:
    """HWC uint8 resized by area average exactly as the agent's `resize_area_rgb8`: rows first
    into f32 (weights added in the same order), then columns, rounded half away from zero."""
    h, w, _ = img_u8.shape
    if (w, h) == (out_w, out_h):
        return img_u8
    src = img_u8.astype(np.float32)
    rows = np.zeros((h, out_w, 3), np.float32)
    for ox, taps in enumerate(_taps(w, out_w)):
        acc = np.zeros((h, 3), np.float32)
        for i, wt in taps:
            acc = acc + wt * src[:, i, :]
        rows[:, ox, :] = acc
    out = np.zeros((out_h, out_w, 3), np.float32)
    for oy, taps in enumerate(_taps(h, out_h)):
        acc = np.zeros((out_w, 3), np.float32)
        for i, wt in taps:
            acc = acc + wt * rows[i]
        out[oy] = acc
    return np.clip(np.floor(out + np.float32(0.5)), 0, 255).astype(np.uint8)


def sized(img_u8: np.ndarray, meta: dict[str, str], key: str) -> np.ndarray:
    """The image at the size the model's card asks for (`image_width_px`, or for the LPE image
    `lpe_image_px`, else the rendering's size)."""
    if key == "lpe":
        px = card_mod.lpe_input_px(meta)
        return resize_area(img_u8, px, px)
    return resize_area(img_u8, int(meta["image_width_px"]), int(meta["image_height_px"]))


def normalize(img_u8: np.ndarray, meta: dict[str, str]) -> np.ndarray:
    """HWC uint8 → NCHW f32 exactly as the agent does ((p/255 - mean) / std in f32)."""
    mean = np.array([float(v) for v in meta["norm_mean"].split(",")], dtype=np.float32)
    std = np.array([float(v) for v in meta["norm_std"].split(",")], dtype=np.float32)
    x = (img_u8.astype(np.float32) / np.float32(255.0) - mean) / std
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.check_frames", description=__doc__.splitlines()[0])
    p.add_argument("--data", help="a recording (eval record)")
    p.add_argument("--refresh", action="store_true",
                   help="keep the frames in --out and recompute the models' outputs on them")
    p.add_argument("--models", default="models", help="folder with dlm.onnx, lpe.onnx, none.onnx")
    p.add_argument("--out", default="models/checks")
    args = p.parse_args(argv)
    if args.refresh == bool(args.data):
        p.error("give either --data (new frames) or --refresh (the frames in --out)")

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sessions = {}
    for kind in KINDS:
        path = Path(args.models) / f"{kind}.onnx"
        if path.exists():
            sessions[kind] = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    if not sessions:
        raise SystemExit(f"no model in {args.models}")

    if args.refresh:
        old = json.loads((out / "expected.json").read_text())
        dataset_id = str(old["dataset_id"])
        inputs = [
            (np.asarray(Image.open(out / f["files"]["camera"]).convert("RGB")),
             np.asarray(Image.open(out / f["files"]["lpe"]).convert("RGB")),
             f["files"], int(f["dlm"]), [float(v) for v in f["label"]])
            for f in old["frames"]
        ]
    else:
        ds = dataset.load(args.data)
        dataset_id = str(ds.index["dataset_id"])
        inputs = []
        for n, i in enumerate(pick(ds)):
            sample = ds.sample(i)
            camera, lpe = np.asarray(sample["camera"]), np.asarray(sample["lpe"])
            files = {"camera": f"frame_{n:02}_camera.png", "lpe": f"frame_{n:02}_lpe.png"}
            Image.fromarray(camera).save(out / files["camera"])
            Image.fromarray(lpe).save(out / files["lpe"])
            inputs.append((camera, lpe, files, int(sample["dlm"]), [float(v) for v in sample["label"]]))

    frames = []
    for camera, lpe, files, dlm, label in inputs:
        entry = {
            "files": files,
            "dlm": dlm,
            "label": label,
            "outputs": {},
        }
        for kind, sess in sessions.items():
            meta = sess.get_modelmeta().custom_metadata_map
            feeds = {"camera": normalize(sized(camera, meta, "camera"), meta)}
            if kind == "dlm":
                one_hot = np.zeros((1, 4), dtype=np.float32)
                one_hot[0, dlm] = 1.0
                feeds["intention"] = one_hot
            elif kind == "lpe":
                feeds["lpe"] = normalize(sized(lpe, meta, "lpe"), meta)
            entry["outputs"][kind] = [float(v) for v in sess.run(["control"], feeds)[0][0]]
        frames.append(entry)
    doc = {
        "what": "frames of a recording and the shipped models' outputs on them (training/check_frames.py)",
        "dataset_id": dataset_id,
        "models": {kind: sess.get_modelmeta().custom_metadata_map.get("dataset_id", "") for kind, sess in sessions.items()},
        "frames": frames,
    }
    (out / "expected.json").write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {len(frames)} frames and expected.json to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Draws what a shipped model's convolutions respond to, like the paper's feature visualisation
(Gao et al., CoRL 2017, section 4.3, figure `fig:visualization`: the camera view beside the
activated features of an early, a middle and a late layer).

    python -m training.activations --model models/lpe.onnx --out docs/figures/activations-lpe.png
    python -m training.activations --model models/dlm.onnx --out docs/figures/activations-dlm.png

It works on the shipped ONNX model itself, not on a checkpoint (no torch):

* layers: the Relu nodes of the camera branch (the 4-d tensors reachable from the `camera`
  input, in graph order) -- the first, the middle and the last of them unless `--layers` names
  others; for an LPE model also the first and the last of the LPE branch. Each is labelled by
  its depth (how many convolutions lead to it), its map size and, in the printout, its node name.
  The onnx package adds their outputs to the graph as extra outputs; onnxruntime runs it on CPU.
* frames: the agent's check frames (`models/checks`, written by training/check_frames.py):
  camera and LPE PNGs and expected.json. The inputs are normalised with check_frames.normalize
  and the card in the model's metadata, exactly as check_frames and the agent do, and the
  model's `control` output on every frame must match expected.json to 1e-4 -- otherwise it
  stops, because then the preprocessing (or the model) is not the shipped one.
* picture: one row per frame (--rows, default 4: in turn the sharpest left turn under
  turn_left, the sharpest right turn under turn_right, the straightest go_forward frame, a turn
  intention while the expert still drives straight, and so on); columns: the camera image, the
  LPE image (LPE model), then per layer the channel mean of the activation (or, with --topk K,
  the mean of the K channels most active on that frame) upsampled bilinearly to the image and
  drawn as a heat map over the camera image (LPE-branch layers over the LPE image). Each heat
  map is scaled min-max on its own panel. Row labels: frame, intention, the model's (v, omega)
  and the expert's label.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # shared cores (see train.py)

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from PIL import Image

from training.check_frames import normalize, sized

TOLERANCE = 1e-4
INTENTIONS = ("turn_left", "turn_right", "go_forward", "stop")  # protocol::Dlm::index
# The contract's inputs per kind (training/model.py input_names; not imported: model.py needs torch).
INPUTS = {"dlm": {"camera", "intention"}, "lpe": {"camera", "lpe"}, "none": {"camera"}}
TURNING = 0.4  # |omega label| above which the expert is turning (check_frames' turn groups)
# Figure geometry (inches); the size is exact (no tight bbox) so the test can check it.
PANEL_IN = 1.6
LABEL_IN = 1.55  # left margin for the row labels
HEADER_IN = 0.75  # title + column labels
DPI = 100
ALPHA = 0.55
CMAP = "jet"


# ---------------------------------------------------------------------------------- the graph

def reachable_nodes(graph: onnx.GraphProto, start: str) -> list[onnx.NodeProto]:
    """Nodes downstream of the tensor `start`, in graph (topological) order."""
    live = {start}
    out = []
    for node in graph.node:
        if any(i in live for i in node.input):
            out.append(node)
            live.update(o for o in node.output if o)
    return out


def tensor_ranks(proto: onnx.ModelProto) -> dict[str, int]:
    inferred = onnx.shape_inference.infer_shapes(proto)
    ranks = {}
    for vi in [*inferred.graph.value_info, *inferred.graph.output, *inferred.graph.input]:
        t = vi.type.tensor_type
        if t.HasField("shape"):
            ranks[vi.name] = len(t.shape.dim)
    return ranks


def feature_layers(proto: onnx.ModelProto, image_input: str, exclude: str | None = None) -> list[dict]:
    """The Relu nodes of an image branch with 4-d (N, C, H, W) outputs, in graph order, each as
    {node, tensor, depth}; depth = how many Conv nodes of the branch come up to it. Nodes also
    reachable from `exclude` (the other image input) are not this branch's."""
    ranks = tensor_ranks(proto)
    other = {n.output[0] for n in reachable_nodes(proto.graph, exclude)} if exclude else set()
    layers, convs = [], 0
    for node in reachable_nodes(proto.graph, image_input):
        if node.output[0] in other:
            continue
        if node.op_type == "Conv":
            convs += 1
        elif node.op_type == "Relu" and ranks.get(node.output[0], 4) == 4:
            layers.append({"node": node.name or node.output[0], "tensor": node.output[0], "depth": convs})
    return layers


def choose(layers: list[dict], picks: list[int] | None, names: tuple[str, ...]) -> list[dict]:
    """First, middle and last (or the 1-based positions in `picks`), named early/middle/late."""
    if not layers:
        raise SystemExit("activations: no Relu with a 4-d output in the branch; is this an image model?")
    n = len(layers)
    if picks is None:
        idx = [0, n // 2, n - 1] if len(names) == 3 else [0, n - 1]
    else:
        bad = [p for p in picks if not 1 <= p <= n]
        if bad:
            raise SystemExit(f"activations: --layers {bad} out of range: the branch has {n} Relu layers")
        idx = [p - 1 for p in picks]
    out = []
    for j, i in enumerate(idx):
        role = names[j] if len(idx) == len(names) else f"layer {j + 1}"
        out.append(dict(layers[i], role=role, position=i + 1, of=n))
    return out


def session_with_outputs(proto: onnx.ModelProto, tensors: list[str]) -> ort.InferenceSession:
    proto = onnx.ModelProto.FromString(proto.SerializeToString())  # a copy; the file is untouched
    have = {o.name for o in proto.graph.output}
    for t in tensors:
        if t not in have:
            proto.graph.output.append(onnx.helper.make_tensor_value_info(t, onnx.TensorProto.FLOAT, None))
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    return ort.InferenceSession(proto.SerializeToString(), opts, providers=["CPUExecutionProvider"])


# ---------------------------------------------------------------------------------- the frames

def load_frames(folder: Path) -> list[dict]:
    doc = json.loads((folder / "expected.json").read_text())
    frames = []
    for n, f in enumerate(doc["frames"]):
        frames.append({
            "n": n,
            "dlm": int(f["dlm"]),
            "label": [float(v) for v in f["label"]],
            "expected": f["outputs"],
            "camera": np.asarray(Image.open(folder / f["files"]["camera"]).convert("RGB")),
            "lpe": np.asarray(Image.open(folder / f["files"]["lpe"]).convert("RGB")),
        })
    return frames


def default_order(frames: list[dict]) -> list[int]:
    """Frames in turn from the buckets (intention, expert turning?): left turn, right turn,
    straight go_forward, turn_left while straight, turn_right while straight, then the rest;
    within a bucket the sharpest turn (or the straightest, fastest go_forward) first."""
    buckets = [(0, True), (1, True), (2, False), (0, False), (1, False), (2, True), (3, False), (3, True)]
    queues = []
    for dlm, turning in buckets:
        members = [f for f in frames if f["dlm"] == dlm and (abs(f["label"][1]) > TURNING) == turning]
        key = (lambda f: -abs(f["label"][1])) if turning else (lambda f: (abs(f["label"][1]), -f["label"][0]))
        queues.append([f["n"] for f in sorted(members, key=key)])
    order = []
    while any(queues):
        for q in queues:
            if q:
                order.append(q.pop(0))
    return order


def feeds_for(frame: dict, kind: str, meta: dict[str, str]) -> dict[str, np.ndarray]:
    feeds = {"camera": normalize(frame["camera"], meta)}
    if kind == "dlm":
        one_hot = np.zeros((1, 4), dtype=np.float32)
        one_hot[0, frame["dlm"]] = 1.0
        feeds["intention"] = one_hot
    elif kind == "lpe":
        feeds["lpe"] = normalize(frame["lpe"], meta)
    return feeds


def to_card_size(frames: list[dict], kind: str, meta: dict[str, str]) -> list[dict]:
    """The frames resized to the card's input sizes with the agent's area average (the check
    frames are stored at the largest model's size; expected.json was computed the same way)."""
    return [dict(f, camera=sized(f["camera"], meta, "camera"),
                 lpe=sized(f["lpe"], meta, "lpe") if kind == "lpe" else f["lpe"]) for f in frames]


# ---------------------------------------------------------------------------------- the maps

def reduce_map(act: np.ndarray, topk: int | None) -> np.ndarray:
    """(1, C, h, w) -> (h, w): channel mean, or the mean of the topk channels with the largest
    spatial mean on this frame."""
    a = act[0]
    if topk:
        order = np.argsort(a.mean(axis=(1, 2)))[::-1][:topk]
        a = a[order]
    return a.mean(axis=0)


def upsample(m: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Bilinear (PIL, pixel-centre aligned) to (height, width)."""
    img = Image.fromarray(m.astype(np.float32), mode="F").resize((size[1], size[0]), Image.BILINEAR)
    return np.asarray(img)


def unit(m: np.ndarray) -> np.ndarray:
    lo, hi = float(m.min()), float(m.max())
    return np.zeros_like(m) if hi - lo < 1e-12 else (m - lo) / (hi - lo)


def figure_size(ncols: int, nrows: int) -> tuple[float, float]:
    return LABEL_IN + ncols * PANEL_IN, HEADER_IN + nrows * PANEL_IN


def row_label(frame: dict, out: list[float], meta: dict[str, str]) -> str:
    v, w = out
    lab = frame["label"]
    vmax, wmax = float(meta.get("max_speed_mps", "nan")), float(meta.get("max_turn_radps", "nan"))
    return (f"frame {frame['n']:02}\n{INTENTIONS[frame['dlm']]}\n"
            f"model v {v:+.2f}  ω {w:+.2f}\n({v * vmax:.2f} m/s, {w * wmax:+.2f} rad/s)\n"
            f"expert v {lab[0]:+.2f}  ω {lab[1]:+.2f}")


# ---------------------------------------------------------------------------------- main

def render(model_path: str | Path, frames_dir: str | Path, out: str | Path, rows: int = 4,
           layers: list[int] | None = None, topk: int | None = None, pick: list[int] | None = None) -> dict:
    """Checks the model on every frame, draws the figure; returns what it drew."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    proto = onnx.load(str(model_path))
    meta = {p.key: p.value for p in proto.metadata_props}
    kind = meta.get("kind")
    if kind not in INPUTS:
        raise SystemExit(f"activations: {model_path} has no model card kind (got {kind!r})")
    have = {i.name for i in proto.graph.input}
    if have != INPUTS[kind]:
        raise SystemExit(f"activations: a {kind} model needs inputs {sorted(INPUTS[kind])}, "
                         f"the graph has {sorted(have)}")

    cam_layers = choose(feature_layers(proto, "camera", "lpe" if kind == "lpe" else None), layers,
                        ("early", "middle", "late"))
    for layer in cam_layers:
        layer["branch"] = "camera"
    lpe_layers = []
    if kind == "lpe":
        lpe_layers = choose(feature_layers(proto, "lpe", "camera"), None, ("early", "late"))
        for layer in lpe_layers:
            layer["branch"] = "lpe"
    chosen = cam_layers + lpe_layers
    sess = session_with_outputs(proto, [layer["tensor"] for layer in chosen])

    frames = to_card_size(load_frames(Path(frames_dir)), kind, meta)
    names = ["control"] + [layer["tensor"] for layer in chosen]
    results, worst = {}, 0.0
    for f in frames:
        if kind not in f["expected"]:
            raise SystemExit(f"activations: {frames_dir}/expected.json has no `{kind}` outputs")
        got = sess.run(names, feeds_for(f, kind, meta))
        control = got[0][0].astype(np.float64)
        diff = float(np.max(np.abs(control - np.asarray(f["expected"][kind]))))
        worst = max(worst, diff)
        if not diff <= TOLERANCE:
            raise SystemExit(
                f"activations: frame {f['n']:02}: the model gives {control.round(6).tolist()}, expected.json "
                f"{f['expected'][kind]} (|diff| {diff:.3g} > {TOLERANCE}): the preprocessing or the model is not "
                f"the one the check frames were made with (model dataset_id {meta.get('dataset_id')})")
        results[f["n"]] = {"control": control.tolist(), "acts": got[1:]}
    for layer, act in zip(chosen, results[frames[0]["n"]]["acts"]):
        layer["shape"] = list(act.shape[1:])
    print(f"activations: {model_path} ({kind}) matches expected.json on all {len(frames)} frames "
          f"(max |diff| {worst:.2e} <= {TOLERANCE})")
    for layer in chosen:
        c, h, w = layer["shape"]
        print(f"  {layer['branch']:6} {layer['role']:6} relu {layer['position']}/{layer['of']} after conv "
              f"{layer['depth']}: {layer['node']} -> {c}x{h}x{w}")

    order = pick if pick is not None else default_order(frames)[:rows]
    unknown = [i for i in order if i not in results]
    if unknown:
        raise SystemExit(f"activations: no frame {unknown} in {frames_dir} (0..{len(frames) - 1})")

    headers = ["camera"] + (["LPE"] if kind == "lpe" else [])
    for layer in chosen:
        c, h, w = layer["shape"]
        prefix = "LPE " if layer["branch"] == "lpe" else ""
        headers.append(f"{prefix}{layer['role']}\n(conv {layer['depth']}, {w}x{h})")
    ncols, nrows = len(headers), len(order)
    fig_w, fig_h = figure_size(ncols, nrows)
    fig = plt.figure(figsize=(fig_w, fig_h), dpi=DPI)
    how = f"mean of the top {topk} channels" if topk else "channel mean"
    fig.suptitle(f"{kind.upper()}-Net ({Path(model_path).name}): {how} of each layer's ReLU output, "
                 f"upsampled, min-max per panel", fontsize=10, y=1 - 0.18 / fig_h)
    for r, n in enumerate(order):
        f, res = frames[n], results[n]
        images = [f["camera"]] + ([f["lpe"]] if kind == "lpe" else [])
        panels = [(img, None) for img in images]
        for layer, act in zip(chosen, res["acts"]):
            base = f["lpe"] if layer["branch"] == "lpe" else f["camera"]
            panels.append((base, unit(upsample(reduce_map(act, topk), base.shape[:2]))))
        for c, (img, heat) in enumerate(panels):
            left = (LABEL_IN + c * PANEL_IN + 0.03) / fig_w
            bottom = (fig_h - HEADER_IN - (r + 1) * PANEL_IN + 0.03) / fig_h
            ax = fig.add_axes((left, bottom, (PANEL_IN - 0.06) / fig_w, (PANEL_IN - 0.06) / fig_h))
            ax.imshow(img, interpolation="nearest")
            if heat is not None:
                ax.imshow(heat, cmap=CMAP, alpha=ALPHA, vmin=0, vmax=1, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(headers[c], fontsize=8)
            if c == 0:
                ax.set_ylabel(row_label(f, res["control"], meta), fontsize=7, rotation=0, ha="right", va="center",
                              labelpad=6)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=DPI)
    plt.close(fig)
    print(f"activations: wrote {out} ({nrows} frames: {order}; {ncols} columns)")
    return {"kind": kind, "frames": order, "columns": headers, "layers": chosen, "max_abs_diff": worst,
            "size_px": (round(fig_w * DPI), round(fig_h * DPI)), "out": str(out)}


def int_list(text: str) -> list[int]:
    return [int(t) for t in text.split(",") if t.strip()]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.activations", description=__doc__.splitlines()[0])
    p.add_argument("--model", default="models/lpe.onnx", help="a shipped ONNX model (dlm, lpe or none)")
    p.add_argument("--frames", default="models/checks",
                   help="check frames with expected.json (training/check_frames.py)")
    p.add_argument("--out", help="PNG to write (default docs/figures/activations-<kind>.png)")
    p.add_argument("--rows", type=int, default=4, help="how many frames (default %(default)s)")
    p.add_argument("--pick", type=int_list, help="these frames (comma-separated numbers) instead of the default choice")
    p.add_argument("--layers", type=int_list,
                   help="camera-branch Relu layers by 1-based position (default: first, middle, last)")
    p.add_argument("--topk", type=int, help="average only the K most active channels per frame (default: all)")
    args = p.parse_args(argv)
    if args.rows < 1:
        p.error("--rows must be at least 1")
    out = args.out
    if out is None:
        props = onnx.load(args.model, load_external_data=False).metadata_props
        kind = {q.key: q.value for q in props}.get("kind", "model")
        out = f"docs/figures/activations-{kind}.png"
    render(args.model, args.frames, out, args.rows, args.layers, args.topk, args.pick)
    return 0


if __name__ == "__main__":
    sys.exit(main())

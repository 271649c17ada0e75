#!/usr/bin/env python3
"""Generates the small intention-net fixture models the robot agent's tests load.

Until trained models ship in models/, the agent's ONNX Runtime path is tested against three
tiny, seeded, untrained networks that follow the ONNX contract of DESIGN.md section 5 exactly:

* dlm:  camera f32[N,3,H,W] + intention f32[N,4] (one-hot TurnLeft, TurnRight, GoForward, Stop)
        -> control f32[N,2]. CNN features of the camera, the intention embedded to 64-d (as in the
        paper), concatenated, one linear layer that outputs a control for every intention (4x2);
        the given one-hot selects one (MatMul), tanh.
* lpe:  camera + lpe f32[N,3,H,W] through one shared (siamese) CNN, concatenated, linear, tanh.
* none: camera only (the paper's Non-Intention Net ablation).

plus dlm_bad_card.onnx, a dlm model whose card claims a different image size than its graph
(the agent must refuse it).

The model card lives in the ONNX metadata_props (see CARD below and the agent's card.rs).
For a few deterministic inputs the outputs are computed with onnxruntime and written to
models/fixtures/expected.json; the Rust tests rebuild the same pixels, preprocess them with the
card's normalization and must match to 1e-4.

Run from the repository root (needs `onnx`, `onnxruntime` and `numpy` in .venv):
    bash scripts/setup.sh && .venv/bin/python -m pip install onnx
    .venv/bin/python training/make_fixture_model.py
"""

import argparse
import json
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper

SEED = 20170905  # CoRL 2017; any fixed value works, it only has to stay fixed.
OPSET = 17
IR_VERSION = 8
SIZE_PX = 224
MEAN = [0.485, 0.456, 0.406]
STD = [0.229, 0.224, 0.225]
DLM_ORDER = ["turn_left", "turn_right", "go_forward", "stop"]
# The planner's default LPE rendering (planner-service LpeParams::default()).
LPE_RENDERING = {
    "size_px": SIZE_PX,
    "metres_per_px": 0.05,
    "robot_px": [112, 168],
    "travelled_width_px": 3.0,
    "ahead_width_px": 3.0,
    "free_rgb": [255, 255, 255],
    "occupied_rgb": [0, 0, 0],
    "unknown_rgb": [128, 128, 128],
    "travelled_rgb": [255, 0, 0],
    "ahead_rgb": [0, 0, 255],
}


def card(kind, width_px=SIZE_PX, height_px=SIZE_PX):
    props = {
        "card_version": "1",
        "kind": kind,
        "backbone": "fixture-cnn-2conv (untrained, seeded)",
        "image_width_px": str(width_px),
        "image_height_px": str(height_px),
        "norm_mean": ",".join(repr(m) for m in MEAN),
        "norm_std": ",".join(repr(s) for s in STD),
        "max_speed_mps": "0.7",
        "max_turn_radps": "1.2",
        "dataset_id": "fixture-untrained",
        "validation_loss": "0.0",
    }
    if kind == "lpe":
        props["lpe_rendering"] = json.dumps(LPE_RENDERING, sort_keys=True)
    return props


class Builder:
    def __init__(self, rng):
        self.rng = rng
        self.nodes = []
        self.inits = []

    def weight(self, name, shape, fan_in, gain=1.0):
        w = self.rng.normal(0.0, gain * np.sqrt(2.0 / fan_in), size=shape).astype(np.float32)
        self.inits.append(numpy_helper.from_array(w, name))
        return name

    def const(self, name, array):
        self.inits.append(numpy_helper.from_array(np.asarray(array), name))
        return name

    def node(self, op, inputs, output, **attrs):
        self.nodes.append(helper.make_node(op, inputs, [output], name=output, **attrs))
        return output

    def backbone_weights(self):
        """Two strided convolutions and an average pool: [N,3,224,224] -> [N,256]."""
        return {
            "w1": self.weight("conv1_w", (8, 3, 5, 5), 3 * 25),
            "b1": self.const("conv1_b", np.zeros(8, np.float32)),
            "w2": self.weight("conv2_w", (16, 8, 3, 3), 8 * 9),
            "b2": self.const("conv2_b", np.zeros(16, np.float32)),
        }

    def backbone(self, x, w, tag):
        c1 = self.node("Conv", [x, w["w1"], w["b1"]], f"{tag}_c1", strides=[4, 4], pads=[2, 2, 2, 2])
        r1 = self.node("Relu", [c1], f"{tag}_r1")  # [N,8,56,56]
        c2 = self.node("Conv", [r1, w["w2"], w["b2"]], f"{tag}_c2", strides=[2, 2], pads=[1, 1, 1, 1])
        r2 = self.node("Relu", [c2], f"{tag}_r2")  # [N,16,28,28]
        p = self.node("AveragePool", [r2], f"{tag}_pool", kernel_shape=[7, 7], strides=[7, 7])
        return self.node("Flatten", [p], f"{tag}_feat", axis=1)  # [N,16*4*4]


FEAT = 16 * 4 * 4


def image_input(name, size_px):
    return helper.make_tensor_value_info(name, TensorProto.FLOAT, ["N", 3, size_px, size_px])


def finish(b, kind, inputs, props):
    out = helper.make_tensor_value_info("control", TensorProto.FLOAT, ["N", 2])
    graph = helper.make_graph(b.nodes, f"intention_net_{kind}_fixture", inputs, [out], b.inits)
    model = helper.make_model(
        graph,
        producer_name="intention-fleet training/make_fixture_model.py",
        opset_imports=[helper.make_opsetid("", OPSET)],
    )
    model.ir_version = IR_VERSION
    helper.set_model_props(model, props)
    onnx.checker.check_model(model, full_check=True)
    return model


def make_dlm(rng, props):
    b = Builder(rng)
    feat = b.backbone("camera", b.backbone_weights(), "cam")
    e = b.node("MatMul", ["intention", b.weight("int_w", (4, 64), 4)], "int_mm")
    e = b.node("Add", [e, b.const("int_b", rng.normal(0, 0.1, 64).astype(np.float32))], "int_add")
    e = b.node("Relu", [e], "int_emb")  # [N,64]
    cat = b.node("Concat", [feat, e], "cat", axis=1)  # [N,320]
    all_controls = b.node(
        "Gemm",
        [cat, b.weight("head_w", (FEAT + 64, 8), FEAT + 64, gain=0.5),
         b.const("head_b", rng.normal(0, 0.2, 8).astype(np.float32))],
        "head",
    )  # [N,8]: a (v, w) pair per intention
    per_intention = b.node("Reshape", [all_controls, b.const("shape_n42", np.array([-1, 4, 2], np.int64))], "per_int")
    sel = b.node("Unsqueeze", ["intention", b.const("axis1", np.array([1], np.int64))], "sel")  # [N,1,4]
    picked = b.node("MatMul", [sel, per_intention], "picked")  # [N,1,2]
    flat = b.node("Reshape", [picked, b.const("shape_n2", np.array([-1, 2], np.int64))], "picked2")
    b.node("Tanh", [flat], "control")
    intention = helper.make_tensor_value_info("intention", TensorProto.FLOAT, ["N", 4])
    return finish(b, "dlm", [image_input("camera", SIZE_PX), intention], props)


def make_lpe(rng, props):
    b = Builder(rng)
    shared = b.backbone_weights()
    fc = b.backbone("camera", shared, "cam")
    fl = b.backbone("lpe", shared, "lpe")
    cat = b.node("Concat", [fc, fl], "cat", axis=1)  # [N,512]
    h = b.node("Gemm", [cat, b.weight("fc1_w", (2 * FEAT, 32), 2 * FEAT), b.const("fc1_b", np.zeros(32, np.float32))], "fc1")
    h = b.node("Relu", [h], "fc1_r")
    o = b.node("Gemm", [h, b.weight("fc2_w", (32, 2), 32, gain=0.5),
                        b.const("fc2_b", rng.normal(0, 0.2, 2).astype(np.float32))], "fc2")
    b.node("Tanh", [o], "control")
    return finish(b, "lpe", [image_input("camera", SIZE_PX), image_input("lpe", SIZE_PX)], props)


def make_none(rng, props):
    b = Builder(rng)
    feat = b.backbone("camera", b.backbone_weights(), "cam")
    o = b.node("Gemm", [feat, b.weight("fc_w", (FEAT, 2), FEAT, gain=0.5),
                        b.const("fc_b", rng.normal(0, 0.2, 2).astype(np.float32))], "fc")
    b.node("Tanh", [o], "control")
    return finish(b, "none", [image_input("camera", SIZE_PX)], props)


# Deterministic test images, rebuilt pixel for pixel by the Rust tests (robot-agent/tests).
def pattern_pixels(spec, size_px):
    h = w = size_px
    if spec["pattern"] == "constant":
        img = np.empty((h, w, 3), np.uint8)
        img[:, :] = spec["rgb"]
        return img
    if spec["pattern"] == "gradient":
        # R rises left to right, G top to bottom, B along the diagonal (integer arithmetic).
        y, x = np.mgrid[0:h, 0:w].astype(np.int64)
        r = x * 255 // (w - 1)
        g = y * 255 // (h - 1)
        bl = (x + y) * 255 // (w + h - 2)
        return np.stack([r, g, bl], axis=-1).astype(np.uint8)
    raise ValueError(spec)


def to_tensor(img):
    x = img.astype(np.float32) / np.float32(255.0)
    x = (x - np.array(MEAN, np.float32)) / np.array(STD, np.float32)
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None])


CAMERAS = [
    {"pattern": "constant", "rgb": [128, 128, 128]},
    {"pattern": "constant", "rgb": [200, 30, 60]},
    {"pattern": "gradient"},
]
LPES = [
    {"pattern": "constant", "rgb": [255, 255, 255]},
    {"pattern": "gradient"},
]


def run(path, feeds):
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (out,) = sess.run(["control"], feeds)
    return [float(v) for v in out[0]]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="models/fixtures", help="output folder (default: %(default)s)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    models = {
        "dlm": make_dlm(np.random.default_rng(SEED), card("dlm")),
        "lpe": make_lpe(np.random.default_rng(SEED + 1), card("lpe")),
        "none": make_none(np.random.default_rng(SEED + 2), card("none")),
        # Same graph as dlm, but the card claims 112 x 112: the agent must refuse it.
        "dlm_bad_card": make_dlm(np.random.default_rng(SEED), card("dlm", 112, 112)),
    }
    for name, model in models.items():
        path = out / f"{name}.onnx"
        onnx.save(model, path)
        size = path.stat().st_size
        assert size < 1_000_000, f"{path} is {size} bytes"

    cases = []
    for cam in CAMERAS:
        camera = to_tensor(pattern_pixels(cam, SIZE_PX))
        for i, dlm in enumerate(DLM_ORDER):
            one_hot = np.zeros((1, 4), np.float32)
            one_hot[0, i] = 1.0
            control = run(out / "dlm.onnx", {"camera": camera, "intention": one_hot})
            cases.append({"model": "dlm.onnx", "camera": cam, "dlm": dlm, "control": control})
        for lpe in LPES:
            feeds = {"camera": camera, "lpe": to_tensor(pattern_pixels(lpe, SIZE_PX))}
            cases.append({"model": "lpe.onnx", "camera": cam, "lpe": lpe, "control": run(out / "lpe.onnx", feeds)})
        cases.append({"model": "none.onnx", "camera": cam, "control": run(out / "none.onnx", {"camera": camera})})

    expected = {
        "generator": "training/make_fixture_model.py",
        "onnxruntime_version": ort.__version__,
        "image_size_px": SIZE_PX,
        "tolerance": 1e-4,
        "cases": cases,
    }
    (out / "expected.json").write_text(json.dumps(expected, indent=2) + "\n")
    for c in cases:
        print(c["model"], c.get("dlm", c.get("lpe", "")), c["camera"], [round(v, 4) for v in c["control"]])


if __name__ == "__main__":
    main()

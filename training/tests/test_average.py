"""Test of `python -m training.average` (weight averaging of exported models) on the fixture models.

* the average of a model and a copy with every float weight scaled by 1.5 has weights 1.25 times
  the model's; weights 1:0 reproduce the first model's controls exactly through onnxruntime;
* the card: the agent's keys of the first model, the dataset ids joined, the validation losses
  averaged with the weights, every member named with its SHA-256, and it passes the agent's rules;
* refused, naming what: models of different graphs (LPE-Net and DLM-Net), a card key the agent
  reads that differs (norm_mean; DLM parameters compared as parameters, so one the planner gained
  later spelled out at its "as before" value is no difference), a negative weight, a missing file,
  a `--keep-first` prefix no initializer lies under; nothing is written then;
* `--keep-first` (e.g. `heads.0`, a shipped DLM-Net's `turn_left` head): those initializers are
  the first model's bit for bit, the rest averaged, and the card's recipe and deviations say so.

Needs onnx, onnxruntime and torch (training.export's contract check). CI runs it
(scripts/training-smoke.sh).

    .venv/bin/python training/tests/test_average.py
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import onnx  # noqa: E402
import onnxruntime as ort  # noqa: E402
from onnx import numpy_helper  # noqa: E402

from training import average as avg  # noqa: E402
from training import card as card_mod  # noqa: E402

FIXTURES = ROOT / "models" / "fixtures"


def _scaled_copy(src: Path, dst: Path, factor: float, card_changes: dict[str, str]) -> None:
    proto = onnx.load(src)
    for t in proto.graph.initializer:
        a = numpy_helper.to_array(t)
        if a.dtype.kind == "f":
            t.CopyFrom(numpy_helper.from_array((a * factor).astype(a.dtype), t.name))
    card = {p.key: p.value for p in proto.metadata_props}
    card.update(card_changes)
    del proto.metadata_props[:]
    onnx.helper.set_model_props(proto, card)
    onnx.save(proto, dst)


def _floats(path: Path) -> dict[str, np.ndarray]:
    return {t.name: numpy_helper.to_array(t) for t in onnx.load(path).graph.initializer
            if numpy_helper.to_array(t).dtype.kind == "f"}


def _controls(path: Path) -> np.ndarray:
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(3)
    feeds = {i.name: rng.normal(0, 1, [4 if not isinstance(d, int) else d for d in i.shape]).astype(np.float32)
             for i in sess.get_inputs()}
    return sess.run(["control"], feeds)[0]


def _refused(members, out: Path, needle: str, **options) -> None:
    try:
        avg.average(members, out, **options)
    except SystemExit as e:
        assert needle in str(e), f"expected {needle!r} in: {e}"
        assert not out.exists(), f"{out} was written although refused"
        return
    raise AssertionError(f"not refused; expected {needle!r}")


def test_average() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        lpe = FIXTURES / "lpe.onnx"
        base_card = {p.key: p.value for p in onnx.load(lpe).metadata_props}
        scaled = tmp / "scaled.onnx"
        _scaled_copy(lpe, scaled, 1.5, {"dataset_id": "feedfacefeedface", "validation_loss": "0.3"})

        out = tmp / "avg.onnx"
        card = avg.average([(lpe, None), (scaled, None)], out, card_json=tmp / "avg.card.json")
        want, got = _floats(lpe), _floats(out)
        assert sorted(want) == sorted(got)
        for k, a in want.items():
            np.testing.assert_allclose(got[k], 1.25 * a, rtol=1e-6, atol=1e-7, err_msg=k)
        card_mod.check(card)
        assert card["kind"] == "lpe" and card["lpe_rendering"] == base_card["lpe_rendering"]
        assert card["dataset_id"] == f"{base_card['dataset_id']}+feedfacefeedface", card["dataset_id"]
        expected_loss = 0.5 * float(base_card["validation_loss"]) + 0.5 * 0.3
        assert abs(float(card["validation_loss"]) - expected_loss) < 1e-12, card["validation_loss"]
        members = json.loads(card["averaged_from"])
        assert [m["weight"] for m in members] == [0.5, 0.5]
        assert all(len(m["sha256"]) == 64 for m in members)
        # The card says how it was made, as a trained model's does (the agent's shipped-model test).
        recipe = json.loads(card["recipe"])
        assert recipe["weights"] == [0.5, 0.5] and len(recipe["member_recipes"]) == 2, recipe
        read_back = {p.key: p.value for p in onnx.load(out).metadata_props}
        assert read_back == card
        assert json.loads((tmp / "avg.card.json").read_text())["dataset_id"] == card["dataset_id"]

        # Weights 1:0 (normalised from 2:0) give the first model back.
        one = tmp / "one.onnx"
        avg.average([(lpe, 2.0), (scaled, 0.0)], one)
        np.testing.assert_array_equal(_controls(one), _controls(lpe))
        assert not np.allclose(_controls(out), _controls(lpe))

        _refused([(lpe, None), (FIXTURES / "dlm.onnx", None)], tmp / "r1.onnx", "dlm.onnx")
        other_norm = tmp / "norm.onnx"
        _scaled_copy(lpe, other_norm, 1.0, {"norm_mean": "0.5,0.5,0.5"})
        _refused([(lpe, None), (other_norm, None)], tmp / "r2.onnx", "norm_mean")
        _refused([(lpe, 1.0), (scaled, -0.5)], tmp / "r3.onnx", "-0.5")
        _refused([(lpe, 1.0), (scaled, None)], tmp / "r4.onnx", "every --model")
        _refused([(lpe, None), (tmp / "missing.onnx", None)], tmp / "r5.onnx", "missing.onnx")
        # DLM parameters compare as parameters: one the planner gained later, spelled out at its
        # "as before" value, is the same; at another value it is not.
        params = {"measure": "first_turn", "window_m": 1.5, "curvature_threshold_per_m": 0.3, "heading_start_m": 0.0,
                  "heading_chord_m": 1.0, "turn_threshold_rad": 0.8, "turn_release_rad": 0.6, "stop_distance_m": 0.3}
        dlm = tmp / "dlm.onnx"
        _scaled_copy(FIXTURES / "dlm.onnx", dlm, 1.0, {"dlm_params": json.dumps(params)})
        spelled = tmp / "spelled.onnx"
        _scaled_copy(dlm, spelled, 1.0, {"dlm_params": json.dumps({**params, "blocked_ahead_m": 0.0})})
        avg.average([(dlm, None), (spelled, None)], tmp / "dlm-avg.onnx")
        blocked = tmp / "blocked.onnx"
        _scaled_copy(dlm, blocked, 1.0, {"dlm_params": json.dumps({**params, "blocked_ahead_m": 1.2})})
        _refused([(dlm, None), (blocked, None)], tmp / "r6.onnx", "dlm_params")
        # Kept layers are the first model's, bit for bit; the rest is averaged; the card says so.
        # (The fixture's initializers are flat names; a shipped network's are dotted, `heads.0.3.bias`.)
        heads = tmp / "heads.onnx"
        kept_names = ["fc2_w", "fc2_b"]
        card = avg.average([(lpe, None), (scaled, None)], heads, keep_first=kept_names)
        got = _floats(heads)
        for k, a in want.items():
            np.testing.assert_allclose(got[k], a if k in kept_names else 1.25 * a, rtol=1e-6, atol=1e-7, err_msg=k)
        assert json.loads(card["recipe"])["kept_from_first"] == kept_names
        assert "fc2_w, fc2_b" in card["deviations"]
        assert not avg.kept("heads.01.weight", ["heads.0"]) and avg.kept("heads.0.3.bias", ["heads.0"])
        _refused([(lpe, None), (scaled, None)], tmp / "r7.onnx", "heads.9", keep_first=["heads.9"])
        assert avg.parse_member("a/b.onnx:0.25") == (Path("a/b.onnx"), 0.25)
        assert avg.parse_member("a/b.onnx") == (Path("a/b.onnx"), None)
    print("training.average: ok")


if __name__ == "__main__":
    test_average()

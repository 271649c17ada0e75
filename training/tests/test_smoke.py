"""Smoke test of the whole training path: recording format -> train -> ONNX export -> checks.

Writes a tiny synthetic recording in the exact format `eval record` produces (DATASET.md:
NPY shards + index.json; a bar in the camera image and a line in the LPE image whose position
follows the turn-rate label, so there is something to learn), or uses a real one with --data;
then for each kind (dlm, lpe, none) trains for --seconds (default 30) with
`python -m training.train`, and checks:

* the outputs exist (checkpoints, history.json, loss.png, card.json, <kind>.onnx);
* the ONNX card passes the agent's rules (card.check) and carries the recording's dataset_id
  and limits, lpe_image_px for lpe, and the extra keys (recipe, deviations, ...);
* onnxruntime runs the model on a batch with the contract's input names and shapes and the
  export's agreement check with torch was <= 1e-4;
* `python -m training.export` re-exports a checkpoint on its own;
* `python training/dataset.py DIR` still runs as a script.

    .venv/bin/python training/tests/test_smoke.py [--seconds 30] [--data DIR] [--keep DIR]
    .venv/bin/python -m pytest training/tests        # the same, 30 s per kind

It uses --threads 1 so it can run next to other work; expect about 2.5 minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from training import card as card_mod  # noqa: E402

PX = 48
EPISODES = 13  # check_frames takes 12 frames from distinct episodes
PER_EPISODE = 60


def write_synthetic(root: Path, seed: int = 0) -> None:
    """A recording of EPISODES x PER_EPISODE samples at PX px in the recorder's format."""
    rng = np.random.default_rng(seed)
    n = EPISODES * PER_EPISODE
    episode = np.repeat(np.arange(EPISODES, dtype=np.uint32) * 3, PER_EPISODE)  # not every number appears
    t = np.tile(np.arange(PER_EPISODE, dtype=np.float32) * 0.1, EPISODES)
    # Turn rate: smooth per episode; the DLM follows its sign, with straight stretches.
    omega = np.clip(np.sin(t * 0.7 + episode) * 0.9 + rng.normal(0, 0.05, n), -1, 1).astype(np.float32)
    dlm = np.where(omega > 0.3, 0, np.where(omega < -0.3, 1, 2)).astype(np.uint8)
    dlm[np.arange(n) % PER_EPISODE >= PER_EPISODE - 5] = 3  # stop at the end of every episode
    v = np.where(dlm == 3, 0.0, 0.9 - 0.4 * np.abs(omega)).astype(np.float32)
    label = np.stack([v, omega], 1)
    # The expert's target speed: its command reaches it (here, a step above the command while moving).
    target = np.stack([np.where(dlm == 3, 0.0, np.minimum(v + 0.1, 1.0)).astype(np.float32), np.sign(omega)], 1)
    camera = np.full((n, PX, PX, 3), 90, np.uint8)
    lpe = np.full((n, PX, PX, 3), 255, np.uint8)
    cols = ((1 - omega) / 2 * (PX - 6)).astype(int)
    for i in range(n):
        camera[i, :, cols[i] : cols[i] + 6] = (220, 200, 60)
        camera[i, PX // 2 :, :, 2] = 40 + 10 * episode[i] % 100
        lpe[i, PX // 2 :, PX // 2 - 1 : PX // 2 + 1] = (255, 0, 0)
        lpe[i, : PX // 2, cols[i] : cols[i] + 2] = (0, 0, 255)
    camera = np.clip(camera.astype(np.int16) + rng.integers(-8, 9, camera.shape), 0, 255).astype(np.uint8)
    fields = {
        "camera": camera, "lpe": lpe, "dlm": dlm, "label": label, "target": target.astype(np.float32),
        "executed": label.copy(),
        "pose_true": np.zeros((n, 3), np.float32), "pose_amcl": np.zeros((n, 3), np.float32),
        "scenario": (episode % 2).astype(np.uint32), "episode": episode, "noisy": np.zeros(n, np.uint8), "t_s": t,
    }
    shards, per_shard = [], 250  # several shards, one boundary inside an episode
    for s, start in enumerate(range(0, n, per_shard)):
        name = f"shard_{s:05d}"
        (root / name).mkdir(parents=True, exist_ok=True)
        files = {}
        for k, a in fields.items():
            np.save(root / name / f"{k}.npy", np.ascontiguousarray(a[start : start + per_shard]))
            files[k] = f"{name}/{k}.npy"
        shards.append({"name": name, "samples": int(min(per_shard, n - start)), "files": files})
    index = {
        "format": "intention-fleet-demonstrations", "version": 1, "dataset_id": "synthetic-smoke",
        "command": "training/tests/test_smoke.py", "seed": seed, "noise": 0.0, "noise_peak_radps": 0.2,
        "image_px": PX, "every_cycles": 1, "dt_s": 0.1, "episode_s": 12.0, "max_speed_mps": 0.7,
        "max_turn_radps": 1.2, "dlm": ["turn_left", "turn_right", "go_forward", "stop"],
        "scenarios": [{"index": 0, "name": "synthetic_a", "path": "-"}, {"index": 1, "name": "synthetic_b", "path": "-"}],
        "samples": n,
        "fields": {k: {"dtype": str(a.dtype), "shape": list(a.shape[1:])} for k, a in fields.items()},
        "shards": shards,
    }
    (root / "index.json").write_text(json.dumps(index, indent=1))


def run(cmd: list[str]) -> str:
    print("$ " + " ".join(cmd), flush=True)
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        raise AssertionError(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stdout[-4000:]}\n{p.stderr[-4000:]}")
    return p.stdout


def check_kind(kind: str, data_dir: Path, out: Path, seconds: float, backbone: str = "small") -> dict:
    import onnxruntime as ort

    index = json.loads((data_dir / "index.json").read_text())
    px = index["fields"]["camera"]["shape"][0]
    lpe_px = index["fields"]["lpe"]["shape"][0]
    run([sys.executable, "-m", "training.train", "--kind", kind, "--data", str(data_dir), "--out", str(out),
         "--minutes", str(seconds / 60), "--threads", "1", "--seed", "3", "--backbone", backbone])
    for f in ("checkpoint_best.pt", "checkpoint_last.pt", "history.json", "loss.png", "card.json", f"{kind}.onnx", "summary.json"):
        assert (out / f).is_file(), f"{out / f} missing"
    sess = ort.InferenceSession(str(out / f"{kind}.onnx"), providers=["CPUExecutionProvider"])
    card = dict(sess.get_modelmeta().custom_metadata_map)
    card_mod.check(card)
    assert card["kind"] == kind and card["dataset_id"] == index["dataset_id"], card
    if backbone == "small-spatial":
        assert "keypoints" in card["backbone"] and "keypoints" in card["deviations"], card
    assert (card["image_width_px"], card["image_height_px"]) == (str(px), str(px)), card
    assert float(card["max_speed_mps"]) == index["max_speed_mps"] and float(card["max_turn_radps"]) == index["max_turn_radps"]
    for extra in ("recipe", "deviations", "train_loss", "per_intention_val_l1", "samples_seen", "training_minutes", "parameters"):
        assert extra in card, f"card lacks {extra}"
    if kind == "lpe":
        assert card_mod.lpe_input_px(card) == lpe_px, card
    if kind == "dlm":
        # The DLM the labels were derived with (a recording without dlm_params: curvature).
        assert card["dlm_measure"] == index.get("dlm_params", {}).get("measure", "curvature"), card
    feeds = {"camera": np.zeros((3, 3, px, px), np.float32)}
    if kind == "dlm":
        feeds["intention"] = np.eye(4, dtype=np.float32)[[0, 2, 3]]
    if kind == "lpe":
        feeds["lpe"] = np.zeros((3, 3, lpe_px, lpe_px), np.float32)
    (control,) = sess.run(["control"], feeds)
    assert control.shape == (3, 2) and np.all(np.abs(control) <= 1), control
    recorded = json.loads((out / "card.json").read_text())
    diff = float(recorded["onnx_max_abs_diff"])
    assert diff <= 1e-4, diff
    summary = json.loads((out / "summary.json").read_text())
    return {"kind": kind, "backbone": backbone, "max_abs_diff": diff, "val_loss": float(card["validation_loss"]),
            "epochs": summary["epochs"], "samples_per_s": summary["train_samples_per_s"]}


def check_frames_and_measures(data_dir: Path, work: Path) -> None:
    """The agent's check frames from the recording, then refreshed on the same frames (the same
    outputs); and recordings of two DLM measures are refused together."""
    import shutil

    models = work / "models"
    models.mkdir(exist_ok=True)
    for kind in ("dlm", "lpe", "none"):
        shutil.copy(work / kind / f"{kind}.onnx", models / f"{kind}.onnx")
    checks = work / "checks"
    run([sys.executable, "-m", "training.check_frames", "--data", str(data_dir), "--models", str(models),
         "--out", str(checks)])
    first = json.loads((checks / "expected.json").read_text())
    assert first["frames"] and set(first["frames"][0]["outputs"]) == {"dlm", "lpe", "none"}, first
    run([sys.executable, "-m", "training.check_frames", "--refresh", "--models", str(models), "--out", str(checks)])
    again = json.loads((checks / "expected.json").read_text())
    assert again["dataset_id"] == first["dataset_id"] and len(again["frames"]) == len(first["frames"])
    for a, b in zip(first["frames"], again["frames"]):
        assert a["dlm"] == b["dlm"] and a["label"] == b["label"]
        for kind in a["outputs"]:
            assert np.allclose(a["outputs"][kind], b["outputs"][kind], atol=1e-5), (a, b)

    heading = work / "data-heading"
    shutil.copytree(data_dir, heading)
    index = json.loads((heading / "index.json").read_text())
    index["dlm_params"] = {"measure": "heading"}
    index["dataset_id"] = "heading-" + str(index["dataset_id"])
    (heading / "index.json").write_text(json.dumps(index))
    p = subprocess.run([sys.executable, "-m", "training.train", "--kind", "dlm", "--data", str(data_dir), str(heading),
                        "--out", str(work / "mixed"), "--epochs", "1", "--threads", "1"],
                       cwd=ROOT, capture_output=True, text=True)
    assert p.returncode != 0 and "measure" in p.stderr, p.stderr[-2000:]


def check_rebuild(data_dir: Path, work: Path) -> None:
    """A warm start from an ONNX model alone (`training.from_onnx`): the rebuilt network agrees
    with onnxruntime (the command checks it and fails otherwise), `train.py --init` takes it (and
    keeps each epoch's checkpoint with --keep-epochs), and a wrong backbone is refused by name."""
    rebuilt = work / "rebuilt" / "checkpoint_best.pt"
    out = run([sys.executable, "-m", "training.from_onnx", "--model", str(work / "lpe-spatial" / "lpe.onnx"),
               "--backbone", "small-spatial", "--calibrate", str(data_dir), "--samples", "128", "--out", str(rebuilt)])
    assert "max |torch - onnxruntime|" in out and rebuilt.is_file(), out
    run([sys.executable, "-m", "training.train", "--kind", "lpe", "--backbone", "small-spatial", "--data", str(data_dir),
         "--out", str(work / "lpe-warm"), "--epochs", "2", "--samples-per-epoch", "128", "--threads", "1",
         "--init", str(rebuilt), "--keep-epochs"])
    card = json.loads((work / "lpe-warm" / "card.json").read_text())
    assert "warm-started" in card["deviations"], card["deviations"]
    # --keep-epochs: each epoch's weights, as the epoch ended, to judge in closed loop.
    import torch

    kept = sorted(p.name for p in (work / "lpe-warm").glob("checkpoint_e*.pt"))
    assert kept == ["checkpoint_e00.pt", "checkpoint_e01.pt"], kept
    first, last = (torch.load(work / "lpe-warm" / n, map_location="cpu", weights_only=False) for n in kept)
    assert (first["epoch"], last["epoch"]) == (0, 1), (first["epoch"], last["epoch"])
    assert any(not torch.equal(first["state_dict"][k], last["state_dict"][k]) for k in first["state_dict"])
    # --freeze-bn: the batch norms' running statistics stay the warm start's, the weights learn;
    # without it (lpe-warm) a fine-tune re-estimates them on its own data.
    run([sys.executable, "-m", "training.train", "--kind", "lpe", "--backbone", "small-spatial", "--data", str(data_dir),
         "--out", str(work / "lpe-frozen"), "--epochs", "1", "--samples-per-epoch", "128", "--threads", "1",
         "--init", str(rebuilt), "--freeze-bn"])
    init = torch.load(rebuilt, map_location="cpu", weights_only=False)["state_dict"]
    stats = [k for k in init if k.endswith(("running_mean", "running_var"))]
    assert len(stats) > 10, stats
    frozen = torch.load(work / "lpe-frozen" / "checkpoint_last.pt", map_location="cpu", weights_only=False)["state_dict"]
    assert all(torch.equal(frozen[k], init[k]) for k in stats), "--freeze-bn changed running statistics"
    assert any(not torch.equal(frozen[k], init[k]) for k in init if k not in stats), "--freeze-bn trained nothing"
    assert any(not torch.equal(first["state_dict"][k], init[k]) for k in stats), "an unfrozen fine-tune kept them"
    frozen_card = json.loads((work / "lpe-frozen" / "card.json").read_text())
    assert json.loads(frozen_card["recipe"]).get("freeze_bn") is True, frozen_card["recipe"]
    assert "running statistics kept" in frozen_card["deviations"], frozen_card["deviations"]
    p = subprocess.run([sys.executable, "-m", "training.train", "--kind", "lpe", "--data", str(data_dir),
                        "--out", str(work / "lpe-cold"), "--freeze-bn"], cwd=ROOT, capture_output=True, text=True)
    assert p.returncode != 0 and "--freeze-bn needs --init" in p.stderr, p.stderr[-2000:]
    p = subprocess.run([sys.executable, "-m", "training.from_onnx", "--model", str(work / "lpe-spatial" / "lpe.onnx"),
                        "--backbone", "small", "--calibrate", str(data_dir), "--out", str(work / "wrong.pt")],
                       cwd=ROOT, capture_output=True, text=True)
    assert p.returncode != 0 and "convolution" in p.stderr and not (work / "wrong.pt").exists(), p.stderr[-2000:]


def smoke(seconds: float = 30.0, data: str | None = None, keep: str | None = None) -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="training-smoke-") as tmp:
        work = Path(keep) if keep else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        data_dir = Path(data).resolve() if data else work / "data"
        if not data:
            write_synthetic(data_dir)
        print(run([sys.executable, "training/dataset.py", str(data_dir)]))
        results = [check_kind(k, data_dir, work / k, seconds) for k in ("dlm", "lpe", "none")]
        # The GPU round's backbone (average pool + soft-argmax keypoints) trains and exports too.
        results.append(check_kind("lpe", data_dir, work / "lpe-spatial", min(seconds, 15.0), backbone="small-spatial"))
        # The export command on its own, from a checkpoint.
        run([sys.executable, "-m", "training.export", "--checkpoint", str(work / "dlm" / "checkpoint_last.pt"),
             "--out", str(work / "reexport" / "dlm.onnx"), "--threads", "1"])
        assert (work / "reexport" / "dlm.onnx").is_file()
        check_frames_and_measures(data_dir, work)
        check_rebuild(data_dir, work)
    for r in results:
        print(f"smoke {r['kind']} ({r['backbone']}): {r['epochs']} epochs, {r['samples_per_s']} samples/s, "
              f"val loss {r['val_loss']:.4f}, onnxruntime vs torch max |diff| {r['max_abs_diff']:.2e}")
    return results


def test_smoke():
    smoke(float(os.environ.get("SMOKE_SECONDS", "30")))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="training smoke test")
    ap.add_argument("--seconds", type=float, default=30.0, help="training time per kind")
    ap.add_argument("--data", help="a real recording instead of the synthetic one")
    ap.add_argument("--keep", help="write everything under this folder instead of a temporary one")
    a = ap.parse_args()
    smoke(a.seconds, a.data, a.keep)
    print("smoke test passed")

"""Tests of `train.py --init-camera` (a new network's camera backbone from another kind's
checkpoint) and `--init-stop-from-forward`.

* a DLM-Net (small-spatial) gets exactly the camera weights (and batch-norm statistics) of an
  LPE-Net checkpoint of the same backbone; its intention layer and heads keep their own fresh
  weights; the checkpoint's dataset id is returned for the card;
* refused, naming what: a checkpoint of another backbone, one without a camera.

Needs torch only. CI runs it (scripts/training-smoke.sh).

    .venv/bin/python training/tests/test_init_camera.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import torch  # noqa: E402

from training import model  # noqa: E402
from training.train import load_camera  # noqa: E402


def _checkpoint(path: Path, config: dict, seed: int) -> torch.nn.Module:
    torch.manual_seed(seed)
    net = model.build(config)
    # Batch-norm statistics other than the defaults, so that copying them is checked too.
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-1.0, 1.0)
            m.running_var.uniform_(0.5, 2.0)
    torch.save({"model_config": config, "state_dict": net.state_dict(),
                "card_inputs": {"dataset_id": "0123456789abcdef"}}, path)
    return net


def _refused(net: torch.nn.Module, config: dict, path: Path, needle: str) -> None:
    try:
        load_camera(net, config, str(path))
    except SystemExit as e:
        assert needle in str(e), f"error does not name {needle!r}: {e}"
        return
    raise AssertionError(f"{path} was not refused")


def test_init_camera() -> None:
    dlm_config = {"kind": "dlm", "backbone": "small-spatial", "lpe_branch": "light"}
    lpe_config = {"kind": "lpe", "backbone": "small-spatial", "lpe_branch": "light"}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        lpe = _checkpoint(tmp / "lpe.pt", lpe_config, seed=1)
        torch.manual_seed(2)
        dlm = model.build(dlm_config)
        heads_before = {k: v.clone() for k, v in dlm.state_dict().items() if not k.startswith("camera.")}
        path, dataset = load_camera(dlm, dlm_config, str(tmp / "lpe.pt"))
        assert dataset == "0123456789abcdef" and path == str((tmp / "lpe.pt").resolve())
        theirs = lpe.camera.state_dict()
        ours = dlm.camera.state_dict()
        assert sorted(theirs) == sorted(ours) and len(ours) > 10
        for k, v in theirs.items():
            assert torch.equal(ours[k], v), k
        for k, v in dlm.state_dict().items():
            if not k.startswith("camera."):
                assert torch.equal(v, heads_before[k]), f"{k} changed"
        # The same image through both cameras gives the same features (eval mode: running stats).
        lpe.eval(), dlm.eval()
        x = torch.rand(2, 3, 128, 128, generator=torch.Generator().manual_seed(3))
        torch.testing.assert_close(dlm.camera(x), lpe.camera(x))

        _checkpoint(tmp / "small.pt", {"kind": "lpe", "backbone": "small", "lpe_branch": "light"}, seed=4)
        _refused(dlm, dlm_config, tmp / "small.pt", "'small'")
        torch.save({"model_config": dlm_config, "state_dict": {"heads.0.0.weight": torch.zeros(1)}}, tmp / "none.pt")
        _refused(dlm, dlm_config, tmp / "none.pt", "no camera")
    print("train.py --init-camera: ok")


def test_init_stop_from_forward() -> None:
    """`--init-stop-from-forward`: after `copy_intention(go_forward, stop)` the stop one-hot
    drives exactly as go_forward does, the turns as before."""
    torch.manual_seed(5)
    net = model.build({"kind": "dlm", "backbone": "small", "lpe_branch": "light"}).eval()
    x = torch.rand(2, 3, 96, 96, generator=torch.Generator().manual_seed(6))
    hot = torch.eye(4)

    def drive(i: int) -> torch.Tensor:
        return net(x, hot[i].expand(2, 4))

    left, forward = drive(0), drive(2)
    assert not torch.allclose(drive(3), forward)
    net.copy_intention(2, 3)
    torch.testing.assert_close(drive(3), forward)
    torch.testing.assert_close(drive(0), left)
    print("train.py --init-stop-from-forward: ok")


if __name__ == "__main__":
    test_init_camera()
    test_init_stop_from_forward()

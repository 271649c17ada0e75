"""Test of `python -m training.activations` on the shipped models and check frames.

* for models/lpe.onnx and models/dlm.onnx: the figure is written into a temp dir, the model's
  outputs matched expected.json (the command checks that on all 12 frames), and the PNG has the
  size of its grid (rows x columns of square panels plus the label margin and header);
* a tampered expected.json makes the command stop with an explanation.

Skipped when onnx, onnxruntime, matplotlib or Pillow are missing (no torch needed). CI runs it
(scripts/training-smoke.sh).

    .venv/bin/python training/tests/test_activations.py
    .venv/bin/python -m pytest training/tests/test_activations.py      # the same, with pytest
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

MISSING = [m for m in ("onnx", "onnxruntime", "matplotlib", "PIL") if importlib.util.find_spec(m) is None]
MODELS = ROOT / "models"
CHECKS = MODELS / "checks"

try:
    import pytest
except ImportError:  # run as a script
    pytest = None
else:
    pytestmark = pytest.mark.skipif(bool(MISSING), reason=f"needs {', '.join(MISSING)}")


def _figure(kind: str, out_dir: Path, columns: int, rows: int = 4) -> None:
    from PIL import Image

    from training import activations

    out = out_dir / f"activations-{kind}.png"
    model = MODELS / f"{kind}.onnx"
    assert activations.main(["--model", str(model), "--frames", str(CHECKS), "--out", str(out),
                             "--rows", str(rows)]) == 0
    assert out.exists() and out.stat().st_size > 10_000
    w_in, h_in = activations.figure_size(columns, rows)
    with Image.open(out) as img:
        assert img.format == "PNG"
        assert img.size == (round(w_in * activations.DPI), round(h_in * activations.DPI)), img.size
        width, height = img.size
    # square panels: the grid part is columns:rows
    grid_w = width - activations.LABEL_IN * activations.DPI
    grid_h = height - activations.HEADER_IN * activations.DPI
    assert abs(grid_w / grid_h - columns / rows) < 0.01


def test_lpe_figure(tmp_path: Path) -> None:
    # camera, LPE, camera early/middle/late, LPE-branch early/late
    _figure("lpe", tmp_path, columns=7)


def test_dlm_figure(tmp_path: Path) -> None:
    # camera, camera early/middle/late; 2 rows also works
    _figure("dlm", tmp_path, columns=4)
    _figure("dlm", tmp_path, columns=4, rows=2)


def test_mismatch_stops(tmp_path: Path) -> None:
    from training import activations

    frames = tmp_path / "checks"
    shutil.copytree(CHECKS, frames)
    doc = json.loads((frames / "expected.json").read_text())
    doc["frames"][3]["outputs"]["lpe"][1] += 1e-3
    (frames / "expected.json").write_text(json.dumps(doc))
    try:
        activations.main(["--model", str(MODELS / "lpe.onnx"), "--frames", str(frames),
                          "--out", str(tmp_path / "x.png")])
    except SystemExit as e:
        assert "frame 03" in str(e) and "expected.json" in str(e), e
    else:
        raise AssertionError("a wrong expected output was not noticed")
    assert not (tmp_path / "x.png").exists()


if __name__ == "__main__":
    if MISSING:
        print(f"skipped: needs {', '.join(MISSING)}")
        sys.exit(0)
    for test in (test_lpe_figure, test_dlm_figure, test_mismatch_stops):
        with tempfile.TemporaryDirectory() as d:
            test(Path(d))
        print(f"ok {test.__name__}")

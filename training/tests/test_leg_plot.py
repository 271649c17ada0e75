"""Test of scripts/leg_plot.py on run logs written here in the format of docs/logs.md
(`/intention` and `/ground_truth`, JSON): a robot drives along x at 0.5 m/s; the intention names
goal index 1 from 4 s; the judge carries it 1 m ahead at 6 s. The leg starts at 4 s, the trace is
cut at the carry, the intervention is matched to its run, the picture is written over a floor
plan made here, and a --runs without its parts is refused, naming the form.

    .venv/bin/python training/tests/test_leg_plot.py
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))

import leg_plot  # noqa: E402
import run_log  # noqa: E402


def write_log(path: Path) -> None:
    def records():
        for k in range(100):  # 10 s at 10 Hz
            t = k / 10
            x = 0.05 * k + (1.0 if t >= 6 else 0.0)
            header = {"seq": k, "stamp_ns": int(round(t * 1e9))}
            yield "/ground_truth", {"header": header, "pose": {"x_m": x, "y_m": 1.0, "yaw_rad": 0.0}}
            yield "/intention", {"header": header, "goal_index": 0 if t < 4 else 1, "dlm": "go_forward"}

    run_log.write(path, {"/intention": "fleet.Intention", "/ground_truth": "fleet.StampedPose"}, records())


def main() -> None:
    from PIL import Image

    with tempfile.TemporaryDirectory(prefix="leg-") as tmp:
        tmp = Path(tmp)
        logs, table = tmp / "logs", tmp / "table"
        logs.mkdir()
        table.mkdir()
        write_log(logs / "task_x-dlm-seed0.mcap")
        start, trace = leg_plot.leg(logs / "task_x-dlm-seed0.mcap", 1, 3.0)
        assert abs(start - 4.0) < 1e-9, start
        # After 4.0 s (the pose of 4.0 s was logged before the intention) to 7.0 s: 30 poses,
        # carried 1 m between 5.9 and 6.0 s.
        assert len(trace) == 30 and abs(trace[0][0] - 2.05) < 1e-9, (len(trace), trace[0])
        cut = leg_plot.pieces(trace)
        assert [len(c) for c in cut] == [19, 11], [len(c) for c in cut]
        assert leg_plot.leg(logs / "task_x-dlm-seed0.mcap", 2, 3.0) == (None, [])
        (table / "runs.json").write_text(json.dumps([
            {"scenario": "task_x", "seed": 0, "intervention_log": [{"t_s": 5.95, "x_m": 3.0, "y_m": 1.0, "cause": "no progress"}]},
            {"scenario": "task_y", "seed": 0, "intervention_log": []},
        ]))
        assert leg_plot.interventions(table, "task_x")[0][0]["x_m"] == 3.0
        Image.new("L", (120, 40), 254).save(tmp / "plan.pgm")
        (tmp / "plan.yaml").write_text("image: plan.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n")
        out = tmp / "fig" / "leg.png"
        assert leg_plot.main(["--map", str(tmp / "plan.yaml"), "--task", "task_x", "--goal-index", "1",
                              "--span-s", "3", "--out", str(out), "--runs", f"run={logs}:{table}"]) == 0
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        try:
            leg_plot.main(["--map", str(tmp / "plan.yaml"), "--task", "task_x", "--goal-index", "1",
                           "--out", str(out), "--runs", str(logs)])
        except SystemExit as e:
            assert "LABEL=LOGS:TABLE" in str(e), e
        else:
            raise AssertionError("a --runs without a label and table was accepted")
    print("leg plot test passed")


def test_leg_plot():
    main()


if __name__ == "__main__":
    main()

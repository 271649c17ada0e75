"""Test of scripts/setoff_plot.py on a run log written here in the format of docs/logs.md
(`/cmd_vel` and `/ground_truth`, JSON): a robot drives along x at 0.5 m/s, passes 4.7 m at
9.4 s, stops at (5, 0) at 10 s, stands and turns on the spot from 11 s, and drives off from 13 s. The window is aligned
at the reach, the turn and the set-off are found at their times, the picture is written, and
a point never reached is refused, naming it.

    .venv/bin/python training/tests/test_setoff_plot.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))

import run_log  # noqa: E402
import setoff_plot  # noqa: E402


def write_log(path: Path) -> None:
    def records():
        for k in range(200):  # 20 s at 10 Hz
            t = k / 10
            v, w_ = (0.5, 0.0) if t < 10 else ((0.0, 1.0) if 11 <= t < 13 else ((0.6, 0.0) if t >= 13 else (0.0, 0.0)))
            x = 0.05 * min(k, 100)
            header = {"seq": k, "stamp_ns": int(round(t * 1e9))}
            yield "/ground_truth", {"header": header, "pose": {"x_m": x, "y_m": 0.0, "yaw_rad": 0.0}}
            yield "/cmd_vel", {"header": header, "v_mps": v, "omega_radps": w_}

    run_log.write(path, {"/cmd_vel": "fleet.CmdVel", "/ground_truth": "fleet.StampedPose"}, records())


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="setoff-") as tmp:
        log = Path(tmp) / "run.mcap"
        write_log(log)
        r = setoff_plot.around(log, (5.0, 0.0), 0.32, 6.0, 14.0)
        times = [t for t, _, _ in r["window"]]
        # Within 0.32 m of x = 5 from x = 4.70, reached at 9.4 s; the log ends at 19.9 s.
        assert abs(times[0] + 6.0) < 1e-6 and abs(max(times) - 10.5) < 1e-6, (times[0], max(times))
        assert abs(r["turn_s"] - 1.6) < 1e-6, r["turn_s"]
        assert abs(r["moving_s"] - 3.6) < 1e-6, r["moving_s"]
        out = Path(tmp) / "fig" / "setoff.png"
        assert setoff_plot.main(["--point", "5", "0", "--out", str(out), "--log", f"run={log}"]) == 0
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        try:
            setoff_plot.around(log, (50.0, 0.0), 0.35, 6.0, 14.0)
        except ValueError as e:
            assert "(50.0, 0.0)" in str(e), e
        else:
            raise AssertionError("a point never reached gave a window")
        try:
            setoff_plot.main(["--point", "5", "0", "--out", str(out), "--log", str(log)])
        except SystemExit as e:
            assert "LABEL=PATH" in str(e), e
        else:
            raise AssertionError("a --log without a label was accepted")
    print("setoff plot test passed")


def test_setoff_plot():
    main()


if __name__ == "__main__":
    main()

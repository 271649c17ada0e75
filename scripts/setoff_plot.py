"""How a controller arrives at and leaves a place: the commanded speed and turn rate of run logs
(`eval table --record-dir`, docs/logs.md) around the first moment the robot's true pose comes
within a radius of a point, one line per log, aligned at that moment.

Made for the corner goal of task C (33, 23), where LPE-Net r39 alone stalled after the goal and
r44 does not (docs/evaluation.md, round 44):

  .venv/bin/python scripts/setoff_plot.py --point 33 23 --out docs/figures/round44-corner-setoff.png \\
      --log "r39 seed 0=out/s47/logs-r39/task_c-lpe-seed0.mcap" --log "r44 seed 0=out/s47/logs-t3/task_c-lpe-seed0.mcap"

It prints, for each log, when the turn on the spot started (|omega| above 0.5 rad/s) and when the
speed was back at 0.3 m/s after it. Needs mcap (scripts/setup.sh installs it) and matplotlib.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import run_log

TURN_RADPS = 0.5
MOVING_MPS = 0.3


def read_log(path: Path) -> tuple[list[tuple[float, float, float]], list[tuple[float, float, float]]]:
    """(t, v, omega) of /cmd_vel and (t, x, y) of /ground_truth, in stamp order."""
    cmd, pose = [], []
    for topic, t, d in run_log.messages(path, ["/cmd_vel", "/ground_truth"]):
        if topic == "/cmd_vel":
            cmd.append((t, d["v_mps"], d["omega_radps"]))
        else:
            pose.append((t, d["pose"]["x_m"], d["pose"]["y_m"]))
    return cmd, pose


def around(path: Path, point: tuple[float, float], radius_m: float, before_s: float, after_s: float) -> dict:
    """The log's commands from `before_s` before to `after_s` after it first came within
    `radius_m` of `point`, the times relative to that moment, and when it turned and set off."""
    cmd, pose = read_log(path)
    reach = next((t for t, x, y in pose if math.hypot(x - point[0], y - point[1]) <= radius_m), None)
    if reach is None:
        raise ValueError(f"{path}: the robot never came within {radius_m} m of {point}")
    window = [(t - reach, v, w) for t, v, w in cmd if -before_s <= t - reach <= after_s]
    turn = next((t for t, _, w in window if t > 0 and abs(w) > TURN_RADPS), None)
    moving = next((t for t, v, _ in window if turn is not None and t > turn and v >= MOVING_MPS), None)
    return {"window": window, "turn_s": turn, "moving_s": moving}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--log", action="append", required=True, metavar="LABEL=PATH", help="a run log and its legend label")
    p.add_argument("--point", nargs=2, type=float, required=True, metavar=("X_M", "Y_M"), help="the place, map frame")
    p.add_argument("--radius-m", type=float, default=0.35, help="within this of the point counts as there (the goal tolerance)")
    p.add_argument("--before-s", type=float, default=6.0)
    p.add_argument("--after-s", type=float, default=14.0)
    p.add_argument("--title", default=None)
    p.add_argument("--out", required=True, help="PNG to write")
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_v, ax_w) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for item in args.log:
        label, sep, path = item.partition("=")
        if not sep or not label or not path:
            raise SystemExit(f"--log {item!r}: expected LABEL=PATH")
        r = around(Path(path), tuple(args.point), args.radius_m, args.before_s, args.after_s)
        t = [a for a, _, _ in r["window"]]
        (line,) = ax_v.plot(t, [v for _, v, _ in r["window"]], label=label)
        ax_w.plot(t, [w for _, _, w in r["window"]], color=line.get_color())
        print(f"{label}: turn on the spot from {r['turn_s']} s, back at {MOVING_MPS} m/s at {r['moving_s']} s after reaching the point")
    ax_v.set_ylabel("commanded v (m/s)")
    ax_w.set_ylabel("commanded ω (rad/s)")
    ax_w.set_xlabel(f"s after coming within {args.radius_m} m of ({args.point[0]:g}, {args.point[1]:g})")
    for a in (ax_v, ax_w):
        a.axvline(0, color="k", lw=0.8, ls=":")
        a.grid(alpha=0.3)
    ax_v.legend(fontsize=8)
    ax_v.set_title(args.title or f"commands around ({args.point[0]:g}, {args.point[1]:g})")
    fig.tight_layout()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp.png")
    fig.savefig(tmp, dpi=100)
    tmp.replace(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Where robots went when a leg of a task began: the true traces of run logs (`eval table
--record-dir`, docs/logs.md) from the moment the intention first names a goal index (the goal
before it reached) for a few seconds, drawn over the floor plan, one panel per set of runs, with
the judge's interventions of that window (from the table's `runs.json`) as crosses and the runs
that had one in red.

Made for the turns round after a goal of DLM-Net r49 alone (docs/evaluation.md, round 53):

  .venv/bin/python scripts/leg_plot.py --map sim/scenarios/maps/maze.yaml --task task_e \\
      --goal-index 3 --span-s 12 --box 5 17 5 12.5 --out /tmp/e3.png \\
      --runs "before=out/s55/logs-cde20:out/s55/cde20" --runs "after=out/s56/logs-at26-20:out/s56/t20-at26-alone"

`--runs LABEL=LOGS:TABLE`: LOGS is the `--record-dir` folder (`<task>-<method>-seed<N>.mcap`),
TABLE the `--out` folder whose `runs.json` has the interventions. Needs mcap (scripts/setup.sh
installs it), matplotlib, numpy and Pillow.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import ros_map
import run_log

# A jump of the true pose larger than this between two messages is the judge carrying the robot.
JUMP_M = 0.3


def leg(path: Path, goal_index: int, span_s: float) -> tuple[float | None, list[tuple[float, float]]]:
    """When the intention first named `goal_index` (s, the log's stamps) and the true (x, y) of
    the `span_s` after it; (None, []) when it never did."""
    start, trace = None, []
    for topic, t, d in run_log.messages(path, ["/intention", "/ground_truth"]):
        if topic == "/intention":
            if start is None and d.get("goal_index") == goal_index:
                start = t
        elif start is not None and t <= start + span_s:
            trace.append((d["pose"]["x_m"], d["pose"]["y_m"]))
    return start, trace


def pieces(trace: list[tuple[float, float]]) -> list[list[tuple[float, float]]]:
    """`trace` cut where the robot was carried (a jump over `JUMP_M`)."""
    out: list[list[tuple[float, float]]] = []
    for p in trace:
        if out and math.dist(out[-1][-1], p) <= JUMP_M:
            out[-1].append(p)
        else:
            out.append([p])
    return out


def interventions(table: Path, task: str) -> dict[int, list[dict]]:
    """The judge's interventions of `task`'s runs in `table`/runs.json, by seed."""
    runs = json.loads((table / "runs.json").read_text())
    return {r["seed"]: r["intervention_log"] for r in runs if r["scenario"] == task}


def floor_plan(yaml_path: Path):
    """The ROS map's image (grey levels) and its extent in metres (left, right, bottom, top)."""
    import numpy as np
    from PIL import Image

    meta = ros_map.read_yaml(yaml_path)
    img = np.array(Image.open(meta["image"]).convert("L"))
    (x0, y0), res = meta["origin_m"], meta["resolution_m"]
    return img, (x0, x0 + img.shape[1] * res, y0, y0 + img.shape[0] * res)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--map", type=Path, required=True, help="the task's floor plan (ROS map YAML)")
    p.add_argument("--task", required=True, help="the scenario name in runs.json, e.g. task_e")
    p.add_argument("--method", default="dlm", help="the method in the log names")
    p.add_argument("--goal-index", type=int, required=True, help="the leg: the index of the goal it goes to")
    p.add_argument("--span-s", type=float, default=12.0, help="seconds drawn from the leg's start")
    p.add_argument("--box", nargs=4, type=float, metavar=("X0", "X1", "Y0", "Y1"), help="the part of the map shown")
    p.add_argument("--runs", action="append", required=True, metavar="LABEL=LOGS:TABLE",
                   help="a panel: run logs folder and table folder")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)
    panels = []
    for spec in args.runs:
        label, sep, rest = spec.partition("=")
        logs, sep2, table = rest.rpartition(":")
        if not (sep and sep2 and label and logs and table):
            raise SystemExit(f"--runs wants LABEL=LOGS:TABLE, not {spec!r}")
        panels.append((label, Path(logs), Path(table)))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    img, extent = floor_plan(args.map)
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4.2), squeeze=False)
    for ax, (label, logs, table) in zip(axes[0], panels):
        ax.imshow(img, cmap="gray", extent=extent, vmin=0, vmax=255)
        by_seed = interventions(table, args.task)
        total = 0
        for log in sorted(logs.glob(f"{args.task}-{args.method}-seed*.mcap")):
            seed = int(log.stem.rsplit("seed", 1)[1])
            start, trace = leg(log, args.goal_index, args.span_s)
            if start is None:
                continue
            hits = [i for i in by_seed.get(seed, []) if start <= i["t_s"] <= start + args.span_s]
            total += len(hits)
            for piece in pieces(trace):
                xs, ys = zip(*piece)
                ax.plot(xs, ys, color="tab:red" if hits else "tab:blue", lw=0.9, alpha=0.7)
            for i in hits:
                ax.plot(i["x_m"], i["y_m"], "kx", ms=7)
            ax.plot(*trace[0], "o", color="tab:green", ms=3)
            print(f"{label} seed {seed}: leg from {start:.1f} s, {len(hits)} interventions in {args.span_s:g} s")
        if args.box:
            ax.set_xlim(args.box[0], args.box[1])
            ax.set_ylim(args.box[2], args.box[3])
        ax.set_aspect("equal")
        ax.set_title(f"{label}\n{total} interventions", fontsize=9)
    fig.suptitle(f"{args.task}, {args.span_s:g} s from the start of the leg to goal index {args.goal_index} "
                 "(green: start; red: runs with an intervention; x: where)", fontsize=9)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_name(args.out.name + ".tmp.png")
    fig.savefig(tmp, dpi=110)
    tmp.replace(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

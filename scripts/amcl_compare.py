#!/usr/bin/env python3
"""Our AMCL and Nav2's particle filter, side by side on the same MCAP run logs (issue 18).

For every log (written by `eval amcl-accuracy --record-dir`, `eval table --record-dir`,
`robot-agent --record` or `sim --record`) this replays the log's scans and odometry

- through our filter: `robot-agent replay` (the agent's own AMCL, the log's recorded
  configuration), and
- through Nav2's: PyPI's `amcl` (0.1.2), which wraps Nav2's C particle filter (`pf_*`, kd-tree,
  KLD sampling, Nav2's differential motion model) with Nav2's beam sensor model,

with matched settings: the same particle bounds, beams, motion noise (the four alphas have the
same meaning in both), hit/random mixture and sigma, the same update gating (a filter update
once the odometry moved `update_min_d_m` or turned `update_min_a_rad`; between updates the
estimate is carried forward by the odometry, as the agent publishes it), the same initial pose
and the same re-initialisations (`/initialpose`, e.g. after an intervention). What cannot be
matched: Nav2's wrapper has no likelihood-field model (ours is a likelihood field), and its
random source is not seedable.

Both estimates are compared with the log's ground truth at every scan. Per log it reports the
mean and max position and heading error, the time per filter update, and the ratio
ours / Nav2's, as a markdown table (stdout and OUT/compare.md) and JSON (OUT/compare.json).

Usage:
  .venv/bin/python scripts/amcl_compare.py --out out/amcl-compare LOG.mcap [LOG.mcap ...]
  options: --agent PATH (robot-agent binary, default target/release/robot-agent),
           --particles N (pin both filters to N particles, e.g. 2000 for the timing target)
Needs: pip install amcl==0.1.2 mcap zstandard (scripts/setup.sh installs them into .venv).
"""

from __future__ import annotations

import argparse
import bisect
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import ros_map

try:
    import amcl
    from mcap.reader import make_reader
except ImportError as e:  # pragma: no cover - a setup error, said clearly
    sys.exit(f"amcl_compare: {e}; run scripts/setup.sh (it installs amcl==0.1.2, mcap, zstandard into .venv)")

ROOT = Path(__file__).resolve().parent.parent

# Nav2's beam model has terms our likelihood field does not: Nav2's defaults for them.
NAV2_Z_SHORT = 0.05
NAV2_Z_MAX = 0.05
NAV2_LAMBDA_SHORT = 0.1
NAV2_CHI_OUTLIER = 0.0


def normalize(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


# ----- the log ------------------------------------------------------------------------------

class RunLog:
    """The messages of one log that a localization replay needs, each list in time order."""

    def __init__(self, path: Path):
        self.path = path
        self.map_info = None
        self.agent_config = None
        self.scans, self.odom, self.truth, self.initial_poses = [], [], [], []
        with open(path, "rb") as f:
            reader = make_reader(f)
            for _schema, channel, message in reader.iter_messages(log_time_order=True):
                topic = channel.topic
                if topic not in ("/map", "/agent_config", "/scan", "/odom", "/ground_truth", "/initialpose"):
                    continue
                body = json.loads(message.data)
                if topic == "/map":
                    self.map_info = body
                elif topic == "/agent_config":
                    self.agent_config = body
                elif topic == "/scan":
                    self.scans.append(body)
                elif topic == "/odom":
                    self.odom.append(body)
                elif topic == "/ground_truth":
                    self.truth.append(body)
                else:
                    self.initial_poses.append(body)
        if self.map_info is None:
            raise SystemExit(f"{path}: no /map message: cannot tell which floor plan it ran on")
        if not self.truth:
            raise SystemExit(f"{path}: no /ground_truth: nothing to compare the filters against")
        self.odom_stamps = [o["header"]["stamp_ns"] for o in self.odom]
        self.truth_stamps = [t["header"]["stamp_ns"] for t in self.truth]

    def odom_at(self, stamp_ns: int):
        """The newest odometry at or before the stamp, else the oldest (as the agent picks it)."""
        i = bisect.bisect_right(self.odom_stamps, stamp_ns) - 1
        if i < 0:
            return self.odom[0] if self.odom else None
        return self.odom[i]

    def truth_at(self, stamp_ns: int):
        i = bisect.bisect_left(self.truth_stamps, stamp_ns)
        best = None
        for j in (i - 1, i):
            if 0 <= j < len(self.truth):
                if best is None or abs(self.truth_stamps[j] - stamp_ns) < abs(self.truth_stamps[best] - stamp_ns):
                    best = j
        return None if best is None else self.truth[best]["pose"]

    def map_yaml(self) -> Path:
        p = self.map_info.get("path")
        if not p:
            raise SystemExit(f"{self.path}: /map names no floor-plan file")
        path = Path(p)
        if not path.is_absolute():
            path = (self.path.parent / path) if (self.path.parent / path).exists() else (ROOT / path)
        if not path.exists():
            raise SystemExit(f"{self.path}: floor plan {p} not found")
        return path


# ----- the floor plan ----------------------------------------------------------------------

def read_pgm(path: Path):
    data = path.read_bytes()
    tokens, pos = [], 0
    while len(tokens) < 4:
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            while data[pos:pos + 1] not in (b"\n", b""):
                pos += 1
            continue
        start = pos
        while not data[pos:pos + 1].isspace():
            pos += 1
        tokens.append(data[start:pos])
    magic, width, height, maxval = tokens[0], int(tokens[1]), int(tokens[2]), int(tokens[3])
    if magic == b"P5" and maxval < 256:
        pixels = data[pos + 1:pos + 1 + width * height]
    elif magic == b"P2":
        pixels = [int(t) for t in data[pos:].split()][: width * height]
    else:
        raise SystemExit(f"{path}: unsupported image (need an 8-bit P5 or P2 PGM)")
    if len(pixels) != width * height:
        raise SystemExit(f"{path}: truncated image")
    return width, height, maxval, pixels


def load_ros_map(yaml_path: Path):
    """A ROS map (YAML + PGM) as Nav2's grid: rows bottom-up, 0 free / 100 occupied / -1 unknown."""
    meta = ros_map.read_yaml(yaml_path)
    negate, occ_t, free_t = meta["negate"], meta["occupied_thresh"], meta["free_thresh"]
    width, height, maxval, pixels = read_pgm(meta["image"])
    rows = []
    for r in range(height - 1, -1, -1):  # the image's top row is the map's last
        row = []
        for c in range(width):
            p = pixels[r * width + c] / maxval
            occ = p if negate else 1.0 - p
            row.append(100 if occ > occ_t else 0 if occ < free_t else -1)
        rows.append(row)
    return rows, meta["resolution_m"], meta["origin_m"][0], meta["origin_m"][1]


# ----- Nav2's filter -----------------------------------------------------------------------

def amcl_settings(log: RunLog, particles: int | None) -> dict:
    a = (log.agent_config or {}).get("amcl", {})
    s = {
        "min_particles": a.get("min_particles", 500), "max_particles": a.get("max_particles", 2000),
        "alpha1": a.get("alpha1", 0.05), "alpha2": a.get("alpha2", 0.02),
        "alpha3": a.get("alpha3", 0.02), "alpha4": a.get("alpha4", 0.02),
        "z_hit": a.get("z_hit", 0.5), "z_rand": a.get("z_rand", 0.5),
        "sigma_hit_m": a.get("sigma_hit_m", 0.2), "max_beams": a.get("max_beams", 60),
        "alpha_slow": a.get("recovery_alpha_slow", 0.0), "alpha_fast": a.get("recovery_alpha_fast", 0.0),
        "update_min_d_m": a.get("update_min_d_m", 0.05), "update_min_a_rad": a.get("update_min_a_rad", 0.05),
        "laser": a.get("robot_from_laser", {"x_m": 0.0, "y_m": 0.0, "yaw_rad": 0.0}),
    }
    if particles:
        s["min_particles"] = s["max_particles"] = particles
    return s


def matrix(cov9):
    m = amcl.Matrix3D()
    m.from_list([list(cov9[0:3]), list(cov9[3:6]), list(cov9[6:9])])
    return m


class Nav2Filter:
    def __init__(self, grid, s: dict, pose, cov9):
        motion = amcl.MotionParameters(alpha1=s["alpha1"], alpha2=s["alpha2"], alpha3=s["alpha3"],
                                       alpha4=s["alpha4"], alpha5=0.0)
        laser = amcl.LaserParameters(z_hit=s["z_hit"], z_short=NAV2_Z_SHORT, z_max=NAV2_Z_MAX,
                                     z_rand=s["z_rand"], sigma_hit=s["sigma_hit_m"],
                                     lambda_short=NAV2_LAMBDA_SHORT, chi_outlier=NAV2_CHI_OUTLIER,
                                     max_beams=s["max_beams"])
        self.pf = amcl.AMCL(s["min_particles"], s["max_particles"], s["alpha_slow"], s["alpha_fast"],
                            motion, laser, "differential")
        self.pf.set_map(grid)
        lz = s["laser"]
        self.pf.set_laser_pose(amcl.Vector3D(lz["x_m"], lz["y_m"], lz["yaw_rad"]))
        self.pf.set_initial_pose(amcl.Vector3D(pose["x_m"], pose["y_m"], pose["yaw_rad"]), matrix(cov9))
        self.estimate = (pose["x_m"], pose["y_m"], pose["yaw_rad"])
        self.odom_at_update = None

    def due(self, odom, s) -> bool:
        if self.odom_at_update is None:
            return True
        b = self.odom_at_update
        d = math.hypot(odom["x_m"] - b["x_m"], odom["y_m"] - b["y_m"])
        return d >= s["update_min_d_m"] or abs(normalize(odom["yaw_rad"] - b["yaw_rad"])) >= s["update_min_a_rad"]

    def update(self, scan_obj, odom) -> float:
        t0 = time.perf_counter()
        self.pf.update(scan_obj, amcl.Vector3D(odom["x_m"], odom["y_m"], odom["yaw_rad"]))
        ms = (time.perf_counter() - t0) * 1e3
        m = self.pf.get_pose_mean()
        self.estimate = (m.x, m.y, m.theta)
        self.odom_at_update = odom
        return ms

    def predict(self, odom):
        """The estimate carried forward by the odometry since the last update."""
        b = self.odom_at_update
        if b is None:
            return self.estimate
        s, c = math.sin(b["yaw_rad"]), math.cos(b["yaw_rad"])
        dx, dy = odom["x_m"] - b["x_m"], odom["y_m"] - b["y_m"]
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        x, y, yaw = self.estimate
        s, c = math.sin(yaw), math.cos(yaw)
        return (x + c * lx - s * ly, y + s * lx + c * ly, normalize(yaw + odom["yaw_rad"] - b["yaw_rad"]))


def scan_for_nav2(scan):
    rmin, rmax = scan["range_min_m"], scan["range_max_m"]
    a0, inc = scan["angle_min_rad"], scan["angle_increment_rad"]
    pairs = []
    for i, r in enumerate(scan["ranges_m"]):
        if r < rmin:  # too close to measure: Nav2's node reports these as max range
            r = rmax
        pairs.append([float(r), a0 + i * inc])
    return amcl.create_laser_scan_from_list(pairs, float(rmax))


def run_nav2(log: RunLog, s: dict):
    rows, res, ox, oy = load_ros_map(log.map_yaml())
    grid = amcl.create_occupancy_grid_from_list(rows, res, ox, oy)
    init = log.map_info.get("initial_pose")
    if init is None:
        raise SystemExit(f"{log.path}: no initial pose; both filters are compared from a known start")
    cov = log.map_info.get("initial_covariance") or [0.0225, 0, 0, 0, 0.0225, 0, 0, 0, 0.01]
    flt = Nav2Filter(grid, s, init, cov)
    reinit = sorted(log.initial_poses, key=lambda p: p["header"]["stamp_ns"])
    next_reinit = 0
    out, update_ms = [], []
    for scan in log.scans:
        stamp = scan["header"]["stamp_ns"]
        while next_reinit < len(reinit) and reinit[next_reinit]["header"]["stamp_ns"] <= stamp:
            p = reinit[next_reinit]
            # A fresh filter: the wrapper measures motion from the odometry of its first update.
            flt = Nav2Filter(grid, s, p["pose"], p["covariance"])
            next_reinit += 1
        odom = log.odom_at(stamp)
        if odom is None:
            continue
        if flt.due(odom["pose"], s):
            update_ms.append(flt.update(scan_for_nav2(scan), odom["pose"]))
        out.append((stamp, flt.predict(odom["pose"])))
    return out, update_ms


# ----- ours --------------------------------------------------------------------------------

def run_ours(log: RunLog, agent: Path, particles: int | None):
    with tempfile.TemporaryDirectory() as tmp:
        poses = Path(tmp) / "poses.jsonl"
        cmd = [str(agent), "replay", "--log", str(log.path), "--map", str(log.map_yaml()), "--out", str(poses)]
        if particles:
            cmd += ["--particles", str(particles)]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stderr}")
        out, update_ms = [], []
        for line in read_poses(poses):
            out.append((line["stamp_ns"], (line["x_m"], line["y_m"], line["yaw_rad"])))
            if line["filter_ran"]:
                update_ms.append(line["update_ms"])
        return out, update_ms


def read_poses(path: Path):
    """`robot-agent replay --out *.jsonl`: one estimate per scan."""
    for l in path.read_text().splitlines():
        if l.strip():
            yield json.loads(l)


# ----- comparison --------------------------------------------------------------------------

def errors(log: RunLog, estimates):
    pos, head = [], []
    for stamp, (x, y, yaw) in estimates:
        t = log.truth_at(stamp)
        if t is None:
            continue
        pos.append(math.hypot(x - t["x_m"], y - t["y_m"]))
        head.append(abs(math.degrees(normalize(yaw - t["yaw_rad"]))))
    return pos, head


def summary(pos, head, ms):
    mean = lambda v: sum(v) / len(v) if v else float("nan")
    return {
        "cycles": len(pos), "updates": len(ms),
        "mean_position_error_m": mean(pos), "max_position_error_m": max(pos, default=float("nan")),
        "mean_heading_error_deg": mean(head), "max_heading_error_deg": max(head, default=float("nan")),
        "mean_update_ms": mean(ms), "max_update_ms": max(ms, default=float("nan")),
    }


def markdown(rows) -> str:
    out = ("| log | particles | beams | filter | mean pos. err (m) | max pos. err (m) | mean heading err (deg) "
           "| max heading err (deg) | ms / update | cycles / updates |\n|---|---|---|---|---|---|---|---|---|---|\n")
    for r in rows:
        for name in ("ours", "nav2"):
            f = r[name]
            out += (f"| {r['log']} | {r['particles']} | {r['beams']} | {name} | {f['mean_position_error_m']:.3f} | "
                    f"{f['max_position_error_m']:.3f} | {f['mean_heading_error_deg']:.2f} | {f['max_heading_error_deg']:.2f} | "
                    f"{f['mean_update_ms']:.2f} | {f['cycles']} / {f['updates']} |\n")
        q = r["ratio"]
        out += (f"| {r['log']} | | | ours / nav2 | {q['mean_position_error']:.2f} | {q['max_position_error']:.2f} | "
                f"{q['mean_heading_error']:.2f} | {q['max_heading_error']:.2f} | {q['update_ms']:.3f} | |\n")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--agent", type=Path, default=Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "release" / "robot-agent")
    ap.add_argument("--particles", type=int, default=None)
    args = ap.parse_args()
    if not args.agent.exists():
        sys.exit(f"amcl_compare: no robot-agent binary at {args.agent} (cargo build --release -p robot-agent, or --agent)")
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for path in args.logs:
        log = RunLog(path)
        s = amcl_settings(log, args.particles)
        ours, ours_ms = run_ours(log, args.agent, args.particles)
        nav2, nav2_ms = run_nav2(log, s)
        o, n = summary(*errors(log, ours), ours_ms), summary(*errors(log, nav2), nav2_ms)
        ratio = lambda k: o[k] / n[k] if n[k] else float("nan")
        rows.append({
            "log": path.name,
            "particles": f"{s['min_particles']}–{s['max_particles']}" if s["min_particles"] != s["max_particles"] else str(s["max_particles"]),
            "beams": s["max_beams"], "ours": o, "nav2": n,
            "ratio": {"mean_position_error": ratio("mean_position_error_m"), "max_position_error": ratio("max_position_error_m"),
                      "mean_heading_error": ratio("mean_heading_error_deg"), "max_heading_error": ratio("max_heading_error_deg"),
                      "update_ms": ratio("mean_update_ms")},
        })
        print(f"{path.name}: ours {o['mean_position_error_m']:.3f} m / {o['mean_update_ms']:.2f} ms, "
              f"nav2 {n['mean_position_error_m']:.3f} m / {n['mean_update_ms']:.2f} ms", file=sys.stderr)
    md = markdown(rows)
    (args.out / "compare.md").write_text(md)
    (args.out / "compare.json").write_text(json.dumps(rows, indent=2))
    print(md)


if __name__ == "__main__":
    main()

"""The keys of a ROS map_server YAML (docs: Nav2's map_server), for the scripts that draw or
replay on a floor plan. The files are flat `key: value` lines, so they are read by hand, without
PyYAML (not a dependency of the scripts).
"""

from __future__ import annotations

from pathlib import Path


def read_yaml(yaml_path: Path) -> dict:
    """The map's image (a path beside the YAML), resolution (m per pixel), origin (x, y in m),
    negate and thresholds; a file without image, resolution or origin is refused, naming it."""
    meta = {}
    for line in yaml_path.read_text().splitlines():
        key, sep, value = line.split("#", 1)[0].partition(":")
        if sep:
            meta[key.strip()] = value.strip()
    try:
        origin = [float(v) for v in meta["origin"].strip("[]").split(",")]
        return {
            "image": yaml_path.parent / meta["image"].strip("'\""),
            "resolution_m": float(meta["resolution"]),
            "origin_m": (origin[0], origin[1]),
            "negate": int(meta.get("negate", "0")),
            "occupied_thresh": float(meta.get("occupied_thresh", "0.65")),
            "free_thresh": float(meta.get("free_thresh", "0.196")),
        }
    except (KeyError, ValueError, IndexError) as e:
        raise SystemExit(f"{yaml_path}: not a ROS map YAML with image, resolution and origin ({e!r})") from e

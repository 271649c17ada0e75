"""The model card: string key -> string value, stored as the ONNX model's metadata_props.

The robot agent reads it (robot-agent/src/controllers/intention_net/card.rs) and refuses a
model whose card is incomplete or does not match its configuration. Keys it reads:

    card_version "1", kind dlm|lpe|none, backbone (free text), image_width_px, image_height_px
    (the camera input size), norm_mean, norm_std ("r,g,b"), max_speed_mps, max_turn_radps,
    dataset_id, validation_loss; lpe models also lpe_rendering (JSON of the planner's LPE
    parameters, every key) and lpe_image_px (the lpe input size; absent = the rendering's size_px).

Everything else the trainer writes (recipe, deviations, per-intention errors, ...) is for people
and ignored by the agent. `check` applies the agent's rules in Python so a bad card fails at
export time, not when a robot loads it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

CARD_VERSION = "1"
REQUIRED = (
    "card_version",
    "kind",
    "backbone",
    "image_width_px",
    "image_height_px",
    "norm_mean",
    "norm_std",
    "max_speed_mps",
    "max_turn_radps",
    "dataset_id",
    "validation_loss",
)
LPE_RENDERING_KEYS = (
    "size_px",
    "metres_per_px",
    "robot_px",
    "travelled_width_px",
    "ahead_width_px",
    "free_rgb",
    "occupied_rgb",
    "unknown_rgb",
    "travelled_rgb",
    "ahead_rgb",
)


def triple(values) -> str:
    return ",".join(repr(float(v)) for v in values)


def make(meta: dict, validation_loss: float, extras: dict | None = None) -> dict[str, str]:
    """The card from a checkpoint's `card_inputs` (see train.py) and the validation loss.
    Values become strings; dicts and lists become compact JSON."""
    kind = meta["kind"]
    card = {
        "card_version": CARD_VERSION,
        "kind": kind,
        "backbone": meta["backbone_text"],
        "image_width_px": str(int(meta["camera_px"])),
        "image_height_px": str(int(meta["camera_px"])),
        "norm_mean": triple(meta["norm_mean"]),
        "norm_std": triple(meta["norm_std"]),
        "max_speed_mps": repr(float(meta["max_speed_mps"])),
        "max_turn_radps": repr(float(meta["max_turn_radps"])),
        "dataset_id": str(meta["dataset_id"]),
        "validation_loss": repr(float(validation_loss)),
    }
    if kind == "lpe":
        card["lpe_rendering"] = json.dumps(meta["lpe_rendering"], sort_keys=True, separators=(",", ":"))
        card["lpe_image_px"] = str(int(meta["lpe_px"]))
    if kind == "dlm":
        # The DLM the labels were derived with (planning DlmParams): `eval table` and `eval record
        # --policy` plan with this measure, and the fleet's [dlm] table must say the same.
        params = meta.get("dlm_params") or {"measure": "curvature"}
        card["dlm_measure"] = str(params.get("measure", "curvature"))
        card["dlm_params"] = json.dumps(params, sort_keys=True, separators=(",", ":"))
    for k, v in (extras or {}).items():
        card[k] = v if isinstance(v, str) else json.dumps(v, sort_keys=True, separators=(",", ":"))
    return card


def check(card: dict[str, str]) -> None:
    """Raises ValueError naming the first key the agent would refuse (mirrors card.rs)."""
    for key in REQUIRED:
        if key not in card or not str(card[key]).strip():
            raise ValueError(f"model card: key {key!r} is missing or empty")
    if card["card_version"] != CARD_VERSION:
        raise ValueError(f"model card: card_version {card['card_version']!r}, the agent reads {CARD_VERSION}")
    kind = card["kind"]
    if kind not in ("dlm", "lpe", "none"):
        raise ValueError(f"model card: kind {kind!r}")
    for key in ("image_width_px", "image_height_px"):
        if not 1 <= int(card[key]) <= 8192:
            raise ValueError(f"model card: {key} = {card[key]}")
    for key, positive in (("norm_mean", False), ("norm_std", True)):
        parts = [float(p) for p in card[key].split(",")]
        if len(parts) != 3 or not all(math.isfinite(p) and (p > 0 or not positive) for p in parts):
            raise ValueError(f"model card: {key} = {card[key]!r}")
    for key in ("max_speed_mps", "max_turn_radps"):
        v = float(card[key])
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"model card: {key} = {card[key]}")
    loss = float(card["validation_loss"])
    if not (math.isfinite(loss) and loss >= 0):
        raise ValueError(f"model card: validation_loss = {card['validation_loss']}")
    if kind == "lpe":
        rendering = json.loads(card.get("lpe_rendering", "null") or "null")
        if not isinstance(rendering, dict):
            raise ValueError("model card: an lpe model needs lpe_rendering (JSON object)")
        missing = [k for k in LPE_RENDERING_KEYS if k not in rendering]
        if missing:
            raise ValueError(f"model card: lpe_rendering lacks {missing}")
        size = int(rendering["size_px"])
        rx, ry = rendering["robot_px"]
        if not (8 <= size <= 4096 and 0 <= rx < size and 0 <= ry < size):
            raise ValueError(f"model card: lpe_rendering out of range: {rendering}")
        if "lpe_image_px" in card and not 1 <= int(card["lpe_image_px"]) <= 8192:
            raise ValueError(f"model card: lpe_image_px = {card['lpe_image_px']}")
    else:
        for key in ("lpe_rendering", "lpe_image_px"):
            if key in card:
                raise ValueError(f"model card: {key} on a {kind} model (the agent refuses it)")


def lpe_input_px(card: dict[str, str]) -> int:
    """The lpe input size the agent feeds: lpe_image_px, else the rendering's size_px."""
    if "lpe_image_px" in card:
        return int(card["lpe_image_px"])
    return int(json.loads(card["lpe_rendering"])["size_px"])


def closed_loop_summary(tables: list[str | Path], kind: str, commands: list[str] | None = None) -> str:
    """The card's `closed_loop`: this network's rows of `eval table` results (table.json), per
    scenario: successes/runs, interventions, collisions, time and smoothness (mean over seeds),
    each row naming its table by its index in `tables`; with `commands`, the command that made
    each table, in the same order."""
    if commands is not None and len(commands) != len(tables):
        raise SystemExit(f"--commands: {len(commands)} commands for {len(tables)} tables (one per table)")
    rows = []
    for i, path in enumerate(tables):
        table = json.loads(Path(path).read_text())
        for r in table["rows"]:
            if r["method"] != kind:
                continue
            def mean(key, digits):
                stat = r.get(key)
                return None if stat is None else round(stat["mean"], digits)

            rows.append({
                # Which of `tables` (a card may carry the network alone and deployed, or tasks
                # and behaviours, from separate tables with the same scenarios).
                "table": i,
                "scenario": r["scenario"],
                "success": f"{r['successes']}/{r['runs']}",
                "interventions": mean("interventions", 2),
                "collisions": mean("collisions", 2),
                "collisions_person_glass": r["collisions_person"] + r["collisions_glass"],
                "time_s": mean("time_s", 1),
                "smoothness_mps3": mean("smoothness", 3),
            })
    if not rows:
        raise SystemExit(f"--closed-loop: no rows for method {kind} in {', '.join(map(str, tables))}")
    summary = {"tables": [str(t) for t in tables], "rows": rows}
    if commands is not None:
        summary["commands"] = list(commands)
    return json.dumps(summary, separators=(",", ":"))

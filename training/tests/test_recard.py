"""Test of `python -m training.recard` (a newer closed-loop record in a shipped model's card) on
a copy of the shipped DLM-Net and its card JSON:

* `closed_loop` becomes the network's rows of the given `eval table` results (table.json in the
  format `eval table` writes; the other method's rows left out), with the command of each
  table; every other card key, in the model and in the JSON, stays as it was; the graph
  (weights, nodes) is byte for byte the old one, and onnxruntime reads the new card;
* refused, naming what, with both files left untouched: a card JSON of another model (it
  differs on a key), tables without a row for the network, a command count that does not match
  the tables.

Needs onnx and onnxruntime (not torch). CI runs it (scripts/training-smoke.sh).

    .venv/bin/python training/tests/test_recard.py
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import onnx  # noqa: E402
import onnxruntime as ort  # noqa: E402

from training import recard as rc  # noqa: E402

MODELS = ROOT / "models"


def row(method: str, scenario: str, interventions: float, time_s: float, glass: int = 0) -> dict:
    """A row as `eval table` writes it into table.json (eval/src/table)."""
    stat = lambda m: {"mean": m, "std": 0.1, "n": 5}  # noqa: E731
    return {
        "scenario": scenario, "role": "evaluation", "method": method, "runs": 5, "successes": 5,
        "interventions": stat(interventions), "collisions": stat(0.2 if glass else 0.0),
        "collisions_wall": 0, "collisions_furniture": 0, "collisions_glass": glass,
        "collisions_person": 0, "collisions_robot": 0, "time_s": stat(time_s),
        "smoothness": stat(2.5), "path_length_m": stat(80.0),
    }


def refused(says: str, *args) -> None:
    try:
        rc.recard(*args)
    except SystemExit as e:
        assert says in str(e), f"{args}: {e}"
        return
    raise AssertionError(f"{args} was not refused")


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, card_json = tmp / "dlm.onnx", tmp / "dlm.card.json"
        shutil.copy(MODELS / "dlm.onnx", model)
        shutil.copy(MODELS / "dlm.card.json", card_json)
        tasks, behaviours = tmp / "tasks.json", tmp / "beh.json"
        tasks.write_text(json.dumps({"rows": [row("dlm", "task_a", 0.1, 135.0), row("dlm", "task_e", 0.4, 301.0),
                                              row("dynamic-window", "task_a", 0.05, 124.0)]}))
        behaviours.write_text(json.dumps({"rows": [row("dlm", "behaviour_glass_door", 0.0, 60.0),
                                                   row("lpe", "behaviour_glass_door", 0.0, 58.0, glass=6)]}))
        before = onnx.load(str(model))
        old_card = rc.card_of(before)
        old_json = json.loads(card_json.read_text())
        old_bytes, old_json_text = model.read_bytes(), card_json.read_text()

        # Refused, nothing written.
        other = tmp / "lpe.card.json"
        shutil.copy(MODELS / "lpe.card.json", other)
        refused("is not the card of", model, other, [tasks])
        lpe_only = tmp / "lpe-only.json"
        lpe_only.write_text(json.dumps({"rows": [row("lpe", "task_a", 0.0, 126.0)]}))
        refused("no rows for method dlm", model, card_json, [lpe_only])
        refused("2 commands for 1 tables", model, card_json, [tasks], ["a", "b"])
        assert model.read_bytes() == old_bytes and card_json.read_text() == old_json_text

        commands = ["eval table --methods dlm --seeds 20", "eval table --methods dlm,lpe --seeds 5 --scenario ..."]
        new = rc.recard(model, card_json, [tasks, behaviours], commands)
        summary = json.loads(new["closed_loop"])
        assert summary["tables"] == [str(tasks), str(behaviours)], summary
        assert summary["commands"] == commands, summary
        got = [(r["table"], r["scenario"], r["interventions"], r["time_s"]) for r in summary["rows"]]
        assert got == [(0, "task_a", 0.1, 135.0), (0, "task_e", 0.4, 301.0), (1, "behaviour_glass_door", 0.0, 60.0)], got

        after = onnx.load(str(model))
        assert after.graph.SerializeToString(deterministic=True) == before.graph.SerializeToString(deterministic=True)
        card = rc.card_of(after)
        assert {k: v for k, v in card.items() if k != "closed_loop"} == {
            k: v for k, v in old_card.items() if k != "closed_loop"}
        assert card["closed_loop"] == new["closed_loop"] != old_card["closed_loop"]
        meta = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"]).get_modelmeta().custom_metadata_map
        assert meta["closed_loop"] == new["closed_loop"]
        recorded = json.loads(card_json.read_text())
        assert recorded["closed_loop"] == new["closed_loop"]
        assert recorded["onnx_mb"] == f"{model.stat().st_size / 1e6:.3f}", recorded["onnx_mb"]
        assert {k: v for k, v in recorded.items() if k not in ("closed_loop", "onnx_mb")} == {
            k: v for k, v in old_json.items() if k not in ("closed_loop", "onnx_mb")}
        assert not list(tmp.glob("*.tmp")), "temporary files left behind"

        # Driven on a planner rule added since (the sidestep, round 51): dlm_params changes in
        # both, what the labels were derived with stays dlm_params_trained; nothing else moves.
        refused("not a DLM parameter", model, card_json, [tasks], None, {"measure": "route"})
        refused("not a non-negative number", model, card_json, [tasks], None, {"sidestep_ahead_m": -1})
        driven = rc.recard(model, card_json, [tasks], None, {"sidestep_ahead_m": 2.0})
        params = json.loads(driven["dlm_params"])
        assert params["sidestep_ahead_m"] == 2.0, params
        assert {k: v for k, v in params.items() if k != "sidestep_ahead_m"} == {
            k: v for k, v in json.loads(old_card["dlm_params"]).items() if k != "sidestep_ahead_m"}, params
        assert driven["dlm_params_trained"] == old_card["dlm_params_trained"], driven["dlm_params_trained"]
        card = rc.card_of(onnx.load(str(model)))
        recorded = json.loads(card_json.read_text())
        for key in ("dlm_params", "dlm_params_trained", "closed_loop"):
            assert card[key] == recorded[key] == driven[key], key
        assert {k: v for k, v in card.items() if k not in ("closed_loop", "dlm_params")} == {
            k: v for k, v in old_card.items() if k not in ("closed_loop", "dlm_params")}
    print("recard: ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())

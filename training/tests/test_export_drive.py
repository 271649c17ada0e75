"""Test of `python -m training.export --drive-dlm-params` (training/export.py `drive_dlm_with`):
the card's `dlm_params` (what `eval table`, `eval record --policy` and the fleet plan the DLM
with) take the changed keys, `dlm_params_trained` keeps what the labels were derived with; the
measure, unknown keys, values the planner refuses (a negative length, a chord of 0, a string)
and a card that is not a DLM-Net's are refused, naming the key or the value. On the shipped DLM-Net's card.

    .venv/bin/python training/tests/test_export_drive.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from training.export import drive_dlm_with  # noqa: E402


def refused(card: dict, changes: dict, says: str) -> None:
    try:
        drive_dlm_with(dict(card), changes)
    except SystemExit as e:
        assert says in str(e), f"{changes}: {e}"
        return
    raise AssertionError(f"{changes} was not refused")


def main() -> int:
    shipped = json.loads((ROOT / "models" / "dlm.card.json").read_text())
    trained = json.loads(shipped.get("dlm_params_trained", shipped["dlm_params"]))
    card = {"kind": "dlm", "dlm_params": json.dumps(trained, sort_keys=True, separators=(",", ":"))}
    driven = dict(card)
    drive_dlm_with(driven, {"heading_start_m": 0.25, "turn_release_rad": 0.5})
    params = json.loads(driven["dlm_params"])
    assert params["heading_start_m"] == 0.25 and params["turn_release_rad"] == 0.5, params
    assert params["measure"] == trained["measure"], params
    assert {k: v for k, v in params.items() if k not in ("heading_start_m", "turn_release_rad")} == {
        k: v for k, v in trained.items() if k not in ("heading_start_m", "turn_release_rad")
    }
    assert json.loads(driven["dlm_params_trained"]) == trained
    refused(card, {"measure": "route"}, "'measure'")
    refused(card, {"heading_start": 0.5}, "'heading_start'")
    refused(card, {"heading_start_m": -0.5}, "heading_start_m = -0.5 is not a non-negative number")
    refused(card, {"heading_chord_m": 0}, "heading_chord_m = 0 is not a positive number")
    from_robot = dict(card)
    drive_dlm_with(from_robot, {"heading_start_m": 0})
    assert json.loads(from_robot["dlm_params"])["heading_start_m"] == 0.0
    refused(card, {"heading_start_m": "0.5"}, "heading_start_m = '0.5'")
    refused({"kind": "lpe"}, {"heading_start_m": 0.5}, "only a DLM-Net")
    # A parameter the planner gained after the card was written (round 55's turn beside a seen
    # obstacle measured on the path).
    assert "sidestep_over_turn_rad" not in trained, trained
    over = dict(card)
    drive_dlm_with(over, {"sidestep_over_turn_rad": 3.0})
    assert json.loads(over["dlm_params"])["sidestep_over_turn_rad"] == 3.0
    refused(card, {"sidestep_over_turn": 3.0}, "'sidestep_over_turn'")
    print("export --drive-dlm-params: ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())

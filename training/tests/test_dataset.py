"""Test of a recording's share (`DIR@FRACTION`, training/dataset.py `parse_source`), on the smoke
test's synthetic recording (4 shards: 250, 250, 250, 30 samples):

* `@0.5` opens shards 1 and 3 (evenly spaced), 280 samples, read back equal to the whole
  recording's rows there; its dataset id says the share; a training pool of it and the whole
  recording has both, and the sources name the share;
* `@1` is the whole recording;
* recordings labelled with other DLM parameters are refused together;
* `speed_label="target"` trains speed on the expert's target and the turn rate on its command,
  `speed_label="lead"` speed on the larger of target and command,
  and refuses, naming it, a recording without the target field;
* refused, naming the value: a share of 0, above 1, or not a number.

    .venv/bin/python training/tests/test_dataset.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "training" / "tests"))

import numpy as np  # noqa: E402

from training import data, dataset  # noqa: E402
from test_smoke import write_synthetic  # noqa: E402


def refused(call, why: str) -> str:
    """The message of the ValueError that `call()` raises; fails with `why` when it raises none."""
    try:
        call()
    except ValueError as e:
        return str(e)
    raise AssertionError(why)


def check(root: Path) -> None:
    whole = dataset.load(root)
    assert len(whole) == 780 and len(whole.index["shards"]) == 4, len(whole)
    assert dataset.shard_share(4, 0.5) == [1, 3] and dataset.shard_share(23, 0.5) == list(range(1, 23, 2))
    assert dataset.shard_share(3, 0.1) == [2], dataset.shard_share(3, 0.1)

    half = dataset.load(f"{root}@0.5")
    assert len(half) == 280 and [s["name"] for s in half.index["shards"]] == ["shard_00001", "shard_00003"]
    assert half.index["dataset_id"] == "synthetic-smoke@0.5", half.index["dataset_id"]
    assert np.array_equal(half.field("label"), np.concatenate([whole.fields["label"][1], whole.fields["label"][3]]))
    assert np.array_equal(half.sample(250)["camera"], whole.sample(750)["camera"])

    full = dataset.load(f"{root}@1")
    assert len(full) == 780 and full.index["dataset_id"] == "synthetic-smoke"

    pool = data.Pool([str(root), f"{root}@0.5"])
    assert len(pool) == 1060 and pool.dataset_id == "synthetic-smoke+synthetic-smoke@0.5", pool.dataset_id
    shares = [s["shard_fraction"] for s in pool.describe_sources()]
    assert shares == [1.0, 0.5], shares
    # Episodes of the two stay apart (the recording's index is part of the key).
    assert len(np.unique(pool.episode_key)) > len(np.unique(whole.field("episode")))

    # Recordings of other DLM parameters (one measure) do not train together.
    import json
    import shutil

    def relabelled(name: str, src: Path, dlm_params) -> None:
        """A copy of recording `src` named `name` whose index.json says its labels came from the
        DLM parameters `dlm_params(its own)` returns."""
        copy = root.parent / name
        shutil.copytree(src, copy)
        index = json.loads((copy / "index.json").read_text())
        index["dlm_params"] = dlm_params(index.get("dlm_params"))
        (copy / "index.json").write_text(json.dumps(index))

    params = {"measure": "route", "heading_start_m": 1.0, "heading_chord_m": 1.0, "turn_threshold_rad": 0.8,
              "turn_release_rad": 0.6}
    for name, release in (("a", 0.6), ("b", 0.3)):
        relabelled(name, root, lambda _: {**params, "turn_release_rad": release})
    assert len(data.Pool([str(root.parent / "a"), f"{root.parent / 'a'}@0.5"])) == 1060
    e = refused(
        lambda: data.Pool([str(root.parent / "a"), str(root.parent / "b")]),
        "recordings of two DLM parameter sets were pooled",
    )
    assert "turn_release_rad" in e and "labelled alike" in e, e
    # A parameter the planner gained later (the arrive distance) pools at the value meaning
    # "as before", and not at another.
    for name, arrive in (("c", 0.0), ("d", 1.5)):
        relabelled(name, root.parent / "a", lambda p: {**p, "arrive_distance_m": arrive})
    assert len(data.Pool([str(root.parent / "a"), str(root.parent / "c")])) == 2 * 780
    e = refused(
        lambda: data.Pool([str(root.parent / "c"), str(root.parent / "d")]),
        "recordings of two arrive distances were pooled",
    )
    assert "arrive_distance_m" in e, e
    # So does round 49's turn before a wall (blocked_ahead_m 0: never).
    for name, blocked in (("e", 0.0), ("f", 1.2)):
        relabelled(name, root.parent / "a", lambda p: {**p, "blocked_ahead_m": blocked, "blocked_turn_rad": 0.2})
    assert len(data.Pool([str(root.parent / "a"), str(root.parent / "e")])) == 2 * 780
    e = refused(
        lambda: data.Pool([str(root.parent / "a"), str(root.parent / "f")]),
        "recordings with and without the turn before a wall were pooled",
    )
    assert "blocked_ahead_m" in e, e

    # Speed from the expert's target, turn rate from its command.
    targeted = data.Pool([str(root)], speed_label="target")
    assert np.array_equal(targeted.label[:, 0], whole.field("target")[:, 0])
    assert np.array_equal(targeted.label[:, 1], whole.field("label")[:, 1])
    assert not np.array_equal(targeted.label[:, 0], whole.field("label")[:, 0])
    # "lead": the larger of the two, so the target at set-offs and the command while braking.
    lead = data.Pool([str(root)], speed_label="lead")
    command_v, target_v = whole.field("label")[:, 0], whole.field("target")[:, 0]
    assert np.array_equal(lead.label[:, 0], np.maximum(command_v, target_v))
    assert np.array_equal(lead.label[:, 1], whole.field("label")[:, 1])
    assert not np.array_equal(lead.label[:, 0], command_v)
    # Turn rate "lead": the target where the robot stands or crawls and the target turns the
    # same way harder, the command everywhere else; the speed label is left as asked.
    turned = data.Pool([str(root)], speed_label="target", turn_label="lead")
    command, target = whole.field("label"), whole.field("target")
    assert np.array_equal(turned.label[:, 0], target[:, 0])
    took = turned.label[:, 1] != command[:, 1]
    assert took.any(), "no frame of the fixture recording takes the target turn rate"
    assert np.array_equal(turned.label[took, 1], target[took, 1])
    assert np.all(np.abs(command[took, 0]) < data.SLOW_V)
    assert np.all(np.abs(target[took, 1]) > np.abs(command[took, 1]))
    assert np.all(np.sign(target[took, 1]) * np.sign(command[took, 1]) >= 0)
    moving = np.abs(command[:, 0]) >= data.SLOW_V
    assert np.array_equal(turned.label[moving, 1], command[moving, 1])
    # "spin": "lead", and also where the robot moves but the expert means to stop and turn.
    spun = data.Pool([str(root)], speed_label="target", turn_label="spin")
    spun_took = spun.label[:, 1] != command[:, 1]
    assert np.all(spun_took[took]), "spin dropped a frame lead takes"
    assert np.array_equal(spun.label[spun_took, 1], target[spun_took, 1])
    extra = spun_took & ~took
    # A goal reached at speed with the way behind: the command still rolls on (0.71, 0.36), the
    # target stops and turns (0.01, 0.89); "lead" keeps the command, "spin" takes the target.
    # Braking for someone without a turn, or a target turning the other way, keeps the command.
    cmd = np.array([[0.71, 0.36], [0.71, 0.36], [0.5, 0.0], [0.71, 0.36], [0.1, 0.2]], np.float32)
    tgt = np.array([[0.01, 0.89], [0.5, 0.89], [0.0, 0.0], [0.01, -0.89], [0.5, 0.6]], np.float32)
    assert data.turn_leads(cmd, tgt).tolist() == [False, False, False, False, True]
    assert data.turn_leads(cmd, tgt, spin=True).tolist() == [True, False, False, False, True]
    assert np.all(np.abs(target[extra, 0]) < data.SLOW_V)
    assert np.all(np.abs(target[extra, 1]) > np.abs(command[extra, 1]))
    stays = (np.abs(command[:, 0]) >= data.SLOW_V) & (np.abs(target[:, 0]) >= data.SLOW_V)
    assert np.array_equal(spun.label[stays, 1], command[stays, 1])
    only_turn = data.Pool([str(root)], turn_label="lead")
    assert np.array_equal(only_turn.label[:, 0], command[:, 0])
    assert np.array_equal(only_turn.label[:, 1], turned.label[:, 1])
    from training import recipe

    assert any("larger" in d for d in recipe.deviations(
        recipe.resolve("default", {"speed_label": "lead"}), {"kind": "dlm"}, 128, 128, [], None))
    r = recipe.resolve("default", {"speed_label": "target"})
    both = {**r, "turn_label": "lead"}
    said = recipe.deviations(both, {"kind": "dlm"}, 128, 128, [], None)
    assert any("turn-rate label" in d for d in said) and not any("turn rate the command's" in d for d in said), said
    said = recipe.deviations({**r, "turn_label": "spin"}, {"kind": "dlm"}, 128, 128, [], None)
    assert any("means to stop" in d for d in said) and not any("turn rate the command's" in d for d in said), said
    assert any("target speed" in d for d in recipe.deviations(r, {"kind": "lpe"}, 128, 128, [], None))
    older = root.parent / "older"
    shutil.copytree(root, older)
    index = json.loads((older / "index.json").read_text())
    del index["fields"]["target"]
    (older / "index.json").write_text(json.dumps(index))
    e = refused(
        lambda: data.Pool([str(root), str(older)], speed_label="target"),
        "a recording without targets trained on targets",
    )
    assert "'target'" in e and str(older) in e, e
    e = refused(
        lambda: data.Pool([str(root), str(older)], turn_label="lead"),
        "a recording without targets trained its turn rate on targets",
    )
    assert "turn_label 'lead'" in e and str(older) in e, e
    e = refused(lambda: data.Pool([str(root)], turn_label="target"), "an unknown turn label was accepted")
    assert "'target'" in e and "turn_label" in e, e
    e = refused(lambda: data.Pool([str(root)], speed_label="goal"), "an unknown speed label was accepted")
    assert "'goal'" in e, e

    for bad, says in (("0", "0.0"), ("1.5", "1.5"), ("half", "'half'")):
        e = refused(lambda: dataset.load(f"{root}@{bad}"), f"@{bad} was accepted")
        assert says in e and "share" in e, e


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="dataset-share-") as tmp:
        root = Path(tmp) / "data"
        write_synthetic(root)
        check(root)
    print("dataset share test passed")


def test_dataset_share():
    main()


if __name__ == "__main__":
    main()

"""What the trainer feeds the networks, on top of the memory-mapped recordings (dataset.py).

* `Pool`               -- one or more recordings as one index space; the small fields (dlm,
                          label, episode) in memory, the images read from the maps per batch.
* `split_by_episode`   -- train/validation split with no episode on both sides (frames of one
                          episode are near-duplicates; a per-frame split would leak).
* `balance_weights`    -- sampling weights that keep straight driving from dominating: equal
                          mass per (DLM class, |omega| bin) cell, with a cap on the boost a rare
                          cell gets so that a handful of frames is not repeated endlessly.
* `randomize_intention`-- LEARNING.md: straight go_forward frames get a random intention, so the
                          net learns to read the intention where it matters and ignore it elsewhere.
* `augment`            -- photometric augmentation only (brightness, multiply, contrast,
                          Gaussian noise, blur, pixel dropout) on the camera image; never
                          geometric (a flipped image would need a flipped label) and never on the
                          LPE drawing (its colours are a code, not a photograph).
* `Batches`            -- a torch Dataset whose items are whole batches (indices drawn for the
                          epoch up front), so `DataLoader(batch_size=None, num_workers=W)`
                          parallelises gathering and augmentation when cores allow; every batch is
                          seeded by (seed, epoch, batch), so results do not depend on W.

Pixels become network inputs exactly as the robot agent computes them:
`x = (pixel / 255 - mean[c]) / std[c]` in f32, CHW (the recorder already area-averaged the
224 px renderings down to the stored size, as the agent does).
"""

from __future__ import annotations

from pathlib import Path

import math

import numpy as np
from tqdm import tqdm
import torch
import torch.nn.functional as F

try:  # `python -m training.train` (package) or a script run from training/
    from training import dataset
except ImportError:  # pragma: no cover
    import dataset  # type: ignore[no-redef]

# ImageNet statistics: the usual choice, and what the fixture models' cards carry. Batch norm
# adapts to the real statistics anyway; the card records whatever is used here.
NORM_MEAN = (0.485, 0.456, 0.406)
NORM_STD = (0.229, 0.224, 0.225)
DLM_NAMES = ("turn_left", "turn_right", "go_forward", "stop")
GO_FORWARD = 2
# |omega label| (normalised) bin edges for balancing: straight, gentle, turning, sharp.
OMEGA_BINS = (0.1, 0.3, 0.6)
# What a sample's speed label is: the expert's command (its filter's output, the current motion
# plus a bounded step) or the target speed that filter steers towards. A network that does not
# see the current speed learns from the command a mean over the speeds the robot happened to
# have in that view, so from rest (after a turn on the spot) it creeps; the target does not
# depend on the current speed, and the agent's acceleration limit makes the ramp. The turn
# rate stays the command's (TURN_LABELS for where not): its target jumps to the limit on every
# turn.
SPEED_LABELS = ("command", "target", "lead")
# What a sample's turn-rate label is: the expert's command, or ("lead") its target where the
# robot stands or crawls (command speed below SLOW_V) and the target turns the same way harder.
# In a DAgger round the expert's filter restarts from the measured motion when the learner's
# turn rate is more than 0.25 rad/s off its own, so where the learner stood facing a wall the
# label is the learner's own standstill plus one bounded step, which a network that sees no
# motion may learn as a creep (round 48: DLM-Net c4 alone stood or turned at 0.03-0.09 rad/s
# at task D's room exit and task E's goal 3; a fine-tune with "lead" did not beat c4 there).
# Moving, target and command agree (|difference| > 0.3 on 2-4 % of frames).
# "spin": the target also where the expert means to stop and turn on the spot while the robot
# still moves (target speed below SLOW_V), a goal reached with the way behind. There the
# command is the learner's motion plus one bounded step: in round 50's furniture recording
# (r49 driving), 822 turn frames moving at >= 0.35 m/s with a target of 0.01 (speed) and 0.89
# (turn rate, of the limits) carry a command label of 0.71 and 0.36, and a network trained on
# them brakes but turns at 0.3 (docs/evaluation.md, round 52).
TURN_LABELS = ("command", "lead", "spin")
# Normalised speed label below which a frame counts as slow (0.2 of 0.7 m/s: 0.14 m/s).
SLOW_V = 0.2
# Limits of the robot agent (robot-agent/src/config.rs Limits::default) for recordings whose
# index.json does not state them.
DEFAULT_MAX_SPEED_MPS = 0.7
DEFAULT_MAX_TURN_RADPS = 1.2
# The DLM a recording made before `eval record` wrote `dlm_params` was labelled with (planning
# DlmParams::curvature(), what DLM-Net r1 was trained on; the default is now heading).
DEFAULT_DLM_MEASURE = "curvature"
# DLM parameters the planner gained after recordings wrote `dlm_params`, with the value that
# means what those recordings had (planning DlmParams: no arriving Stop; once there was one,
# at any bearing of the goal; no narrower turn angles before a wall, round 49; no sidestep round
# what the laser sees, round 51; no side chosen by the walls for a turn round, round 53; no turn
# measured on the path round what the laser sees, round 55).
ADDED_DLM_PARAMS = {
    "arrive_distance_m": 0.0,
    "arrive_bearing_rad": math.pi,
    "blocked_ahead_m": 0.0,
    "blocked_turn_rad": 0.2,
    "sidestep_ahead_m": 0.0,
    "sidestep_turn_rad": 0.3,
    "sidestep_over_turn_rad": 0.0,
    "about_turn_rad": 0.0,
}


def with_added(params: dict) -> dict:
    """DLM parameters as written (a recording's, a card's), those the planner gained after they
    were written filled in with the value that means what they had."""
    return {**ADDED_DLM_PARAMS, **params}


def recorded_dlm_params(index: dict) -> dict:
    """The DLM parameters a recording's labels were derived with (its index.json), parameters
    added to the planner since filled in ([`with_added`])."""
    if "dlm_params" not in index:
        return {"measure": DEFAULT_DLM_MEASURE}
    return with_added(index["dlm_params"])

# The planner's default LPE rendering (protocol LpeParams::default()), only for recordings made
# before `eval record` wrote the rendering into index.json (`lpe_rendering`).
DEFAULT_LPE_RENDERING = {
    "size_px": 224,
    "metres_per_px": 0.05,
    "robot_px": [112, 168],
    "travelled_width_px": 3.0,
    "ahead_width_px": 3.0,
    "free_rgb": [255, 255, 255],
    "occupied_rgb": [0, 0, 0],
    "unknown_rgb": [128, 128, 128],
    "travelled_rgb": [255, 0, 0],
    "ahead_rgb": [0, 0, 255],
}


def turn_leads(command: np.ndarray, target: np.ndarray, spin: bool = False) -> np.ndarray:
    """Where the "lead" turn label takes the expert's target turn rate (rows of normalised
    (v, omega)): the command's speed below SLOW_V and the target turning the same way as the
    command (or the command not turning), harder. With `spin` ("spin"), also where the
    target's speed is below SLOW_V (the expert means to turn on the spot)."""
    same_way = np.sign(target[:, 1]) * np.sign(command[:, 1]) >= 0
    slow = np.abs(command[:, 0]) < SLOW_V
    if spin:
        slow |= np.abs(target[:, 0]) < SLOW_V
    return slow & same_way & (np.abs(target[:, 1]) > np.abs(command[:, 1]))


class Pool:
    """All samples of one or more recordings, globally indexed in the order given.

    The recordings must agree on image sizes, limits and LPE rendering (a model is trained for
    one of each). Episode keys are (recording, episode) so equal episode numbers of different
    recordings stay different episodes."""

    def __init__(self, dirs: list[str | Path], preload: tuple[str, ...] = (), speed_label: str = "command",
                 turn_label: str = "command"):
        if not dirs:
            raise ValueError("no dataset folder given")
        if speed_label not in SPEED_LABELS:
            raise ValueError(f"speed_label {speed_label!r} is not one of {SPEED_LABELS}")
        if turn_label not in TURN_LABELS:
            raise ValueError(f"turn_label {turn_label!r} is not one of {TURN_LABELS}")
        self.sets = [dataset.load(d) for d in dirs]
        first = self.sets[0]
        self.camera_px = tuple(first.index["fields"]["camera"]["shape"][:2])
        self.lpe_px = tuple(first.index["fields"]["lpe"]["shape"][:2])
        self.max_speed_mps = float(first.index.get("max_speed_mps", DEFAULT_MAX_SPEED_MPS))
        self.max_turn_radps = float(first.index.get("max_turn_radps", DEFAULT_MAX_TURN_RADPS))
        self.lpe_rendering = dict(first.index.get("lpe_rendering", DEFAULT_LPE_RENDERING))
        self.limits_from_index = "max_speed_mps" in first.index and "max_turn_radps" in first.index
        self.rendering_from_index = "lpe_rendering" in first.index
        self.dlm_params = recorded_dlm_params(first.index)
        self.dlm_measure = self.dlm_params.get("measure", DEFAULT_DLM_MEASURE)
        for ds in self.sets[1:]:
            ix = ds.index
            other = (
                tuple(ix["fields"]["camera"]["shape"][:2]),
                tuple(ix["fields"]["lpe"]["shape"][:2]),
                float(ix.get("max_speed_mps", DEFAULT_MAX_SPEED_MPS)),
                float(ix.get("max_turn_radps", DEFAULT_MAX_TURN_RADPS)),
                dict(ix.get("lpe_rendering", DEFAULT_LPE_RENDERING)),
            )
            mine = (self.camera_px, self.lpe_px, self.max_speed_mps, self.max_turn_radps, self.lpe_rendering)
            theirs = recorded_dlm_params(ix)
            if theirs.get("measure", DEFAULT_DLM_MEASURE) != self.dlm_measure:
                raise ValueError(
                    f"{ds.root} has DLM labels of the {theirs.get('measure', DEFAULT_DLM_MEASURE)} measure, "
                    f"{first.root} of the {self.dlm_measure} measure; train on recordings labelled alike"
                )
            if "dlm_params" in ix and "dlm_params" in first.index and theirs != self.dlm_params:
                # The planner plans with every parameter the card states (eval, the fleet).
                raise ValueError(
                    f"{ds.root} has DLM labels of the parameters {theirs}, {first.root} of "
                    f"{self.dlm_params}; train on recordings labelled alike"
                )
            if other != mine:
                raise ValueError(
                    f"{ds.root} differs from {first.root} in image size, limits or LPE rendering: "
                    f"{other} vs {mine}; train on recordings made with the same settings"
                )
        if self.camera_px[0] != self.camera_px[1] or self.lpe_px[0] != self.lpe_px[1]:
            raise ValueError(f"images must be square: camera {self.camera_px}, lpe {self.lpe_px}")

        # One flat list of shards over all recordings; starts[i] is shard i's first global index.
        self.shards: list[dict[str, np.ndarray]] = []
        starts = []
        n = 0
        for ds in self.sets:
            for k in range(len(ds.index["shards"])):
                self.shards.append({name: arrays[k] for name, arrays in ds.fields.items()})
                starts.append(n)
                n += len(ds.fields["label"][k])
        self.starts = np.asarray(starts, dtype=np.int64)
        self.n = n
        if preload:
            # Balanced sampling reads rows in random order; from a memory map on disk that is
            # I/O-bound (measured: ~10 samples/s with 80 % iowait on a 7.8 GB recording whose
            # pages did not stay cached), so the image fields are copied into memory once.
            for shard in tqdm(self.shards, desc=f"loading {'+'.join(preload)} into memory", unit="shard"):
                for name in preload:
                    shard[name] = np.array(shard[name])
        self.dlm = np.concatenate([ds.field("dlm") for ds in self.sets]).astype(np.int64)
        self.label = np.concatenate([ds.field("label") for ds in self.sets]).astype(np.float32)
        if speed_label != "command" or turn_label != "command":
            which = f"speed_label {speed_label!r}" if speed_label != "command" else f"turn_label {turn_label!r}"
            missing = [str(ds.root) for ds in self.sets if "target" not in ds.fields]
            if missing:
                raise ValueError(
                    f"{which}: {', '.join(missing)} has no 'target' field (recorded before "
                    "`eval record` stored the expert's target); record it again or train with the command's labels"
                )
            target = np.concatenate([ds.field("target") for ds in self.sets]).astype(np.float32)
            if turn_label in ("lead", "spin"):
                # Before the speed label changes: the rule reads the command's speed.
                leads = turn_leads(self.label, target, spin=turn_label == "spin")
                self.label[leads, 1] = target[leads, 1]
            if speed_label == "target":
                self.label[:, 0] = target[:, 0]
            elif speed_label == "lead":
                # "lead": the target where it leads the command (setting off: the filter's first
                # steps are not a speed to learn), the command where the filter still brakes
                # towards a lower target (it keeps rolling to a goal the camera cannot place).
                self.label[:, 0] = np.maximum(target[:, 0], self.label[:, 0])
        self.episode_key = np.concatenate(
            [(np.int64(i) << 32) | ds.field("episode").astype(np.int64) for i, ds in enumerate(self.sets)]
        )
        if np.any(self.dlm > 3):
            raise ValueError("dlm values outside 0..3")

    def __len__(self) -> int:
        return self.n

    @property
    def dataset_ids(self) -> list[str]:
        return [str(ds.index["dataset_id"]) for ds in self.sets]

    @property
    def dataset_id(self) -> str:
        """The card's dataset_id: the recording's id, or the ids joined by '+'."""
        return "+".join(self.dataset_ids)

    def describe_sources(self) -> list[dict]:
        return [
            {
                "dataset_id": ds.index["dataset_id"],
                "dir": str(ds.root.resolve()),
                "samples": len(ds),
                "shard_fraction": float(ds.index.get("shard_fraction", 1.0)),
                "command": ds.index.get("command", ""),
            }
            for ds in self.sets
        ]

    def gather(self, idx: np.ndarray, name: str) -> np.ndarray:
        """Rows `idx` (global indices, any order) of one field, read from the maps. Reads each
        shard's rows in ascending order (sequential access on the map), then restores `idx`'s
        order."""
        idx = np.asarray(idx, dtype=np.int64)
        first = self.shards[0][name]
        out = np.empty((len(idx), *first.shape[1:]), dtype=first.dtype)
        shard_of = np.searchsorted(self.starts, idx, side="right") - 1
        for s in np.unique(shard_of):
            where = np.nonzero(shard_of == s)[0]
            rows = idx[where] - self.starts[s]
            order = np.argsort(rows, kind="stable")
            out[where[order]] = self.shards[s][name][rows[order]]
        return out


def split_by_episode(pool: Pool, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """(train indices, validation indices, validation episode keys).

    Episodes are shuffled (seeded) and moved to validation until it holds at least
    `val_fraction` of the samples, skipping an episode that would overshoot the target by more
    than half (long episodes of a small recording); at least one episode stays on each side."""
    if not 0.0 < val_fraction < 1.0:
        raise ValueError(f"--val-fraction must be in (0, 1), got {val_fraction}")
    keys, counts = np.unique(pool.episode_key, return_counts=True)
    if len(keys) < 2:
        raise ValueError(
            f"the data hold {len(keys)} episode(s); a split by episode needs at least 2 "
            "(record more samples or several recordings)"
        )
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5B117]))
    order = rng.permutation(len(keys))
    target = val_fraction * len(pool)
    val_keys, have = [], 0
    for i in order:
        if have >= target or len(val_keys) == len(keys) - 1:  # one always stays in training
            break
        if have + counts[i] <= 1.5 * target:
            val_keys.append(int(keys[i]))
            have += int(counts[i])
    if not val_keys:  # every episode is longer than 1.5 x the target: take the shortest
        val_keys.append(int(keys[np.argmin(counts)]))
    is_val = np.isin(pool.episode_key, np.asarray(val_keys, dtype=np.int64))
    return np.nonzero(~is_val)[0], np.nonzero(is_val)[0], val_keys


def omega_bin(label_omega: np.ndarray) -> np.ndarray:
    return np.digitize(np.abs(label_omega), OMEGA_BINS)


def balance_weights(dlm: np.ndarray, label: np.ndarray, max_boost: float = 10.0,
                    by_speed: bool = False) -> tuple[np.ndarray, dict]:
    """Per-sample sampling weights giving every non-empty (DLM class, |omega| bin) cell the
    same total mass, except that no sample is drawn more than about `max_boost` times as often
    as under uniform sampling (a cell of 3 frames must not take 1/12 of every batch).

    `by_speed` splits the go_forward cells by the speed label (slow: v < SLOW_V of the limit): the frames
    where the expert holds back for a person or stops short of a glass door are well under 1 %
    of a recording and would otherwise be drowned by the straight driving of their cell.

    Returns (weights summing to 1, {cell name: (count, share of draws)}) for the log."""
    cell = dlm * (len(OMEGA_BINS) + 1) + omega_bin(label[:, 1])
    ncells = 4 * (len(OMEGA_BINS) + 1)
    if by_speed:
        # Only go_forward frames: slow turning frames are mostly turns in place, common enough.
        cell = cell * 2 + ((label[:, 0] < SLOW_V) & (dlm == GO_FORWARD))
        ncells *= 2
    counts = np.bincount(cell, minlength=ncells).astype(np.float64)
    nonempty = np.count_nonzero(counts)
    # Equal mass per cell draws a sample of a cell of c samples n / (nonempty * c) times as
    # often as uniform sampling; counting small cells as if they had at least
    # n / (nonempty * max_boost) samples caps that factor at max_boost.
    floor = len(dlm) / nonempty / max_boost
    w = 1.0 / np.maximum(counts[cell], floor)
    w /= w.sum()
    mass = np.bincount(cell, weights=w, minlength=ncells)
    edges = (0.0, *OMEGA_BINS, 1.0)
    report = {}
    for c in range(ncells):
        if counts[c]:
            base, slow = divmod(c, 2) if by_speed else (c, None)
            d, b = divmod(base, len(OMEGA_BINS) + 1)
            name = f"{DLM_NAMES[d]} |w| {edges[b]:.1f}-{edges[b + 1]:.1f}"
            if slow:
                name += " slow"
            report[name] = (int(counts[c]), float(mass[c]))
    return w, report


def randomize_intention(dlm: np.ndarray, label: np.ndarray, p: float, rng: np.random.Generator) -> np.ndarray:
    """Copy of `dlm` where go_forward frames with |omega label| < 0.1 get, with probability p,
    a random intention among turn_left, turn_right, go_forward.

    Stop is left out on purpose: its head must learn to stop, and a stop intention on a frame
    whose label drives would teach it the opposite."""
    out = dlm.copy()
    if p <= 0:
        return out
    pick = (dlm == GO_FORWARD) & (np.abs(label[:, 1]) < 0.1) & (rng.random(len(dlm)) < p)
    out[pick] = rng.integers(0, 3, size=int(pick.sum()))
    return out


def to_unit(images_u8: np.ndarray) -> torch.Tensor:
    """uint8 NHWC -> float32 NCHW in [0, 1] (pixel / 255, as the agent computes it)."""
    # Transpose while still 1 byte per value, then convert: cheaper than the other way round.
    t = torch.from_numpy(np.ascontiguousarray(images_u8)).permute(0, 3, 1, 2).contiguous()
    return t.float().div_(255.0)


def normalize(x: torch.Tensor, mean=NORM_MEAN, std=NORM_STD) -> torch.Tensor:
    m = torch.tensor(mean, dtype=torch.float32).view(1, 3, 1, 1)
    s = torch.tensor(std, dtype=torch.float32).view(1, 3, 1, 1)
    return ((x - m) / s).contiguous()


_BLUR = torch.tensor([1.0, 2.0, 1.0]) / 4.0
_BLUR = (_BLUR[:, None] * _BLUR[None, :]).expand(3, 1, 3, 3).contiguous()


def augment(x: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """Photometric augmentation of a batch in [0, 1] (NCHW, float32), each transform applied to
    a random subset of the images with its own random strength. Ranges as in Codevilla et al.
    2018 (brightness +-20/255, multiply 0.9-1.1, contrast 0.8-1.2); blur, noise and pixel
    dropout mild. Never geometric."""
    n = x.shape[0]

    def u(lo, hi, shape=(n, 1, 1, 1)):
        return lo + (hi - lo) * torch.rand(shape, generator=gen)

    def chosen(p, shape=(n, 1, 1, 1)):
        return (torch.rand(shape, generator=gen) < p).float()

    def subset(p):
        return torch.nonzero(torch.rand(n, generator=gen) < p).flatten()

    # Brightness (additive), multiply (per image, slightly per channel: white balance) and
    # contrast about the image's mean are one affine map per image and channel: one pass.
    bright = chosen(0.5) * u(-20 / 255, 20 / 255)
    mul = 1 + chosen(0.5) * (u(0.9, 1.1) * u(0.97, 1.03, (n, 3, 1, 1)) - 1)
    con = 1 + chosen(0.5) * (u(0.8, 1.2) - 1)
    mean = ((x.mean(dim=(2, 3), keepdim=True) + bright) * mul).mean(dim=1, keepdim=True)
    x = torch.addcmul(bright * mul * con + mean * (1 - con), x, mul * con)
    # Blur: blend towards a 3x3 binomial blur by a random amount.
    sel = subset(0.2)
    if len(sel):
        xs = x[sel]
        blurred = F.conv2d(F.pad(xs, (1, 1, 1, 1), mode="replicate"), _BLUR, groups=3)
        x[sel] = xs + u(0.0, 1.0, (len(sel), 1, 1, 1)) * (blurred - xs)
    # Gaussian pixel noise.
    sel = subset(0.3)
    if len(sel):
        sigma = u(0.0, 0.03, (len(sel), 1, 1, 1))
        x[sel] += sigma * torch.randn((len(sel), *x.shape[1:]), generator=gen)
    # Pixel dropout: up to 2 % of the pixels (all channels) set to black.
    sel = subset(0.2)
    if len(sel):
        frac = u(0.0, 0.02, (len(sel), 1, 1, 1))
        drop = torch.rand((len(sel), 1, *x.shape[2:]), generator=gen) < frac
        x[sel] = x[sel].masked_fill(drop, 0.0)
    return x.clamp_(0.0, 1.0)


def one_hot(dlm: np.ndarray) -> torch.Tensor:
    return F.one_hot(torch.from_numpy(np.asarray(dlm, dtype=np.int64)), 4).float()


def batch_seed(seed: int, epoch: int, batch: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([seed, epoch, batch, 0xBA7C4])


class Batches(torch.utils.data.Dataset):
    """Item b = batch b of an epoch: dict of network inputs (named as in the ONNX contract)
    plus `label` and `dlm` (the recorded intention, for per-class metrics).

    Training batches are augmented and (DLM) intention-randomised; validation batches are not."""

    def __init__(
        self,
        pool: Pool,
        batches: list[np.ndarray],
        kind: str,
        *,
        train: bool,
        seed: int = 0,
        epoch: int = 0,
        augment_images: bool = True,
        randomize_p: float = 0.0,
    ):
        self.pool, self.batches, self.kind = pool, batches, kind
        self.train, self.seed, self.epoch = train, seed, epoch
        self.augment_images, self.randomize_p = augment_images, randomize_p

    def __len__(self) -> int:
        return len(self.batches)

    def __getitem__(self, b: int) -> dict[str, torch.Tensor]:
        idx = self.batches[b]
        ss = batch_seed(self.seed, self.epoch, b)
        gen = torch.Generator().manual_seed(int(ss.generate_state(1, np.uint64)[0] >> 1))
        rng = np.random.default_rng(ss)
        label = self.pool.label[idx]
        dlm = self.pool.dlm[idx]
        cam = to_unit(self.pool.gather(idx, "camera"))
        if self.train and self.augment_images:
            cam = augment(cam, gen)
        out = {"camera": normalize(cam), "label": torch.from_numpy(label), "dlm": torch.from_numpy(dlm)}
        if self.kind == "dlm":
            shown = randomize_intention(dlm, label, self.randomize_p, rng) if self.train else dlm
            out["intention"] = one_hot(shown)
        elif self.kind == "lpe":
            out["lpe"] = normalize(to_unit(self.pool.gather(idx, "lpe")))
        return out


def epoch_batches(weights: np.ndarray | None, pool_idx: np.ndarray, samples: int, batch: int, seed: int, epoch: int) -> list[np.ndarray]:
    """The epoch's draws, `samples` indices with replacement from `pool_idx` by `weights`
    (None: uniform), cut into batches (the last one may be smaller)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, epoch, 0x5A3F1E]))
    draws = rng.choice(len(pool_idx), size=samples, replace=True, p=weights)
    picked = pool_idx[draws]
    return [picked[i : i + batch] for i in range(0, samples, batch)]


def sequential_batches(pool_idx: np.ndarray, batch: int) -> list[np.ndarray]:
    return [pool_idx[i : i + batch] for i in range(0, len(pool_idx), batch)]


def loader(source: Batches, workers: int) -> torch.utils.data.DataLoader:
    # Items are already batches; the DataLoader only adds worker processes.
    return torch.utils.data.DataLoader(source, batch_size=None, shuffle=False, num_workers=workers)

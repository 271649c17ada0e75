"""Training recipes: the project's default and the paper's, and the card's list of deviations.

The paper (Gao et al. 2017, section 3.2): 4:1 split, MSE on (v, omega) normalised to [-1, 1],
RMSprop lr 1e-4, L2 1e-4, lr = lr0 / (1 + k), batch 8, 200,000 samples drawn uniformly from the
pool per epoch, ResNet-50 at 224 x 224, no augmentation.

The default follows what LEARNING.md reports to work in closed loop: L1, Adam(W), batch 64,
cosine decay, balanced sampling by DLM class and turn rate, photometric augmentation and
randomised intentions on straight go_forward frames. Anything given on the command line
overrides the preset; `deviations` lists every way the run differs from the paper, recipe,
model and data alike, and goes into the card.
"""

from __future__ import annotations

PRESETS = {
    "default": {
        "loss": "l1",
        "optimizer": "adamw",
        "lr": 3e-4,
        "weight_decay": 1e-4,
        "batch": 64,
        "schedule": "cosine",
        "samples_per_epoch": None,  # None: the number of training samples
        "balance": True,
        "balance_speed": False,
        "augment": True,
        "randomize_intention": 0.2,
    },
    "paper": {
        "loss": "mse",
        "optimizer": "rmsprop",
        "lr": 1e-4,
        "weight_decay": 1e-4,  # RMSprop's weight_decay is a coupled L2 penalty, as in the paper
        "batch": 8,
        "schedule": "inverse",  # lr0 / (1 + k), k = epoch index
        "samples_per_epoch": 200_000,
        "balance": False,
        "balance_speed": False,
        "augment": False,
        "randomize_intention": 0.0,
    },
}
PAPER = PRESETS["paper"]
PAPER_IMAGE_PX = 224


def resolve(preset: str, overrides: dict) -> dict:
    """The preset with every non-None override applied."""
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r} (one of {sorted(PRESETS)})")
    r = dict(PRESETS[preset], preset=preset)
    r.update({k: v for k, v in overrides.items() if v is not None})
    return r


def deviations(recipe: dict, model_config: dict, camera_px: int, lpe_px: int, indexes: list[dict], minutes: float | None) -> list[str]:
    """Every difference from the paper's setup, in words, for the card."""
    d = []
    kind = model_config["kind"]
    backbone = model_config.get("backbone", "small")
    if backbone == "small":
        d.append("backbone: small 5-layer CNN (~0.4 M parameters) instead of ResNet-50 (CPU training)")
    elif backbone == "small-spatial":
        d.append("backbone: wider small 5-layer CNN (~1 M parameters) with average pool and spatial soft-argmax "
                 "keypoints instead of ResNet-50 (fits a 10 Hz CPU budget on the robot)")
    else:
        d.append("backbone: ResNet-50 randomly initialised (no ImageNet weights downloaded)")
    if camera_px != PAPER_IMAGE_PX:
        d.append(f"camera input {camera_px}x{camera_px} px (224 px rendering area-averaged) instead of 224x224")
    if kind == "lpe":
        if lpe_px != PAPER_IMAGE_PX:
            d.append(f"LPE input {lpe_px}x{lpe_px} px (224 px rendering area-averaged) instead of 224x224")
        branch = model_config.get("lpe_branch", "light")
        if branch == "light":
            d.append("LPE-Net: the LPE image goes through a separate, lighter CNN instead of the shared (siamese) backbone")
        elif branch == "separate":
            d.append("LPE-Net: the LPE image goes through a separate backbone (own weights) instead of the shared (siamese) one")
    d.append("heads: MLP (one hidden layer, dropout 0.2) instead of one linear layer"
             + ("; one head per intention selected by the one-hot as in the paper" if kind == "dlm" else ""))
    d.append("train/validation split by episode (no episode on both sides) instead of per sample")
    names = {"l1": "L1", "mse": "MSE", "adamw": "AdamW", "adam": "Adam", "rmsprop": "RMSprop"}
    if recipe["loss"] != PAPER["loss"]:
        d.append(f"loss {names[recipe['loss']]} instead of MSE")
    if recipe["optimizer"] != PAPER["optimizer"]:
        wd = "decoupled weight decay" if recipe["optimizer"] == "adamw" else "L2"
        d.append(f"optimizer {names[recipe['optimizer']]} ({wd} {recipe['weight_decay']:g}) instead of RMSprop (L2 1e-4)")
    elif recipe["weight_decay"] != PAPER["weight_decay"]:
        d.append(f"L2 {recipe['weight_decay']:g} instead of 1e-4")
    if recipe["lr"] != PAPER["lr"]:
        d.append(f"initial learning rate {recipe['lr']:g} instead of 1e-4")
    if recipe["schedule"] != PAPER["schedule"]:
        d.append(f"learning-rate schedule {recipe['schedule']} (to 1% of lr0 over the run) instead of lr0/(1+k)")
    if recipe["batch"] != PAPER["batch"]:
        d.append(f"batch {recipe['batch']} instead of 8")
    if recipe["samples_per_epoch"] != PAPER["samples_per_epoch"]:
        d.append(f"{recipe['samples_per_epoch']} samples per epoch instead of 200,000")
    if recipe["balance"]:
        cells = "(DLM class, |omega| bin, slow/moving)" if recipe.get("balance_speed") else "(DLM class, |omega| bin)"
        d.append(f"balanced sampling: equal mass per {cells} cell, boost capped at 10x, instead of uniform")
    turn_rate = "" if recipe.get("turn_label") in ("lead", "spin") else "; turn rate the command's"
    if recipe.get("speed_label") == "target":
        d.append("speed label: the target speed the expert's command filter steers towards, not its filtered "
                 "command (which from rest is the current motion plus a bounded step)" + turn_rate)
    if recipe.get("speed_label") == "lead":
        d.append("speed label: the larger of the expert's target speed and its filtered command (the target on "
                 "setting off, the command while it brakes)" + turn_rate)
    if recipe.get("turn_label") == "lead":
        d.append("turn-rate label: the expert's target turn rate where the robot stands or crawls and the target "
                 "turns the same way harder than the filtered command (a DAgger label restarts from the learner's "
                 "own standstill), the command elsewhere")
    if recipe.get("turn_label") == "spin":
        d.append("turn-rate label: the expert's target turn rate where the robot stands or crawls or the expert "
                 "means to stop (target speed slow) and the target turns the same way harder than the filtered "
                 "command (a DAgger label restarts from the learner's own motion), the command elsewhere")
    if recipe["augment"]:
        d.append("photometric augmentation of the camera image (brightness, multiply, contrast, blur, noise, pixel dropout)")
    if kind == "dlm" and recipe["randomize_intention"] > 0:
        d.append(f"intention randomised (turn_left/turn_right/go_forward) on {recipe['randomize_intention']:.0%} "
                 "of go_forward frames with |omega| < 0.1")
    d.append("demonstrations from the project's privileged expert (eval/src/expert.rs) through the agent's "
             "safety rules, not the dynamic-window approach")
    noise = sorted({float(ix.get("noise", 0) or 0) for ix in indexes} - {0.0})
    if noise:
        d.append(f"steering-noise episodes ({', '.join(f'{n:.0%}' for n in noise)} of the episodes) "
                 "whose labels stay the expert's corrective command")
    dagger = [ix for ix in indexes if ix.get("policy")]
    if dagger:
        d.append(f"DAgger: {len(dagger)} of {len(indexes)} recordings driven by a learner mixed with the expert "
                 "(expert labels)")
    if minutes is not None:
        d.append(f"training capped at {minutes:g} minutes of wall time")
    return d

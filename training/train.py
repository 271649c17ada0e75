"""Trains DLM-Net, LPE-Net or the Non-Intention Net on recorded demonstrations and exports the
ONNX model with its card.

    python -m training.train --kind dlm --data data/d1 --out out/train/dlm --minutes 60

Run from the repository root. What it does (details in training/README.md):

1. opens the recordings by memory map (`data.Pool`), splits them 4:1 by episode;
2. per epoch draws `samples_per_epoch` training samples (balanced by DLM class and |omega| bin
   unless --preset paper), augments the camera image photometrically and randomises the
   intention on straight go_forward frames (DLM), and fits with the recipe's loss/optimiser;
3. after every epoch validates (recipe loss, L1 overall, per intention, for v and omega),
   saves `checkpoint_last.pt`, `checkpoint_best.pt` (lowest validation loss), `history.json`
   and `loss.png`;
4. stops after --epochs, or after the step where --minutes runs out (then validates once more);
5. exports the best checkpoint to `<out>/<kind>.onnx` with the card (export.py), checks it with
   onnxruntime, writes `<out>/card.json` and prints a summary.
"""

from __future__ import annotations

import os

# Before torch loads OpenMP: idle OpenMP threads sleep instead of spinning. On a machine whose
# cores are shared (a recording or a build beside the training) spinning threads fight the other
# process at every barrier; measured here with 2 threads next to one busy process: 50 samples/s
# spinning, 280 passive. Set OMP_WAIT_POLICY=ACTIVE to override on an idle machine.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse
import json
import math
import random
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from training import data, export, model, recipe

CHECKPOINT_FORMAT = "intention-fleet-checkpoint"
CHECKPOINT_VERSION = 1
MIN_LR_FRACTION = 0.01  # cosine decays to 1 % of lr0
CURVE_EVERY_S = 5.0  # training-curve point interval (wall seconds)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m training.train",
        description="Train an intention-net (dlm, lpe) or the Non-Intention Net (none) and export it to ONNX.",
    )
    p.add_argument("--kind", required=True, choices=model.KINDS)
    p.add_argument("--data", required=True, nargs="+", help="recording folder(s) written by `eval record`; DIR@FRACTION: an evenly spaced share of its shards")
    p.add_argument("--out", required=True, help="output folder (checkpoints, history, loss.png, <kind>.onnx, card.json)")
    p.add_argument("--preset", default="default", choices=sorted(recipe.PRESETS),
                   help="default: LEARNING.md's recipe (L1, AdamW, balanced, augmented); paper: Gao et al.'s")
    p.add_argument("--minutes", type=float, help="wall-time budget; stops after the step where it runs out")
    p.add_argument("--epochs", type=int, help="epochs (default: 10, or unlimited when --minutes is given)")
    p.add_argument("--samples-per-epoch", type=int, help="draws per epoch (default: training-set size; paper: 200000)")
    p.add_argument("--batch", type=int, help="batch size (default 64; paper 8)")
    p.add_argument("--lr", type=float, help="initial learning rate (default 3e-4; paper 1e-4)")
    p.add_argument("--weight-decay", type=float, help="AdamW weight decay / RMSprop L2 (default 1e-4)")
    p.add_argument("--loss", choices=("l1", "mse"), help="override the preset's loss")
    p.add_argument("--optimizer", choices=("adamw", "adam", "rmsprop"), help="override the preset's optimiser")
    p.add_argument("--schedule", choices=("cosine", "inverse", "constant"), help="override the preset's lr schedule")
    p.add_argument("--balance", action=argparse.BooleanOptionalAction, default=None,
                   help="balanced sampling by DLM class and |omega| bin (default on; paper off)")
    p.add_argument("--balance-speed", action=argparse.BooleanOptionalAction, default=None,
                   help="also split the balancing cells by slow/moving speed label (default off)")
    p.add_argument("--speed-label", choices=data.SPEED_LABELS, default="command",
                   help="speed label: the expert's command (default), the target speed its filter steers towards, or "
                        "'lead', the larger of the two (recordings with a 'target' field); the turn rate: --turn-label")
    p.add_argument("--turn-label", choices=data.TURN_LABELS, default="command",
                   help="turn-rate label: the expert's command (default); 'lead', its target where the robot "
                        "stands or crawls and the target turns the same way harder; 'spin', also where the target "
                        "speed is slow (the expert means to turn on the spot); recordings with a 'target' field")
    p.add_argument("--augment", action=argparse.BooleanOptionalAction, default=None,
                   help="photometric augmentation of the camera image (default on; paper off)")
    p.add_argument("--randomize-intention", type=float,
                   help="DLM: probability of a random intention on go_forward frames with |omega| < 0.1 (default 0.2; paper 0)")
    p.add_argument("--val-fraction", type=float, default=0.2, help="share of samples (whole episodes) for validation")
    p.add_argument("--backbone", default="small", choices=model.BACKBONES, help="small CNN (CPU), small-spatial (wider, average pool + soft-argmax keypoints; for GPU training, CPU inference) or resnet50 (GPU, needs torchvision)")
    p.add_argument("--lpe-branch", default="light", choices=model.LPE_BRANCHES,
                   help="LPE-Net: light separate CNN (default), shared siamese backbone (paper), or separate full backbone")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument("--workers", type=int, default=0, help="DataLoader worker processes for reading/augmenting batches")
    p.add_argument("--preload", action=argparse.BooleanOptionalAction, default=True,
                   help="copy the image fields into memory first (default on: random reads from a "
                        "memory map on disk are I/O-bound); --no-preload for recordings larger than memory")
    p.add_argument("--device", default="auto", help="cpu, cuda, or auto (cuda when available)")
    p.add_argument("--max-onnx-mb", type=float, default=export.MAX_MB, help="refuse an exported model larger than this")
    p.add_argument("--no-export", action="store_true", help="skip the ONNX export at the end")
    p.add_argument("--keep-epochs", action="store_true",
                   help="also keep every epoch's checkpoint as checkpoint_eNN.pt: candidates to judge in closed "
                        "loop, where validation loss does not choose (a GPU lease brings them all back)")
    p.add_argument("--init", help="start from this checkpoint's weights (same kind and architecture), e.g. "
                   "the previous DAgger round's checkpoint_best.pt; optimiser and schedule start afresh")
    p.add_argument("--freeze-bn", action="store_true",
                   help="keep every batch norm's running statistics as --init left them (the layers in eval mode "
                        "while training; their scale and shift still learn): a fine-tune then cannot re-estimate "
                        "them on its new data")
    p.add_argument("--init-stop-from-forward", action="store_true",
                   help="DLM-Net with --init: the stop intention (head and embedding column) starts as a copy "
                        "of go_forward's, for recordings with the arriving Stop (dlm.arrive_distance_m) fine-tuned "
                        "from a network trained without it, whose stop head never saw a sample")
    p.add_argument("--init-camera", help="start the camera backbone only from this checkpoint's camera backbone "
                   "(any kind, the same --backbone), e.g. LPE-Net's for a new DLM-Net; the rest starts fresh")
    args = p.parse_args(argv)
    if args.init and args.init_camera:
        p.error("--init and --init-camera exclude each other (--init already loads the camera)")
    if args.init_stop_from_forward and not (args.init and args.kind == "dlm"):
        p.error("--init-stop-from-forward needs --kind dlm and --init")
    if args.freeze_bn and not (args.init or args.init_camera):
        p.error("--freeze-bn needs --init or --init-camera (freshly built batch norms have no statistics to keep)")
    if args.backbone == "resnet50" and args.max_onnx_mb < 200:
        p.error("a ResNet-50 model is ~95 MB in ONNX (two for --lpe-branch separate); pass --max-onnx-mb 200 or more")
    return args


def load_camera(net: torch.nn.Module, config: dict, path: str) -> tuple[str, str | None]:
    """Loads the camera backbone of checkpoint `path` (any kind, the same backbone) into `net`'s
    camera; returns the checkpoint's resolved path and its dataset id. A camera that learned
    corridors, doors and people for one network is a better start for another kind's than
    random weights: the image is the same, only what is made of it differs."""
    init = torch.load(path, map_location="cpu", weights_only=False)
    theirs = init.get("model_config") or {}
    if theirs.get("backbone", "small") != config["backbone"]:
        raise SystemExit(f"--init-camera {path}: its backbone {theirs.get('backbone', 'small')!r} "
                         f"is not --backbone {config['backbone']!r}")
    camera = {k.removeprefix("camera."): v for k, v in init["state_dict"].items() if k.startswith("camera.")}
    if not camera:
        raise SystemExit(f"--init-camera {path}: the checkpoint has no camera backbone")
    net.camera.load_state_dict(camera)  # strict: every weight of the camera, nothing else
    return str(Path(path).resolve()), init.get("card_inputs", {}).get("dataset_id")


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def make_optimizer(name: str, params, lr: float, wd: float) -> torch.optim.Optimizer:
    if name == "adamw":
        return torch.optim.AdamW(params, lr=lr, weight_decay=wd)
    if name == "adam":
        return torch.optim.Adam(params, lr=lr, weight_decay=wd)
    if name == "rmsprop":
        # Keras' RMSprop defaults (rho 0.9, eps 1e-7), which the authors' code used.
        return torch.optim.RMSprop(params, lr=lr, alpha=0.9, eps=1e-7, weight_decay=wd)
    raise ValueError(name)


def lr_at(r: dict, epoch: int, progress: float) -> float:
    """Learning rate for the recipe's schedule. `progress` in [0, 1] is the share of the run
    done (steps or wall time, whichever limit binds), for the cosine schedule."""
    lr0 = r["lr"]
    if r["schedule"] == "inverse":
        return lr0 / (1 + epoch)
    if r["schedule"] == "cosine":
        lo = MIN_LR_FRACTION * lr0
        return lo + (lr0 - lo) * 0.5 * (1 + math.cos(math.pi * min(1.0, progress)))
    return lr0


def loss_fn(name: str):
    return F.l1_loss if name == "l1" else F.mse_loss


def inputs_of(kind: str, batch: dict, device) -> list[torch.Tensor]:
    # Images channels-last like the network's weights: ~35 % faster convolutions on the CPU.
    return [
        batch[n].to(device, non_blocking=True, memory_format=torch.channels_last) if batch[n].dim() == 4
        else batch[n].to(device, non_blocking=True)
        for n in model.input_names(kind)
    ]


@torch.no_grad()
def evaluate(net, pool: data.Pool, val_idx: np.ndarray, kind: str, loss_name: str, batch: int, device, workers: int) -> dict:
    """Validation metrics on the recorded intentions, no augmentation.

    `loss` is the recipe's loss averaged over the DLM classes present (so junction frames
    count as much as straight driving; this is the card's validation_loss and picks the best
    checkpoint); `loss_all` the plain mean; L1 overall, for v and omega, and per intention.
    DLM also reports `intention_effect_omega`: the mean |omega| change on turn frames when the
    intention is replaced by go_forward -- near zero means the net ignores the intention."""
    net.eval()
    src = data.Batches(pool, data.sequential_batches(val_idx, batch), kind, train=False)
    preds, labels, dlms, effect = [], [], [], []
    for b in data.loader(src, workers):
        x = inputs_of(kind, b, device)
        y = net(*x)
        preds.append(y.float().cpu())
        labels.append(b["label"])
        dlms.append(b["dlm"])
        if kind == "dlm":
            turn = b["dlm"] <= 1
            if turn.any():
                fwd = torch.zeros_like(x[1])
                fwd[:, data.GO_FORWARD] = 1
                y_fwd = net(x[0], fwd)
                effect.append((y[:, 1] - y_fwd[:, 1]).abs().cpu()[turn])
    pred, label, dlm = torch.cat(preds), torch.cat(labels), torch.cat(dlms)
    err = (pred - label).abs()
    per_sample = err.mean(1) if loss_name == "l1" else ((pred - label) ** 2).mean(1)
    per_int, per_int_loss, counts = {}, [], {}
    for c, name in enumerate(data.DLM_NAMES):
        m = dlm == c
        counts[name] = int(m.sum())
        if m.any():
            per_int[name] = float(err[m].mean())
            per_int_loss.append(float(per_sample[m].mean()))
        else:
            per_int[name] = None
    out = {
        "loss": float(np.mean(per_int_loss)),
        "loss_all": float(per_sample.mean()),
        "l1": float(err.mean()),
        "l1_v": float(err[:, 0].mean()),
        "l1_omega": float(err[:, 1].mean()),
        "per_intention_l1": per_int,
        "per_intention_count": counts,
        "samples": int(len(label)),
    }
    if kind == "dlm":
        out["intention_effect_omega"] = float(torch.cat(effect).mean()) if effect else None
    return out


def plot(history: dict, path: Path) -> None:
    """loss.png: training curve and per-epoch train/val loss; per-intention validation L1."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = history["epochs"]
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    if history["curve"]:
        s, l = zip(*history["curve"])
        a.plot(s, l, color="0.75", lw=1, label="train (running, augmented)")
    if epochs:
        s = [e["samples_seen"] for e in epochs]
        a.plot(s, [e["train_loss"] for e in epochs], "o-", label="train (epoch mean)")
        a.plot(s, [e["val"]["loss"] for e in epochs], "s-", label="validation (class-balanced)")
        a.plot(s, [e["val"]["loss_all"] for e in epochs], "^--", label="validation (all frames)")
        for name in data.DLM_NAMES:
            ys = [e["val"]["per_intention_l1"][name] for e in epochs]
            if any(y is not None for y in ys):
                b.plot(s, [np.nan if y is None else y for y in ys], "o-", label=name)
        b.plot(s, [e["val"]["l1_v"] for e in epochs], "k:", label="v (all)")
        b.plot(s, [e["val"]["l1_omega"] for e in epochs], "k--", label="omega (all)")
    a.set(xlabel="samples seen", ylabel=f"{history['recipe']['loss'].upper()} loss", title=f"{history['kind']}: loss")
    b.set(xlabel="samples seen", ylabel="L1", title="validation L1 per intention")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def save_json(path: Path, obj) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(obj, indent=1) + "\n")
    os.replace(tmp, path)


def main(argv=None) -> int:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    try:
        torch.set_num_interop_threads(1)
    except RuntimeError:  # already set (when called twice in one process)
        pass
    seed_everything(args.seed)
    device = torch.device("cuda" if args.device == "auto" and torch.cuda.is_available() else
                          ("cpu" if args.device == "auto" else args.device))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    preload = () if not args.preload else (("camera", "lpe") if args.kind == "lpe" else ("camera",))
    pool = data.Pool(args.data, preload=preload, speed_label=args.speed_label, turn_label=args.turn_label)
    train_idx, val_idx, val_keys = data.split_by_episode(pool, args.val_fraction, args.seed)
    r = recipe.resolve(args.preset, {
        "loss": args.loss, "optimizer": args.optimizer, "lr": args.lr, "weight_decay": args.weight_decay,
        "batch": args.batch, "schedule": args.schedule, "samples_per_epoch": args.samples_per_epoch,
        "balance": args.balance, "balance_speed": args.balance_speed, "augment": args.augment, "randomize_intention": args.randomize_intention,
    })
    if args.speed_label != "command":
        # Only when not the default, so older recipes read as they did.
        r["speed_label"] = args.speed_label
    if args.turn_label != "command":
        r["turn_label"] = args.turn_label
    if r["samples_per_epoch"] is None:
        r["samples_per_epoch"] = int(len(train_idx))
    if args.kind != "dlm":
        r["randomize_intention"] = 0.0  # only DLM has an intention input to randomise
    epochs = args.epochs if args.epochs is not None else (None if args.minutes is not None else 10)
    r["epochs"] = epochs
    r["val_fraction"] = args.val_fraction
    r["seed"] = args.seed
    if args.freeze_bn:
        r["freeze_bn"] = True

    config = {"kind": args.kind, "backbone": args.backbone, "lpe_branch": args.lpe_branch}
    # Channels-last weights and images: oneDNN's fast convolution layout (the ONNX export is
    # built from a fresh model and does not depend on it).
    net = model.build(config)
    if args.init:
        init = torch.load(args.init, map_location="cpu", weights_only=False)
        if init.get("model_config") != config:
            raise SystemExit(f"--init {args.init}: its model {init.get('model_config')} is not {config}")
        net.load_state_dict(init["state_dict"])
        r["init"] = str(Path(args.init).resolve())
        r["init_datasets"] = init.get("card_inputs", {}).get("dataset_id")
        if args.init_stop_from_forward:
            net.copy_intention(data.GO_FORWARD, data.DLM_NAMES.index("stop"))
            r["init_stop_from_forward"] = True
    if args.init_camera:
        r["init_camera"], r["init_datasets"] = load_camera(net, config, args.init_camera)
    net = net.to(device, memory_format=torch.channels_last)
    n_params = model.count_parameters(net)
    camera_px, lpe_px = pool.camera_px[0], pool.lpe_px[0]
    card_inputs = {
        "kind": args.kind,
        "backbone_text": model.describe(config),
        "camera_px": camera_px,
        "lpe_px": lpe_px,
        "norm_mean": list(data.NORM_MEAN),
        "norm_std": list(data.NORM_STD),
        "max_speed_mps": pool.max_speed_mps,
        "max_turn_radps": pool.max_turn_radps,
        "dataset_id": pool.dataset_id,
        "lpe_rendering": pool.lpe_rendering,
        "dlm_params": pool.dlm_params,
    }
    deviations = recipe.deviations(r, config, camera_px, lpe_px, [ds.index for ds in pool.sets], args.minutes)
    if args.init:
        deviations.append(f"warm-started from the weights of {args.init} (an earlier round, trained on "
                          f"dataset {r['init_datasets']}), as a DAgger round retrains the learner")
    if args.init_stop_from_forward:
        deviations.append("the stop intention's head and embedding column warm-started as copies of go_forward's")
    if args.freeze_bn:
        deviations.append("batch norms' running statistics kept at the warm start's while fine-tuning "
                          "(eval mode; their scale and shift still trained)")
    if args.init_camera:
        deviations.append(f"camera backbone warm-started from the camera backbone of {args.init_camera} "
                          f"(trained on dataset {r['init_datasets']}); intention, heads and the rest from scratch")

    if r["balance"]:
        w, cells = data.balance_weights(pool.dlm[train_idx], pool.label[train_idx],
                                        by_speed=bool(r.get("balance_speed")))
    else:
        w, cells = None, {}
    print(f"data: {len(pool)} samples ({', '.join(pool.dataset_ids)}), camera {camera_px} px, lpe {lpe_px} px; "
          f"train {len(train_idx)}, validation {len(val_idx)} ({len(val_keys)} episodes)")
    if cells:
        print("balanced sampling (cell: samples -> share of draws): " +
              "; ".join(f"{k}: {n} -> {m:.1%}" for k, (n, m) in cells.items()))
    print(f"model: {args.kind}, {n_params:,} parameters, {model.describe(config)}; device {device}, "
          f"{args.threads} threads, {args.workers} workers")
    print("recipe: " + json.dumps(r, sort_keys=True))

    opt = make_optimizer(r["optimizer"], net.parameters(), r["lr"], r["weight_decay"])
    criterion = loss_fn(r["loss"])
    steps_per_epoch = math.ceil(r["samples_per_epoch"] / r["batch"])
    total_steps = steps_per_epoch * epochs if epochs else None
    budget_s = args.minutes * 60 if args.minutes is not None else None

    history = {"kind": args.kind, "recipe": r, "model": config, "parameters": n_params,
               "dataset_ids": pool.dataset_ids, "val_episode_keys": val_keys, "epochs": [], "curve": []}
    common = {
        "format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "model_config": config,
        "card_inputs": card_inputs, "recipe": r, "deviations": deviations, "parameters": n_params,
        "data": {"dirs": [str(Path(d).resolve()) for d in args.data], "val_episode_keys": val_keys,
                 "sources": pool.describe_sources(), "train_samples": int(len(train_idx)),
                 "val_samples": int(len(val_idx))},
        "seed": args.seed, "torch_version": str(torch.__version__),
    }
    tty = sys.stderr.isatty()
    start = time.monotonic()
    step, seen, best, stop = 0, 0, math.inf, False
    epoch = 0
    while not stop and (epochs is None or epoch < epochs):
        net.train()
        if args.freeze_bn:
            model.freeze_batch_norm_statistics(net)
        batches = data.epoch_batches(w, train_idx, r["samples_per_epoch"], r["batch"], args.seed, epoch)
        src = data.Batches(pool, batches, args.kind, train=True, seed=args.seed, epoch=epoch,
                           augment_images=r["augment"], randomize_p=r["randomize_intention"])
        t_epoch, loss_sum, n_sum = time.monotonic(), 0.0, 0
        run_loss, last_curve = None, time.monotonic()
        bar = tqdm(data.loader(src, args.workers), total=len(batches), desc=f"epoch {epoch}",
                   mininterval=0.5 if tty else 30, file=sys.stderr, dynamic_ncols=True)
        for b in bar:
            elapsed = time.monotonic() - start
            progress = max(step / total_steps if total_steps else 0.0, elapsed / budget_s if budget_s else 0.0)
            lr = lr_at(r, epoch, progress)
            for g in opt.param_groups:
                g["lr"] = lr
            x = inputs_of(args.kind, b, device)
            y = b["label"].to(device, non_blocking=True)
            loss = criterion(net(*x), y)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            lv, n = float(loss.detach()), len(y)
            loss_sum += lv * n
            n_sum += n
            step += 1
            seen += n
            run_loss = lv if run_loss is None else 0.98 * run_loss + 0.02 * lv
            now = time.monotonic()
            if now - last_curve >= CURVE_EVERY_S:
                history["curve"].append([seen, run_loss])
                last_curve = now
            bar.set_postfix(loss=f"{run_loss:.4f}", sps=f"{n_sum / max(now - t_epoch, 1e-9):.0f}", lr=f"{lr:.2e}",
                            refresh=False)
            if budget_s is not None and now - start >= budget_s:
                stop = True
                break
        bar.close()
        train_s = time.monotonic() - t_epoch
        if n_sum == 0:
            break
        val = evaluate(net, pool, val_idx, args.kind, r["loss"], max(r["batch"], 64), device, args.workers)
        minutes = (time.monotonic() - start) / 60
        entry = {"epoch": epoch, "samples_seen": seen, "steps": step, "train_loss": loss_sum / n_sum,
                 "train_samples_per_s": n_sum / train_s, "train_s": train_s, "lr": lr, "minutes": minutes,
                 "partial": n_sum < r["samples_per_epoch"], "val": val}
        history["epochs"].append(entry)
        is_best = val["loss"] < best
        best = min(best, val["loss"])
        state = dict(common, state_dict=net.state_dict(), epoch=epoch, samples_seen=seen, steps=step,
                     train_loss=entry["train_loss"], val=val, training_minutes=minutes)
        torch.save(state, out / "checkpoint_last.pt")
        if args.keep_epochs:
            torch.save(state, out / f"checkpoint_e{epoch:02d}.pt")
        if is_best:
            torch.save(state, out / "checkpoint_best.pt")
        history["best_epoch"] = min(history["epochs"], key=lambda e: e["val"]["loss"])["epoch"]
        save_json(out / "history.json", history)
        plot(history, out / "loss.png")
        pi = ", ".join(f"{k} {v:.4f}" for k, v in val["per_intention_l1"].items() if v is not None)
        eff = f", intention effect on omega {val['intention_effect_omega']:.3f}" if val.get("intention_effect_omega") is not None else ""
        print(f"epoch {epoch}: train {entry['train_loss']:.4f} ({entry['train_samples_per_s']:.0f} samples/s), "
              f"val {val['loss']:.4f} (all frames {val['loss_all']:.4f}; L1 v {val['l1_v']:.4f} omega {val['l1_omega']:.4f}; "
              f"per intention {pi}{eff}){' *best*' if is_best else ''}; {minutes:.1f} min", flush=True)
        epoch += 1

    if not history["epochs"]:
        sys.exit("no training step was run")
    total_min = (time.monotonic() - start) / 60
    best_entry = min(history["epochs"], key=lambda e: e["val"]["loss"])
    summary = {
        "kind": args.kind, "parameters": n_params, "epochs": len(history["epochs"]), "samples_seen": seen,
        "training_minutes": round(total_min, 2), "best_epoch": best_entry["epoch"],
        "validation_loss": best_entry["val"]["loss"], "val": best_entry["val"],
        # Training steps only (data, augmentation, forward, backward), without validation.
        "train_samples_per_s": round(seen / max(sum(e["train_s"] for e in history["epochs"]), 1e-9), 1),
    }
    if not args.no_export:
        onnx_path = out / f"{args.kind}.onnx"
        result = export.export_checkpoint(out / "checkpoint_best.pt", onnx_path, max_mb=args.max_onnx_mb,
                                          card_json=out / "card.json")
        summary.update(onnx=str(onnx_path), onnx_mb=round(result["size_mb"], 3), onnx_max_abs_diff=result["max_abs_diff"],
                       onnx_check_inputs=result["check_inputs"])
    save_json(out / "summary.json", summary)
    print("summary: " + json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The training loop: AdamW, linear warm-up then staged decay, gradient clipping, atomic checkpoints and resume,
and a readable log (one line per `log_every` steps, also appended to RUN/train.log)."""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass

import numpy as np
import torch

from ..errors import RanadError
from ..fileutil import atomic_output
from ..model import RaNAD, feature_dim, get_config, prepare
from .data import find_pairs, sample
from .losses import total_loss

CHECKPOINT = "checkpoint.pt"


@dataclass
class TrainConfig:
    dataset: str
    run: str
    config: str = "cpu-small"
    steps: int = 2000
    crop: int = 48
    lr: float = 1e-3
    weight_decay: float = 1e-4
    warmup: float = 0.05          # share of the steps
    decay_at: tuple = (0.6, 0.85)  # shares of the steps where the learning rate drops 3x
    clip: float = 1.0
    seed: int = 0
    log_every: int = 20
    checkpoint_every: int = 200


def learning_rate(cfg: TrainConfig, step: int) -> float:
    warm = max(1, int(cfg.warmup * cfg.steps))
    lr = cfg.lr * min(1.0, (step + 1) / warm)
    return lr * 0.3 ** sum(step >= int(f * cfg.steps) for f in cfg.decay_at)


def save_checkpoint(path: str, model, opt, step: int, cfg: TrainConfig, rng: np.random.Generator) -> None:
    state = {"model": model.state_dict(), "optimizer": opt.state_dict(), "step": step,
             "model_config": model.config.to_dict(), "train_config": asdict(cfg), "rng": rng.bit_generator.state}
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def train(cfg: TrainConfig, progress=None) -> dict:
    """Trains (or resumes) into cfg.run; returns the last step's loss parts."""
    pairs = find_pairs(cfg.dataset)
    os.makedirs(cfg.run, exist_ok=True)
    torch.manual_seed(cfg.seed)
    model = RaNAD(get_config(cfg.config), feature_dim())
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    rng = np.random.default_rng(cfg.seed)
    step = 0
    ckpt = os.path.join(cfg.run, CHECKPOINT)
    if os.path.isfile(ckpt):
        state = torch.load(ckpt, weights_only=False)
        if state["model_config"]["name"] != cfg.config:
            raise RanadError(f"checkpoint is for config {state['model_config']['name']!r}, not {cfg.config!r}", ckpt)
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        rng.bit_generator.state = state["rng"]
        step = state["step"]
    log = open(os.path.join(cfg.run, "train.log"), "a")
    parts = {}
    t0 = time.perf_counter()
    while step < cfg.steps:
        pair = pairs[int(rng.integers(0, len(pairs)))]
        noisy_img, ref_img = sample(pair, rng, cfg.crop)
        noisy, ref = prepare(noisy_img), prepare(ref_img)
        if noisy.layout.bins == 0:
            continue
        for g in opt.param_groups:
            g["lr"] = learning_rate(cfg, step)
        pred = model(noisy)
        loss, parts = total_loss(pred, ref.layers, noisy.layout.offsets)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip)
        opt.step()
        step += 1
        if step % cfg.log_every == 0 or step == cfg.steps:
            secs = (time.perf_counter() - t0) / cfg.log_every
            t0 = time.perf_counter()
            line = (f"step {step} loss {loss.item():.4f} " + " ".join(f"{k} {v:.4f}" for k, v in parts.items())
                    + f" lr {learning_rate(cfg, step - 1):.2e} {secs:.2f} s/step")
            print(line, file=log, flush=True)
        if step % cfg.checkpoint_every == 0 or step == cfg.steps:
            save_checkpoint(ckpt, model, opt, step, cfg, rng)
        if progress:
            progress(1)
    log.close()
    return parts

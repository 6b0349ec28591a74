"""The training loop: AdamW, linear warm-up then staged decay, gradient clipping, atomic checkpoints and resume,
and a readable log (one line per `log_every` steps, appended to RUN/train.log).

Data parallel training goes through torch.distributed (DDP on the gloo backend, which runs on CPUs): every
process samples its own crops (its own random stream), gradients are averaged, so one step consumes one crop per
process. Processes come either from `torchrun` (several machines; the usual RANK/WORLD_SIZE/MASTER_ADDR
environment) or from `spawn_local` (several processes on this machine). Only rank 0 writes the checkpoint and
the log."""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass

import numpy as np
import torch

from ..errors import RanadError
from ..fileutil import atomic_output, probe_writable
from ..model import RaNAD, feature_dim, get_config, prepare
from .data import (find_frame_pairs, find_pairs, frame_context, normal_rotation, reduce_inputs, reduce_window,
                   sample, sample_consecutive, sample_window)
from .losses import temporal_loss, total_loss

CHECKPOINT = "checkpoint.pt"


@dataclass
class TrainConfig:
    dataset: str | tuple          # a `ranad synth` folder, or several (their scenes pooled)
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
    p_no_aux: float = 0.2         # share of crops shown without albedo/normal (reduced mode)
    p_no_split: float = 0.2       # share of crops shown without the diffuse/specular split (reduced mode)
    p_rotate_normals: float = 0.0  # share of crops with their normals turned at random (data.rotated_normals)
    window: int = 3               # cross-frame configs: frames per training window (centre +- (window-1)/2)
    init: str | None = None       # cross-frame configs: single-frame weights to start from (model name/file/run)
    temporal_weight: float = 0.0  # cross-frame configs: weight of the temporal loss; > 0 trains on consecutive frames
    until: int | None = None      # stop (with a checkpoint) at this step; the schedule still runs to `steps`
    freeze_spatial: bool = False  # cross-frame configs: train only the temporal parts; the single-frame model stays
    p_misalign: float = 0.0       # cross-frame configs: share of windows with misaligned neighbours (data.cropped)
    loss_weights: tuple = ()      # (term, weight) pairs overriding weights.WEIGHTS, e.g. (("separation", 1.0),)
    spp_weights: tuple = ()       # (spp, weight) pairs: relative odds of drawing a crop of that sample count (1)
    device: str = "cpu"           # where the model trains ("cpu" or "cuda"; crops are made on the CPU and moved)


def pair_odds(pairs: list, spp_weights: tuple) -> np.ndarray | None:
    """Probabilities of drawing each pair (each a Pair, or a tuple of Pairs of one sample count) when some sample
    counts are weighted (`TrainConfig.spp_weights`; unnamed counts weigh 1); None without weights, where draws stay
    uniform and use the random stream exactly as runs before the option did."""
    if not spp_weights:
        return None
    weight = dict(spp_weights)
    odds = np.array([weight.get((p[0] if isinstance(p, tuple) else p).spp, 1.0) for p in pairs], np.float64)
    if not odds.sum() > 0:
        raise RanadError("every pair of the datasets has weight 0", "--spp-weight")
    return odds / odds.sum()


def draw(items: list, odds: np.ndarray | None, rng: np.random.Generator):
    """One of `items`: uniformly, or by `odds` (pair_odds)."""
    if odds is None:
        return items[int(rng.integers(0, len(items)))]
    return items[int(rng.choice(len(items), p=odds))]


def learning_rate(cfg: TrainConfig, step: int) -> float:
    warm = max(1, int(cfg.warmup * cfg.steps))
    lr = cfg.lr * min(1.0, (step + 1) / warm)
    return lr * 0.3 ** sum(step >= int(f * cfg.steps) for f in cfg.decay_at)


def param_groups(model) -> list:
    """AdamW parameter groups by learning-rate multiplier (the model's `lr_scale(name)`, 1 without one); each
    group holds its "lr_scale" and its parameter names, which is how a checkpoint's optimizer state finds its
    parameters again when the grouping changed."""
    scale_of = getattr(model, "lr_scale", lambda name: 1.0)
    groups = {}
    for name, p in model.named_parameters():
        g = groups.setdefault(scale_of(name), {"params": [], "names": [], "lr_scale": scale_of(name)})
        g["params"].append(p)
        g["names"].append(name)
    return list(groups.values())


def load_optimizer(opt, saved: dict, model) -> None:
    """Loads `saved` (an optimizer state dict) into `opt`, regrouping per parameter name when the groups differ
    (checkpoints written before the groups existed hold one group in `model.named_parameters()` order)."""
    if [g.get("names") for g in saved["param_groups"]] == [g["names"] for g in opt.param_groups]:
        opt.load_state_dict(saved)
        return
    old_names = [n for g in saved["param_groups"] for n in g.get("names", [])] or \
        [n for n, _ in model.named_parameters()]
    old_ids = [i for g in saved["param_groups"] for i in g["params"]]
    by_name = {n: saved["state"][i] for n, i in zip(old_names, old_ids) if i in saved["state"]}
    state, groups, k = {}, [], 0
    for g in opt.param_groups:
        ids = []
        for n in g["names"]:
            if n in by_name:
                state[k] = by_name[n]
            ids.append(k)
            k += 1
        groups.append({**{key: v for key, v in g.items() if key != "params"}, "params": ids})
    opt.load_state_dict({"state": state, "param_groups": groups})


def resume_step(run: str) -> int:
    """The step a run folder's checkpoint resumes from (0 without one)."""
    ckpt = os.path.join(run, CHECKPOINT)
    from ..model.store import load_checkpoint

    return int(load_checkpoint(ckpt)["step"]) if os.path.isfile(ckpt) else 0


def save_checkpoint(path: str, model, opt, step: int, cfg: TrainConfig, rng: np.random.Generator) -> None:
    state = {"model": model.state_dict(), "optimizer": opt.state_dict(), "step": step,
             "model_config": model.config.to_dict(), "train_config": asdict(cfg), "rng": rng.bit_generator.state}
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def check_freeze(cfg: TrainConfig, config) -> None:
    if cfg.freeze_spatial and config.window <= 1:
        raise RanadError("--freeze-spatial needs a cross-frame config (e.g. cpu-small-p-xf)", cfg.config)
    if cfg.freeze_spatial and not cfg.init:
        raise RanadError("--freeze-spatial needs --init (the single-frame model to keep)", cfg.config)
    if cfg.p_misalign > 0 and config.window <= 1:
        raise RanadError("--p-misalign needs a cross-frame config (e.g. cpu-small-p-xf)", cfg.config)


def freeze_spatial(model, cfg: TrainConfig) -> None:
    """With `cfg.freeze_spatial`, the single-frame part of a cross-frame model (embedding, U-Nets, spatial
    reconstruction) stops learning: only T-Mix (or the input keys' MLP), the temporal step and their gates train.
    The model then starts as the single-frame one and can only add what the neighbours bring, instead of drifting
    away from a spatial denoiser trained on many more scenes than the few shots a cross-frame run sees."""
    if not cfg.freeze_spatial:    # train() has checked the options (check_freeze) before building it
        return
    for name, p in model.named_parameters():
        if name.startswith("single."):
            p.requires_grad_(False)


def build_model(cfg: TrainConfig, config):
    """A fresh model for `config`: single-frame, or cross-frame (started from `cfg.init`'s weights when given, so
    training begins from a working denoiser: a single-frame model's, or a cross-frame model's without the output
    mix for a config with it)."""
    if config.window <= 1:
        model = RaNAD(config, feature_dim(config.features))
        if cfg.init:
            init_single(model, cfg.init)
        return model
    from ..model.crossframe import CrossFrameRaNAD

    if cfg.init:
        from ..model.store import load_model

        init = load_model(cfg.init).model
        if init.config.dim != config.dim or init.config.unets != config.unets:
            raise RanadError(f"--init model {init.config.name!r} does not match config {config.name!r}", cfg.init)
        for flag in ("dropout_lattice", "demodulate", "layer_gate"):   # behaviour, not in the weights' shapes
            if getattr(init.config, flag) != getattr(config, flag):
                raise RanadError(f"--init model {init.config.name!r} has {flag}={getattr(init.config, flag)}, "
                                 f"config {config.name!r} {getattr(config, flag)}", cfg.init)
        if init.config.window > 1:
            if init.config.output_mix or not config.output_mix:
                raise RanadError(f"--init: a cross-frame model starts only a config with the output mix (such as "
                                 f"cpu-small-xfm), not {config.name!r}", cfg.init)
            try:
                return CrossFrameRaNAD.from_cross(init, config, feature_dim(config.features)).train()
            except ValueError as e:
                raise RanadError(f"--init: {e}", cfg.init) from None
        return CrossFrameRaNAD.from_single(init, config, feature_dim(config.features)).train()
    return CrossFrameRaNAD(config, feature_dim(config.features))


def model_device(net) -> torch.device:
    """The device the model's weights are on (training crops are moved there)."""
    return next(unwrap(net).parameters()).device


def unwrap(net):
    """The model inside a DistributedDataParallel wrapper (or the model itself)."""
    return getattr(net, "module", net)


def init_single(model, init_name: str) -> None:
    """Starts single-frame `model` from single-frame weights `init_name` of the same architecture, also when the
    feature sets differ (the new feature columns start at zero, so the model begins as the old one would on its
    shared inputs), or when the init has more U-Nets (its first ones kept: the backbone's residual stream read
    after fewer U-Nets, an early exit that fine-tuning then adapts the reconstructions to)."""
    from ..model.inputs import old_columns
    from ..model.store import load_model

    init = load_model(init_name).model
    a, b = init.config, model.config
    if a.window > 1 or (a.dim, a.levels, a.heads, a.head_dim) != (b.dim, b.levels, b.heads, b.head_dim) \
            or a.unets < b.unets:
        raise RanadError(f"--init model {a.name!r} does not match config {b.name!r}", init_name)
    state = {k: v for k, v in init.state_dict().items() if not _dropped_unet(k, b.unets)}
    w = state["embed.0.weight"]
    new = w.new_zeros(w.shape[0], model.embed[0].in_features)
    new[:, old_columns(a.features, b.features)] = w
    state["embed.0.weight"] = new
    model.load_state_dict(grown_reconstruction(state, model.state_dict(), init_name))


def _dropped_unet(key: str, unets: int) -> bool:
    """Whether weight `key` belongs to a backbone U-Net at index `unets` or later."""
    parts = key.split(".")
    return parts[:2] == ["backbone", "unets"] and int(parts[2]) >= unets


# a new scale's share of the mix when a reconstruction starts from one with fewer scales: softmax logit below the
# learned ones (about 1-2% of the mix), so the model starts where the init was and training decides what the new
# scale is worth
NEW_SCALE_LOGIT = -4.0


def grown_reconstruction(state: dict, own: dict, init_name: str) -> dict:
    """`state` (an init's weights) completed for a model whose reconstruction modules may have more scales
    (ReconConfig.scales) than the init's: the init's scales copied, the new scales' modules as freshly made
    (`own`), the scale mixer's new rows zero with bias NEW_SCALE_LOGIT. Any other difference is an error."""
    out = {}
    for k, v in own.items():
        if k not in state:
            if not k.startswith("recon.") or ".mixer." in k:
                raise RanadError(f"--init model lacks {k}", init_name)
            out[k] = v
        elif state[k].shape != v.shape:
            old = state[k]
            if ".mixer." not in k or old.shape[1:] != v.shape[1:] or old.shape[0] > v.shape[0]:
                raise RanadError(f"--init model's {k} has shape {tuple(old.shape)}, not {tuple(v.shape)}", init_name)
            grown = torch.full_like(v, NEW_SCALE_LOGIT) if k.endswith("bias") else torch.zeros_like(v)
            grown[:old.shape[0]] = old
            out[k] = grown
        else:
            out[k] = state[k]
    extra = sorted(set(state) - set(own))
    if extra:
        raise RanadError(f"--init model has weights this config lacks ({extra[0]}, ...)", init_name)
    return out


def pair_loss(net, pair, rng: np.random.Generator, cfg: TrainConfig, cross: bool):
    """(loss, parts) of one training crop of `pair` (its frame's window for cross-frame models); None for a crop
    without bins."""
    features, device = unwrap(net).config.features, model_device(net)
    if cross:
        frames, ref_img, centre, ctxs = sample_window(pair, rng, cfg.crop, cfg.window, features, cfg.p_misalign)
        frames, ref_img = reduce_window(frames, ref_img, rng, cfg.p_no_aux, cfg.p_no_split,
                                        normal_rotation(rng, cfg.p_rotate_normals))
        window = [prepare(f, c.z_stats, features, c.scale).to(device) for f, c in zip(frames, ctxs)]
        noisy, ref = window[centre], prepare(ref_img).to(device)
        scale = ctxs[centre].scale
    else:
        ctx = frame_context(pair.noisy, features)
        noisy_img, ref_img = reduce_inputs(*sample(pair, rng, cfg.crop, features), rng, cfg.p_no_aux,
                                           cfg.p_no_split, cfg.p_rotate_normals)
        noisy = prepare(noisy_img, ctx.z_stats, features, ctx.scale).to(device)
        ref = prepare(ref_img).to(device)
        if noisy.layout.bins == 0:
            return None
        return total_loss(net(noisy), ref.layers, noisy.layout.offsets, noisy.layout.size, ctx.scale,
                          dict(cfg.loss_weights))
    if noisy.layout.bins == 0:
        return None
    pred = net(window, centre)
    return total_loss(pred, ref.layers, noisy.layout.offsets, noisy.layout.size, scale, dict(cfg.loss_weights))


def consecutive_loss(net, pairs: tuple, rng: np.random.Generator, cfg: TrainConfig):
    """(loss, parts) of one crop of two consecutive frames (find_frame_pairs), each denoised with its own window:
    the mean of their losses plus temporal_weight x the temporal loss; None when a crop has no bins."""
    no_aux, no_split = rng.random() < cfg.p_no_aux, rng.random() < cfg.p_no_split  # the same for both frames
    rot = normal_rotation(rng, cfg.p_rotate_normals)
    inputs = []
    features, device = unwrap(net).config.features, model_device(net)
    for frames, ref_img, centre, ctxs in sample_consecutive(pairs, rng, cfg.crop, cfg.window, features):
        frames, ref_img = reduce_window(frames, ref_img, rng, float(no_aux), float(no_split), rot)
        window = [prepare(f, c.z_stats, features, c.scale).to(device) for f, c in zip(frames, ctxs)]
        if window[centre].layout.bins == 0:
            return None
        inputs.append((window, centre, prepare(ref_img).to(device), ctxs[centre].scale))
    preds, losses, parts = [], [], {}
    for window, centre, ref, scale in inputs:
        preds.append(net(window, centre))
        loss, p = total_loss(preds[-1], ref.layers, window[centre].layout.offsets, window[centre].layout.size,
                             scale, dict(cfg.loss_weights))
        losses.append(loss)
        for k, v in p.items():
            parts[k] = parts.get(k, 0.0) + v / len(inputs)
    t = temporal_loss(preds, [ref.layers for _, _, ref, _ in inputs],
                      [w[c].layout.offsets for w, c, _, _ in inputs])
    parts["temporal"] = t.item()
    return sum(losses) / len(losses) + cfg.temporal_weight * t, parts


def consecutive_pairs(cfg: TrainConfig, cross: bool, world: int) -> list:
    """The consecutive frames the temporal loss trains on (empty without it), or a RanadError saying why not."""
    if cfg.temporal_weight <= 0:
        return []
    if not cross:
        raise RanadError("the temporal loss needs a cross-frame config (e.g. cpu-small-xf)", cfg.config)
    if world > 1:  # two forward passes per step through one DDP module are not supported
        raise RanadError("the temporal loss trains in one process (--processes 1)", cfg.run)
    found = find_frame_pairs(cfg.dataset)
    if not found:
        raise RanadError("no consecutive frames with references for the temporal loss (make the dataset with "
                         "`ranad synth --ref-frames all`)", cfg.dataset)
    return found


MAX_NONFINITE_RUN = 50   # draws in a row with a non-finite loss before training stops with an error


def _all_finite(loss: torch.Tensor, world: int) -> bool:
    """Whether the loss is finite on every rank (all skip the step together, or DDP's gradient averaging in
    backward would wait for a rank that skipped)."""
    ok = torch.isfinite(loss.detach()).all().float().reshape(1).cpu()
    if world > 1:
        torch.distributed.all_reduce(ok, op=torch.distributed.ReduceOp.MIN)
    return bool(ok.item() > 0)


def train(cfg: TrainConfig, progress=None) -> dict:
    """Trains (or resumes) into cfg.run; returns the last step's loss parts. Joins the process group when
    torch.distributed is initialised (see `spawn_local`, or torchrun's environment)."""
    dist = torch.distributed
    if not dist.is_initialized() and int(os.environ.get("WORLD_SIZE", "1")) > 1:
        dist.init_process_group("gloo")
    rank, world = (dist.get_rank(), dist.get_world_size()) if dist.is_initialized() else (0, 1)
    pairs = find_pairs(cfg.dataset)
    config = get_config(cfg.config)
    cross = config.window > 1
    consecutive = consecutive_pairs(cfg, cross, world)
    odds = pair_odds(consecutive or pairs, cfg.spp_weights)
    check_freeze(cfg, config)
    torch.manual_seed(cfg.seed)
    if world > 1 and cfg.device != "cpu":  # gloo averages CPU gradients; GPU data parallelism is not wired up
        raise RanadError("data-parallel training runs on the CPU only (one process on a GPU)", "--device")
    model = build_model(cfg, config).to(cfg.device)
    freeze_spatial(model, cfg)
    try:   # after every check: a refused run leaves no folder
        os.makedirs(cfg.run, exist_ok=True)
    except OSError as e:
        raise RanadError(f"cannot create the run folder ({e.strerror or e})", cfg.run) from None
    probe_writable(cfg.run)   # now, not at the first checkpoint, steps of work later
    opt = torch.optim.AdamW(param_groups(model), lr=cfg.lr, weight_decay=cfg.weight_decay)
    rng = np.random.default_rng(cfg.seed if world == 1 else [cfg.seed, rank])
    step = 0
    ckpt = os.path.join(cfg.run, CHECKPOINT)
    if os.path.isfile(ckpt):
        from ..model.store import load_checkpoint

        state = load_checkpoint(ckpt, ("model", "model_config", "step", "optimizer"))
        if state["model_config"]["name"] != cfg.config:
            raise RanadError(f"checkpoint is for config {state['model_config']['name']!r}, not {cfg.config!r}", ckpt)
        model.load_state_dict(state["model"])
        load_optimizer(opt, state["optimizer"], model)
        step = state["step"]
        if rank == 0:
            rng.bit_generator.state = state["rng"]
        else:  # other ranks' streams are not saved: a fresh stream per (seed, rank, resume step)
            rng = np.random.default_rng([cfg.seed, rank, step])
    net = torch.nn.parallel.DistributedDataParallel(model, find_unused_parameters=True) if world > 1 else model
    log = open(os.path.join(cfg.run, "train.log"), "a") if rank == 0 else None
    parts = {}
    nonfinite = bad_run = 0   # draws skipped for a non-finite loss or gradient: in all, and in a row
    t0 = time.perf_counter()
    last = min(cfg.steps, cfg.until or cfg.steps)
    while step < last:
        for g in opt.param_groups:
            g["lr"] = learning_rate(cfg, step) * g["lr_scale"]
        if consecutive:
            result = consecutive_loss(net, draw(consecutive, odds, rng), rng, cfg)
        else:
            result = pair_loss(net, draw(pairs, odds, rng), rng, cfg, cross)
        if result is None:
            continue
        loss, parts = result
        if not loss.requires_grad:  # frozen spatial part, window without neighbours: nothing here trains
            continue
        opt.zero_grad()
        if not _all_finite(loss, world):   # one bad crop must not turn every weight into NaN
            nonfinite += 1
            bad_run += 1
            if bad_run >= MAX_NONFINITE_RUN:
                raise RanadError(f"the loss was not finite on {bad_run} draws in a row (non-finite values in the "
                                 "dataset's files?)", cfg.run)
            continue
        loss.backward()
        norm = torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip)
        if not torch.isfinite(norm):   # the same on every rank: DDP has averaged the gradients
            nonfinite += 1
            continue
        bad_run = 0
        opt.step()
        step += 1
        if log and (step % cfg.log_every == 0 or step == last):
            secs = (time.perf_counter() - t0) / cfg.log_every
            t0 = time.perf_counter()
            line = (f"step {step} loss {loss.item():.4f} " + " ".join(f"{k} {v:.4f}" for k, v in parts.items())
                    + f" lr {learning_rate(cfg, step - 1):.2e} {secs:.2f} s/step"
                    + (f" ({nonfinite} non-finite draws skipped so far)" if nonfinite else ""))
            print(line, file=log, flush=True)
        if rank == 0 and (step % cfg.checkpoint_every == 0 or step == last):
            save_checkpoint(ckpt, model, opt, step, cfg, rng)
        if progress:
            progress(1)
    if log:
        log.close()
    return parts


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _worker(rank: int, world: int, port: int, cfg: TrainConfig, threads: int, show_progress: bool) -> None:
    torch.set_num_threads(threads)
    torch.distributed.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank,
                                         world_size=world)
    try:
        if rank == 0 and show_progress:
            from tqdm import tqdm

            with tqdm(total=cfg.steps, desc=f"train x{world}", unit="step") as bar:
                train(cfg, bar.update)
        else:
            train(cfg)
    finally:
        torch.distributed.destroy_process_group()


def spawn_local(cfg: TrainConfig, processes: int, show_progress: bool = True) -> None:
    """Data-parallel training in `processes` local processes (gloo), the machine's threads shared among them."""
    import torch.multiprocessing as mp

    threads = max(1, torch.get_num_threads() // processes)
    mp.spawn(_worker, args=(processes, _free_port(), cfg, threads, show_progress), nprocs=processes, join=True)

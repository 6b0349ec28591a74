"""``ranad train``: train a RaNAD model on a `ranad synth` dataset, resuming from RUN/checkpoint.pt."""

from __future__ import annotations

import click
from tqdm import tqdm

from ranad_core.train.weights import WEIGHTS

from .params import FiniteFloat, device_option


def _weighted(text: str, key, option: str, expected: str) -> tuple:
    """'NAME=W' -> (key(NAME), W), or a usage error saying `expected`; `key` raises ValueError (or returns None)
    for a name the option does not take."""
    name, _, value = text.partition("=")
    try:
        pair = key(name), float(value)
    except ValueError:
        pair = None, -1.0
    if pair[0] is None or not pair[1] >= 0:
        raise click.BadParameter(f"{text!r}: expected {expected}", param_hint=option)
    return pair


def _loss_weight(text: str) -> tuple[str, float]:
    """'TERM=W' -> (TERM, W), or a usage error naming the known terms."""
    return _weighted(text, lambda name: name if name in WEIGHTS else None, "--loss-weight",
                     f"TERM=W with W >= 0 and TERM one of {', '.join(WEIGHTS)}")


def _spp_weight(text: str) -> tuple[int, float]:
    """'SPP=W' -> (SPP, W), or a usage error."""
    return _weighted(text, lambda name: int(name) if int(name) >= 1 else None, "--spp-weight",
                     "SPP=W with SPP >= 1 and W >= 0")


@click.command("train")
@click.argument("datasets", nargs=-1, required=True, type=click.Path(file_okay=False))
@click.option("-o", "--run", required=True, type=click.Path(file_okay=False),
              help="Run folder: checkpoint.pt (resumed when present) and train.log.")
@click.option("--config", default="cpu-small", show_default=True, help="Model configuration name.")
@click.option("--steps", default=2000, show_default=True, type=click.IntRange(1), help="Total optimiser steps.")
@click.option("--crop", default=48, show_default=True, type=click.IntRange(8), help="Training crop size (pixels).")
@click.option("--lr", default=1e-3, show_default=True, type=FiniteFloat(0, 1),
              help="Peak learning rate (AdamW).")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the crops and the initialisation.")
@click.option("--checkpoint-every", default=200, show_default=True, type=click.IntRange(1))
@click.option("--processes", default=1, show_default=True, type=click.IntRange(1),
              help="Data-parallel processes on this machine (DDP over gloo; one crop per process per step). For "
                   "several machines, start `torchrun ... -m ranad_cli train ...` instead.")
@click.option("--p-no-aux", default=0.2, show_default=True, type=FiniteFloat(0, 1),
              help="Share of crops shown without albedo/normal, so the model serves files that lack them.")
@click.option("--p-no-split", default=0.2, show_default=True, type=FiniteFloat(0, 1),
              help="Share of crops shown without the diffuse/specular split (beauty only).")
@click.option("--rotate-normals", "p_rotate_normals", default=0.0, show_default=True,
              type=FiniteFloat(0, 1),
              help="Share of crops whose normals are turned by a random rotation: renderers write normals in world "
                   "space (for a camera facing any way) or in camera space, and ranad's scenes all face one way; "
                   "the model should not depend on the space. 0 keeps earlier recipes' random draws.")
@click.option("--window", default=3, show_default=True, type=click.IntRange(2, 7),
              help="Cross-frame configs (e.g. cpu-small-xf): frames per training window around the centre.")
@click.option("--init", default=None,
              help="Weights to start from (model name, .safetensors or run): for a single-frame config, a "
                   "single-frame model of the same size (also of another feature set, e.g. cpu-small-v1 for "
                   "cpu-small-p); for a cross-frame config, a single-frame model's, or for a config with the "
                   "output mix (cpu-small-xfm) a cross-frame model's without it.")
@click.option("--temporal-weight", default=0.0, show_default=True, type=FiniteFloat(0),
              help="Cross-frame configs: weight of a temporal loss on two consecutive frames per step (each denoised "
                   "with its own window): the change of the flattened result from one frame to the next against the "
                   "reference's. Needs references on every frame (`ranad synth --ref-frames all`).")
@click.option("--until", default=None, type=click.IntRange(1),
              help="Stop at this step (checkpointed) although the learning-rate schedule runs to --steps: training "
                   "in chunks, each resumed with the same options and a later --until.")
@click.option("--freeze-spatial", is_flag=True,
              help="Cross-frame configs with --init: train only the temporal parts (T-Mix or the input keys, the "
                   "temporal kernel step and its gate); the single-frame model's weights stay as they are.")
@click.option("--p-misalign", default=0.0, show_default=True, type=FiniteFloat(0, 1),
              help="Cross-frame configs: share of training windows whose neighbour frames are shifted by 2 to "
                   "crop/4 pixels, as if their motion vectors were wrong, so the model learns to use a neighbour "
                   "only where it agrees with the centre frame (refraction, bad vectors, disocclusions).")
@click.option("--loss-weight", "loss_weights", multiple=True, metavar="TERM=W",
              help="Override a loss term's weight (repeatable). Terms and defaults: " + ", ".join(
                  f"{k}={v:g}" for k, v in WEIGHTS.items()) + ". 'separation' compares the composites of the bins in "
                  "front of and behind the crop's median depth, each alone (what a holdout sees); 'separation_ssim' "
                  "adds the SSIM term on those two composites; 'edit' and 'edit_ssim' score the compositing edit "
                  "that `ranad eval` scores (front recoloured, a layer inserted at that depth); 'composite_grad' "
                  "compares the tone-mapped composite's pixel-to-pixel differences (fine detail) with the "
                  "reference's; 'composite_coarse' compares the composite averaged over blocks of 4 and 8 pixels "
                  "(energy a dimmed firefly or caustic loses); 'flip' scores the composite's HDR-FLIP, the perceptual "
                  "difference `ranad eval` reports, and 'edit_flip' the compositing edit's.")
@click.option("--spp-weight", "spp_weights", multiple=True, metavar="SPP=W",
              help="Relative odds of drawing a training crop of that sample count (repeatable; counts not named "
                   "weigh 1), e.g. 64=2 to show clean renders twice as often, where the model over-smooths them.")
@device_option("the model trains", " Crops are made on the CPU either way; data-parallel --processes run on the "
               "CPU.")
def train_cmd(datasets, run, config, steps, crop, lr, seed, checkpoint_every, processes, p_no_aux, p_no_split,
              p_rotate_normals, window, init, temporal_weight, until, freeze_spatial, p_misalign, loss_weights,
              spp_weights, device):
    """Train on DATASETS (one or several outputs of `ranad synth`, their scenes pooled): centre-frame pairs,
    random crops, flips and transposes, SMAPE on the diffuse and specular bins and on the composited colour plus
    SSIM on it, L1 on alpha and depth. Resumes from RUN/checkpoint.pt when it exists."""
    from ranad_core.device import resolve
    from ranad_core.model import get_config
    from ranad_core.train.trainer import TrainConfig, resume_step, spawn_local, train

    try:
        get_config(config)
    except ValueError as e:
        raise click.BadParameter(str(e), param_hint="--config") from None
    weights = tuple(_loss_weight(text) for text in loss_weights)
    odds = tuple(_spp_weight(text) for text in spp_weights)
    if processes > 1 and device == "cuda":
        raise click.BadParameter("data-parallel --processes run on the CPU; train on a GPU with one process",
                                 param_hint="--device")
    run_on = "cpu" if processes > 1 else resolve(device).type
    cfg = TrainConfig(dataset=datasets[0] if len(datasets) == 1 else tuple(datasets), run=run, config=config,
                      steps=steps, crop=crop, lr=lr, seed=seed,
                      checkpoint_every=checkpoint_every, p_no_aux=p_no_aux, p_no_split=p_no_split,
                      p_rotate_normals=p_rotate_normals, window=window, init=init, temporal_weight=temporal_weight,
                      until=until, freeze_spatial=freeze_spatial, p_misalign=p_misalign,
                      loss_weights=weights, spp_weights=odds, device=run_on)
    if processes > 1:
        spawn_local(cfg, processes)
        click.echo(f"done: {steps} steps x {processes} processes, log in {run}/train.log")
        return
    start, last = resume_step(run), min(steps, until or steps)
    if start >= last:
        click.echo(f"{run} is already at step {start} (--steps {steps}" + (f", --until {until}" if until else "")
                   + "): nothing to do")
        return
    with tqdm(total=last, initial=start, desc="train", unit="step") as bar:
        parts = train(cfg, bar.update)
    click.echo("done: " + " ".join(f"{k} {v:.4f}" for k, v in parts.items()))

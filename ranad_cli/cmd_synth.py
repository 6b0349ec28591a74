"""``ranad synth``: render a dataset of noisy deep frames and their references with ranad's Mitsuba path tracer."""

from __future__ import annotations

import os

import click
from tqdm import tqdm

from ranad_core.errors import RanadError
from ranad_core.synth.pixel_filter import FILTERS
from ranad_core.synth.scene import FAMILIES
from ranad_core.synth.trace import SAMPLERS

from .params import FiniteFloat, int_list as _int_list
from .params import width_range


@click.command("synth")
@click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
              help="Dataset folder (created; scenes already complete in it are skipped, so reruns resume; a folder "
                   "whose scenes were made with other options is refused).")
@click.option("--scenes", default=8, show_default=True, type=click.IntRange(1), help="Number of scenes.")
@click.option("--size", default=128, show_default=True, type=click.IntRange(8, 4096), help="Image width and height.")
@click.option("--frames", default=3, show_default=True, type=click.IntRange(1, 7), help="Frames per scene.")
@click.option("--spp", default="4,16,64", show_default=True, help="Noisy sample counts, comma-separated.")
@click.option("--ref-spp", default=1024, show_default=True, type=click.IntRange(1),
              help="Reference samples. Under 16x the largest --spp the reference's own noise is part of every "
                   "score against it (`ranad eval` notes it); scenes with caustics (glass, studio) need more.")
@click.option("--seed", default=0, show_default=True, type=int, help="Dataset seed: same seed, same files.")
@click.option("--preset", "presets", multiple=True, type=click.Choice(list(FAMILIES)),
              help="Scene presets/families, used in turn (default: easy, medium, deep-heavy). The families "
                   "studio, glass, thin, layers, textured, interior, exterior, organic, fog and motion "
                   "randomise materials (glass, metals, checkerboard and procedural textures), lighting (small "
                   "intense lights, bounce light, a sky with a sun, exposure), geometry (fences, wires, layer "
                   "stacks, walls, blob and torus meshes), participating media (fog banks, smoke: volume bins) and "
                   "motion blur.")
@click.option("--kind", "kinds", multiple=True, type=click.Choice(["deepz", "deepoid"]),
              help="Deep kinds to write (default: both).")
@click.option("--workers", default=min(2, os.cpu_count() or 1), show_default=True, type=click.IntRange(1),
              help="Scenes rendered in parallel (processes; the cores are shared out between them).")
@click.option("--ref-frames", type=click.Choice(["centre", "all"]), default="centre", show_default=True,
              help="Frames that get a reference: the centre frame (training) or all (temporal evaluation).")
@click.option("--motion", default=1.0, show_default=True, type=FiniteFloat(0),
              help="Scale of every per-frame movement (camera, objects, spins): 0.5 renders the same shots at twice "
                   "the frame rate, 0 holds them still.")
@click.option("--bin-gap", default=0.03, show_default=True, type=FiniteFloat(0, 1),
              help="Deep-Z binning: a pixel's samples start a new bin where consecutive depths differ by more than "
                   "this share (plus 1 cm at the default). Small values split surfaces into many thin bins, as "
                   "renderers that merge less do (held-out data for `ranad denoise --bin-merge`).")
@click.option("--sampler", type=click.Choice(SAMPLERS), default="independent", show_default=True,
              help="Noisy frames' samples: independent; stratified (pixel and lens positions jittered in n x n "
                   "strata per pixel, n^2 <= spp: far less noisy coverage and defocus); or sobol (every dimension, "
                   "light and BSDF choices too, from scrambled Sobol sequences, as production renderers' "
                   "low-discrepancy samplers draw them: less and more even noise).")
@click.option("--guides", type=click.Choice(["first-hit", "through-specular"]), default="first-hit",
              show_default=True,
              help="Albedo/normal guides: the first surface's own, or (through-specular) those of the first surface "
                   "behind smooth glass and mirrors, as OIDN asks and renderers' denoising AOVs write.")
@click.option("--pixel-filter", type=click.Choice(FILTERS), default="box", show_default=True,
              help="Film filter of noisy frames and references: box (each sample in its own pixel) or gaussian "
                   "(each sample weighted into every pixel within --filter-width, as most renderers' default "
                   "filters do: noise correlated between neighbours, edge pixels with their neighbours' bins).")
@click.option("--filter-width", default="2", show_default=True, callback=lambda _c, _p, v: width_range(v),
              help="The Gaussian's width in pixels (Arnold's and RenderMan's default: 2), or a range A:B that each "
                   "scene draws its width from (training data for files of many renderers).")
@click.option("--enclosure", default=0.0, show_default=True, type=FiniteFloat(0, 1),
              help="Share of scenes put inside a room: a back wall, side walls and (without a sky) a ceiling, turned "
                   "and spaced at random around the scene's own objects, in its family's opaque materials, with its "
                   "lights moved inside and some aimed at the walls (bounce light). Each scene's other draws stay "
                   "as they were; families with walls of their own (interior) are left alone.")
def synth_cmd(out, scenes, size, frames, spp, ref_spp, seed, presets, kinds, workers, ref_frames, motion, bin_gap,
              sampler, guides, pixel_filter, filter_width, enclosure):
    """Render SCENES procedural animated scenes: every frame at each noisy spp, and the centre frame's
    reference binned into each noisy image's bins, as deep-Z and deep-OID EXRs with a manifest per scene.

    Needs Mitsuba 3 (pip install 'ranad[synth]') and Debian's libllvm19. See README, "Synthetic data", for the
    channel convention and the binning rules.
    """
    from ranad_core.synth import dataset
    from ranad_core.synth.mitsuba_env import mitsuba
    from ranad_core.synth.scene import PRESETS

    mitsuba()  # fail early, with the install hint, before any folder is made
    cfg = dataset.SynthConfig(out=out, scenes=scenes, size=size, frames=frames, spp=_int_list(spp), ref_spp=ref_spp,
                              seed=seed, presets=tuple(presets) or PRESETS,
                              kinds=tuple(kinds) or ("deepz", "deepoid"), ref_frames=ref_frames,
                              motion=motion, bin_gap=bin_gap, sampler=sampler, guides=guides,
                              pixel_filter=pixel_filter, filter_width=filter_width, enclosure=enclosure)
    skipped = sum(dataset.is_done(cfg, i) for i in range(scenes))
    try:
        with tqdm(total=scenes - skipped, desc="synth", unit="scene", disable=scenes - skipped <= 1) as bar:
            made = dataset.run(cfg, workers, bar.update)
    except OSError as e:
        raise RanadError(f"cannot write the dataset ({e.strerror or e})", out) from None
    secs = sum(m["seconds"] for m in made)
    click.echo(f"{len(made)} scene(s) written to {out} ({skipped} already complete), {secs:.1f} s of rendering")

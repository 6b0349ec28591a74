"""``ranad denoise``: denoise deep EXR frames and shots with a RaNAD model."""

from __future__ import annotations

import contextlib
import gc
import os
import re
import sys

import click
from tqdm import tqdm

from .params import FiniteFloat, device_option
from ranad_core.binmerge import MERGE_GAP
from ranad_core.darkness import DARK_RADIUS
from ranad_core.lightmatch import CLAMP as LIGHT_CLAMP, RADIUS as LIGHT_RADIUS
from ranad_core.errors import RanadError


UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_bytes(text: str) -> float:
    """'8G' -> 8 * 2**30; K, M, G, T with an optional 'B'/'iB'; a bare number is bytes."""
    m = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([KMGT]?)(?:i?B)?\s*", text or "", re.I)
    if not m:
        raise click.BadParameter(f"expected a size like 8G or 512M, got {text!r}", param_hint="--max-memory")
    return float(m.group(1)) * UNITS[m.group(2).upper()]


@click.command("denoise")
@click.argument("inputs", nargs=-1, required=True)
@click.option("-o", "--output", required=True,
              help="Output file, pattern (denoised/beauty.####.exr) or folder ending in '/'; missing folders are "
                   "created. Inputs are never overwritten.")
@click.option("--frames", help="Frame range for patterns, e.g. 1001-1010 (default: all on disk).")
@click.option("--model", default=None, help="Shipped model name, .safetensors file or training run folder "
                                            "(default: the shipped cross-frame model for sequences, the "
                                            "single-frame one otherwise).")
@device_option("the model and the flat prior's OIDN run",
               " Reading, input preparation and writing stay on the CPU.")
@click.option("--threads", type=click.IntRange(1, 1024), default=None, help="CPU threads (default: all cores).")
@click.option("--kind", type=click.Choice(["auto", "deepz", "deepoid"]), default="auto", show_default=True,
              help="What every frame must be: deepz, or deepoid (an id channel gives every bin of a pixel its own "
                   "id); a frame of the other kind is an error naming it. The model handles both kinds alike; "
                   "auto accepts either and reports the first frame's.")
@click.option("--map", "maps", multiple=True, metavar="LAYER=CHANNELS",
              help="Channel mapping override, e.g. --map diffuse=diff_direct, --map albedo=aR,aG,aB, "
                   "--map diffuse=diffuse_direct+diffuse_indirect (a sum), --map motion_prev=mv.X,mv.Y (per-bin "
                   "motion to the previous frame; motion_next to the next).")
@click.option("--preset", default=None, type=click.Choice(["renderman", "arnold", "karma", "vray", "redshift"]),
              help="Try this renderer's documented deep AOV names and motion conventions first (README, "
                   "'Renderers'); --map overrides it.")
@click.option("--motion-units", type=click.Choice(["pixels", "ndc", "velocity"]), default=None,
              help="Units of the motion channels: pixels (per frame, or per --shutter frames), ndc (fraction of the "
                   "display window), velocity (pixels per second, needs --fps). Default: pixels, or the preset's.")
@click.option("--fps", type=float, default=None, help="Frames per second, for --motion-units velocity.")
@click.option("--shutter", type=float, default=None,
              help="The motion channels span this many frames (e.g. 0.5 for a 180-degree shutter); default 1.")
@click.option("--motion-y", type=click.Choice(["up", "down"]), default=None,
              help="Direction of the motion channels' y axis (default down, as pixel rows; up for screen space).")
@click.option("--keep-noisy", metavar="PREFIX", default=None,
              help="Also write the noisy versions of the replaced channels under PREFIX (e.g. 'noisy.').")
@click.option("--keep-depth", is_flag=True,
              help="Write the input's depths (Z, ZBack) unchanged instead of denoised ones. The default model's "
                   "per-bin depth error is 0.66-0.89x the noisy input's on its held-out and in-family sets; "
                   "models without the layer gate (cpu-small-pdl-v1 and older) were up to 3x worse than the "
                   "noisy input on layered scenes (model cards).")
@click.option("--bin-merge", "bin_merge", type=FiniteFloat(0, 0.5), default=MERGE_GAP, show_default=True,
              help="Thin bins of one surface (consecutive point bins of a pixel within this relative depth gap, "
                   "same object ids) are denoised as one bin and shared back, as the model's training bins hold "
                   "whole surfaces: renderers that merge less than 3% get the quality of ones that do. Output "
                   "keeps every input bin; 0 turns it off.")
@click.option("--dark-radius", "dark_radius", type=click.IntRange(0, 8), default=DARK_RADIUS, show_default=True,
              help="Every pixel of an exactly black window of (2R+1)x(2R+1) pixels stays exactly black (beauty and "
                   "AOVs; alpha and depth are denoised): a black neighbourhood means no light, and the kernels "
                   "would spread a faint glow of lit neighbours into it. A black pixel among lit ones is still "
                   "filled in, and so are windows near isolated lit pixels (a dim region few samples reach). "
                   "Objects (id channel) with no lit bin, such as holdout mattes, stay black too. 0 turns it "
                   "off.")
@click.option("--light-match/--no-light-match", "light_match", default=True, show_default=True,
              help=f"Models on the flat prior: each pixel's denoised colour times a gain within "
                   f"{100 * (LIGHT_CLAMP - 1):.0f}% of 1 that brings the local light (a {2 * LIGHT_RADIUS + 1}x"
                   f"{2 * LIGHT_RADIUS + 1}-pixel mean of luminance) to the noisy render's own, undoing the slight "
                   "dimming of smooth regions that averaging kernels leave; the same gain goes to the AOVs (light "
                   "groups still sum to the beauty).")
@click.option("--tile", type=click.IntRange(16), default=None,
              help="Tile size in pixels (default: the tiling that fits --max-memory with the fewest bins "
                   "computed twice in the halos; on the CPU, windows of at most 0.8 M bins).")
@click.option("--halo", type=click.IntRange(0), default=None,
              help="Tile halo in pixels (default: the model's receptive field, so tiles match the whole frame).")
@click.option("--max-memory", default="8G", show_default=True, help="Ceiling on the process's peak memory: the tiles get what the "
              "frames, their working copies and the kernels' buffers leave; a ceiling too small for one 16-pixel "
              "tile is an error that says how much is needed.")
@click.option("--cache", "cache_dir", type=click.Path(file_okay=False), default=None,
              help="Folder for the embedding cache `ranad aov` reuses (one .ranadcache file per frame).")
@click.option("--skip-existing", is_flag=True, help="Skip frames whose output exists (resume a shot).")
@click.option("--shard", default=None, metavar="I/N", help="Only farm task I of N (frames I, I+N, ...).")
@click.option("--strict", is_flag=True,
              help="Fail on NaN/Inf input samples instead of replacing them, and on any negative depth (a frame "
                   "with more than 0.1% of its bins at negative depth is refused anyway: another z convention).")
@click.option("--window", type=click.IntRange(1, 7), default=None,
              help="Frames per window for cross-frame models, odd: the centre and as many on each side (default: "
                   "the window the model was trained with; 1 denoises every frame alone).")
@click.option("--aovs", default=None, metavar="PATTERN",
              help="Also denoise the AOV layers matching PATTERN (e.g. 'lg_*') in the same files, reusing the "
                   "beauty's kernels (see `ranad aov`).")
@click.option("--reference", default=None, metavar="PATTERN",
              help="Reference frames (same layout) to report how much closer to them the output got.")
@click.option("--part", "parts", multiple=True, metavar="NAME|INDEX",
              help="Denoise this deep part of multi-part (e.g. stereo) files; repeatable. Default: every deep part "
                   "with R, G, B, A, Z. The other parts are copied to the output byte for byte.")
@click.option("--flow", default=None, metavar="PATTERN",
              help="Flat EXRs (one per frame, e.g. flow.####.exr) with per-pixel motion, used where the deep frames "
                   "have no per-bin motion; needs --flow-direction. Units and axes as --motion-units/--motion-y/"
                   "--shutter/--fps say (default pixels per frame, y down).")
@click.option("--flow-direction", type=click.Choice(["prev", "next"]), default=None,
              help="What the --flow files hold: each pixel's motion to the previous or to the next frame.")
@click.option("--flow-channels", default=None, metavar="X,Y",
              help="The two channels of the --flow files (default: the files' only x/y pair, e.g. X,Y or R,G).")
@click.option("--profile", "profile", is_flag=True,
              help="After the run, print where the time went: seconds per stage (read, motion, inputs with the "
                   "flat prior, per-tile gather / backbone / reconstruction / scatter, assemble, AOVs, cache, "
                   "write) with the CPU seconds of each and the threads it kept busy (near 1: a serial stage), "
                   "and a per-tile summary (bins with the halo, halo overlap, seconds per tile).")
def denoise_cmd(inputs, output, frames, model, device, threads, kind, maps, preset, motion_units, fps, shutter,
                motion_y, keep_noisy, keep_depth, bin_merge, dark_radius, light_match, tile, halo, max_memory,
                cache_dir,
                skip_existing, shard, strict, window, aovs, reference, parts, flow, flow_direction, flow_channels,
                profile):
    """Denoise deep EXR INPUTS (files or patterns such as beauty.####.exr) into deep EXRs with the same pixels,
    bins, bin order, channels, ids and header: diffuse, specular, alpha and depth are denoised and the beauty
    is rebuilt from them.

    Channels are found automatically (R, G, B, A, Z required; diffuse/specular, emission, albedo and N layers
    used when present; `ranad info` shows the mapping). Without a diffuse/specular split or without albedo and
    normals the model runs in a reduced mode. Frames are processed in tiles with a halo, written atomically,
    and optionally cached for `ranad aov`.
    """
    import torch

    from ranad_core.channels import mapping_options
    from ranad_core.exr.sequence import expand_inputs, is_pattern, output_paths, shard as take_shard
    from ranad_core.fileutil import check_writable_target
    from ranad_core.model.store import load_model, training_window
    from ranad_core.shot import ShotOptions, prescan

    from ranad_core.device import resolve

    budget = parse_bytes(max_memory)
    if window is not None and window % 2 == 0:   # a window is the centre and as many frames on each side
        raise click.BadParameter(f"{window} is even; give an odd window (1, 3, 5, 7)", param_hint="--window")
    run_on = resolve(device)
    if threads:
        torch.set_num_threads(threads)
    overrides = mapping_options(maps, preset, motion_units, fps, shutter, motion_y)
    sequence = expand_inputs(list(inputs), frames)
    frames_list = take_shard(sequence, shard) if shard else sequence
    if not frames_list:
        click.echo(f"nothing to do: shard {shard} has no frames (the shot has {len(sequence)})")
        return
    if is_pattern(output) or not output.endswith((os.sep, "/")):
        _make_folder(os.path.dirname(os.path.abspath(output)), output)
    else:
        _make_folder(output, output)
    outs = dict(zip(sequence, output_paths(output, sequence)))   # the whole shot's: no shard may collide either
    jobs = [(f, outs[f]) for f in frames_list]
    for _, out in jobs:
        check_writable_target(out)
    if cache_dir:
        try:
            os.makedirs(cache_dir, exist_ok=True)
        except OSError as e:
            raise RanadError(f"cannot create the cache folder ({e.strerror or e})", cache_dir) from None
    opts = ShotOptions(model_spec=model, overrides=overrides, tile=tile, halo=halo, max_memory=budget,
                       keep_noisy=keep_noisy, keep_depth=keep_depth, bin_merge=bin_merge, dark_radius=dark_radius,
                       light_match=light_match,
                       cache_dir=cache_dir,
                       skip_existing=skip_existing, strict=strict,
                       aovs=aovs, kind=kind, parts=tuple(parts), flow=flow, flow_direction=flow_direction,
                       flow_channels=None if flow_channels is None else
                       tuple(c.strip() for c in flow_channels.split(",") if c.strip()))
    prescan(frames_list, opts)
    if model is None:  # the cross-frame model whenever frames have neighbours
        from ranad_core.model.store import default_model_for

        model = default_model_for([f.frame for f in sequence], window)
    loaded = load_model(model)
    loaded.model.to(run_on)
    # torch, numpy and the model are some 170,000 objects that live to the end; left to the cycle
    # collector, its full passes walked them all during the tiles (2% of a frame's samples, perf). Frozen, the
    # passes see only what the frames themselves allocate (thawed at the end, for a caller in the same process).
    gc.freeze()
    click.get_current_context().call_on_close(gc.unfreeze)
    opts.model_spec, opts.window = model, window or training_window(loaded)
    from ranad_core.profile import profiling

    # the profile starts before the first frame's read (the shot reuses that image, shot.Preread)
    with profiling() if profile else contextlib.nullcontext() as prof:
        _denoise_frames(frames_list, jobs, sequence, loaded, opts, kind, flow, flow_direction, run_on, reference,
                        prof)


def _denoise_frames(frames_list, jobs, sequence, loaded, opts, kind, flow, flow_direction, run_on, reference, prof):
    """The shot's report line, the frames through denoise_shot with progress bars, and the closing lines."""
    import torch

    from ranad_core.exr import read_deep
    from ranad_core.exr.sequence import format_frame
    from ranad_core.shot import denoise_shot, first_frame

    mapping, found, labels, preread = first_frame(frames_list[0].path, opts)[1:]   # the image: only in preread
    click.echo(f"model {loaded.model_id}; {'deep-OID' if found == 'deepoid' else 'deep-Z'} input"
               f"{'' if kind == 'auto' else ' (--kind ' + kind + ', checked on every frame)'}; "
               + (f"parts: {', '.join(labels)} (the others copied); " if labels else "")
               + f"channels: {mapping.mode()}; motion: {mapping.motion.describe()}"
               + (f"; per-pixel flow: {flow} (to the {flow_direction} frame)" if flow else "")
               + f"; device: {run_on.type}", err=True)
    scores = []

    def on_frame(job, img, result):
        if not reference:
            return
        frame, _ = job
        ref_path = format_frame(reference, frame.frame) if frame.frame is not None else reference
        if os.path.isfile(ref_path):
            from ranad_core.metrics import reference_improvement

            scores.append((frame.path, *reference_improvement(img, result.image, read_deep(ref_path))))

    # the tiles' bar sits under the frames' and moves the cursor up to get there: in a log file (stderr not a
    # terminal) those escape codes would end up in front of the next line, an error's included
    with tqdm(total=len(jobs), desc="frames", unit="frame", disable=len(jobs) <= 1, position=0) as fbar, \
            tqdm(desc="tiles", unit="tile", leave=False, position=1, disable=not _is_terminal(sys.stderr)) as tbar:
        warned = []

        def warn(msg):
            warned.append(msg)
            tqdm.write(f"ranad: warning: {msg}", file=sys.stderr)

        summary = denoise_shot(jobs, loaded, opts, fbar.update, _TileBar(tbar), on_frame, sequence, warn, preread)
    for msg in summary.messages:
        if msg not in warned:
            click.echo(f"ranad: warning: {msg}", err=True)
    click.echo(f"denoised {summary.frames} frame(s), {summary.bins} bins, in {summary.seconds:.1f} s"
               + (f"; skipped {summary.skipped} existing" if summary.skipped else "")
               + (f"; {summary.nonfinite} bin(s) with NaN/Inf replaced" if summary.nonfinite else "")
               + (f"; {summary.dropped} neighbour bin(s) carried out of the frame by motion (not used)"
                  if summary.dropped else "")
               + ("; WITHOUT motion compensation (no motion channels)" if summary.no_motion else ""))
    if prof is not None:
        click.echo(f"\nprofile ({torch.get_num_threads()} thread(s)):\n{prof.table()}")
    for path, before, after in scores:
        click.echo(f"{os.path.basename(path)}: flattened SMAPE vs reference {before:.4f} -> {after:.4f} "
                   f"({before / max(after, 1e-12):.1f}x closer)")


def _is_terminal(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):   # a replaced or closed stream
        return False


def _make_folder(folder: str, what: str) -> None:
    """Output folders are created (a farm task's output tree may not exist yet)."""
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise RanadError(f"cannot create the output folder ({e.strerror or e})", what) from None


class _TileBar:
    """A tqdm bar reused for every frame's tiles."""

    def __init__(self, bar):
        self.bar = bar

    def reset(self, total):
        self.bar.reset(total=total)

    def __call__(self, n):
        self.bar.update(n)

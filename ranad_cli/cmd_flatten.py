"""``ranad flatten``: deep EXRs to flat EXR/PNG/JPEG images for review."""

from __future__ import annotations

import os

import click

from ranad_core.exr.sequence import expand_inputs, output_paths
from ranad_core.fileutil import check_writable_target

from .params import FiniteFloat
from .progress import progress


@click.command("flatten")
@click.argument("inputs", nargs=-1, required=True)
@click.option("-o", "--output", required=True,
              help="Output file, pattern (review/beauty.####.png) or existing folder. The extension picks the "
                   "format: .exr (flat, all channels), .png or .jpg (8-bit sRGB preview).")
@click.option("--frames", help="Frame range for patterns, e.g. 1001-1010 or 1001-1100x2 (default: all on disk).")
@click.option("--part", help="Part index or name in multi-part files (default: the first deep part).")
@click.option("--exposure", type=FiniteFloat(-64, 64), default=0.0, show_default=True,
              help="Exposure in stops (PNG/JPG only).")
@click.option("--float", "as_float", is_flag=True, help="Write 32-bit float EXR channels (default: half, Z float).")
@click.option("--assume-tidy", is_flag=True,
              help="Skip sorting/splitting the bins (faster; wrong on overlapping volume samples).")
@click.option("--overwrite/--no-overwrite", default=True, show_default=True,
              help="Replace existing outputs (inputs are never overwritten).")
def flatten_cmd(inputs, output, frames, part, exposure, as_float, assume_tidy, overwrite) -> None:
    """Composite deep INPUTS front to back (OpenEXR's tidy + over) into flat images.

    INPUTS are files or patterns (name.####.exr, name.%04d.exr, name.@@@@.exr).
    """
    frames_list = expand_inputs(list(inputs), frames)
    jobs = list(zip(frames_list, output_paths(output, frames_list)))
    for _, out in jobs:
        check_writable_target(out)
    from ranad_core.channels import DEPTHS
    from ranad_core.deep import flatten, replace_nonfinite
    from ranad_core.errors import RanadError
    from ranad_core.exr import read_deep
    from ranad_core.exr.flat import write_flat

    for f, out in progress(jobs, total=len(jobs), desc="flatten"):
        if not overwrite and os.path.exists(out):
            continue
        image, nonfinite = replace_nonfinite(read_deep(f.path, part=part))   # NaN/Inf as denoise treats them
        if nonfinite:   # a -inf depth gave NaN pixels in the tidy step's volume split
            click.echo(f"ranad: warning: {f.path}: {nonfinite} bin(s) with NaN/Inf replaced (a depth by the "
                       f"channel's largest finite value, anything else by 0)", err=True)
        try:
            pixels = flatten(image, tidy=not assume_tidy)
        except RanadError as e:  # a problem of this file's contents (no Z): name the file
            raise RanadError(e.problem, e.path or f.path) from None
        types = ["float" if as_float or c in DEPTHS else "half" for c in image.channels]
        write_flat(out, pixels, list(image.channels), data_window=image.data_window,
                   display_window=image.display_window, dtype=types, exposure=exposure)
    if len(jobs) > 1:
        click.echo(f"flattened {len(jobs)} frames", err=True)

"""``ranad aov``: denoise light-group AOVs with the kernels cached by ``ranad denoise --cache``."""

from __future__ import annotations

import glob
import json
import os

import click
from tqdm import tqdm

from .params import device_option
from ranad_core.errors import RanadError


@click.command("aov")
@click.argument("cache", type=click.Path(exists=True))
@click.option("--layers", "pattern", required=True, metavar="PATTERN",
              help="Glob of the AOV layers to denoise, e.g. 'lg_*' (layers with .R/.G/.B channels).")
@click.option("-o", "--output", required=True,
              help="Output file, pattern (denoised/aov.####.exr) or folder ending in '/' (created).")
@click.option("--input", "aov_input", default=None, metavar="FILE_OR_PATTERN",
              help="Files holding the AOVs, with the beauty's bin layout (default: the denoised beauty inputs "
                   "recorded in the cache, where light groups usually live).")
@device_option("the reconstruction runs")
def aov_cmd(cache, pattern, output, aov_input, device):
    """Denoise the AOV layers matching PATTERN for every frame cached in CACHE (a folder of .ranadcache files or
    one file), rerunning only the reconstruction with the cached embeddings: all AOV channels share each RaNA
    call, and light groups that sum to the noisy beauty sum to the denoised beauty.

    Diffuse-like layers (*diffuse*, *diff*) use the diffuse kernels, specular-like ones (*specular*, *spec*)
    the specular kernels; any other layer is split in the proportions of the beauty's diffuse, specular and
    emission components per bin (see ranad_core/aov.py). Outputs keep the AOV file's layout, channels and header.
    """
    from ranad_core import cache as cache_io
    from ranad_core.aov import denoise_cached_frame, partial_layers
    from ranad_core.device import resolve
    from ranad_core.exr import read_header, resolve_part, write_deep, write_parts
    from ranad_core.exr.sequence import Frame, format_frame, is_pattern, output_paths
    from ranad_core.fileutil import check_writable_target
    from ranad_core.model.store import load_model

    run_on = resolve(device)
    files = sorted(glob.glob(os.path.join(cache, "*" + cache_io.SUFFIX))) if os.path.isdir(cache) else [cache]
    if not files:
        raise RanadError(f"no {cache_io.SUFFIX} files (made by ranad denoise --cache)", cache)
    entries = []
    for path in files:
        tensors, meta = cache_io.read_cache(path)
        entries.append((path, tensors, meta))
    frames = [int(m["frame"]) if m["frame"] else None for _, _, m in entries]
    folder = output if output.endswith((os.sep, "/")) and not is_pattern(output) else os.path.dirname(
        os.path.abspath(output))
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise RanadError(f"cannot create the output folder ({e.strerror or e})", output) from None

    def source_of(meta, frame, beauty_path):
        if not aov_input:
            return beauty_path
        if is_pattern(aov_input):
            if frame is None:
                raise RanadError("has no frame number to fill the --input pattern", beauty_path)
            return format_frame(aov_input, frame)
        return aov_input

    # one output per AOV file: the caches of a multi-part file's parts (one each) go into the same output, written
    # once with every part; two different AOV files meeting in one output is an error (output_paths)
    sources = [source_of(meta, frame, meta["input"]) for (_, _, meta), frame in zip(entries, frames)]
    for src in sources:
        if not os.path.isfile(src):
            raise RanadError("AOV file not found", src)
    outputs = {}   # output -> (AOV file, output, [(cache, tensors, meta, frame)])
    outs = output_paths(output, [Frame(src, frame) for src, frame in zip(sources, frames)])
    for (path, tensors, meta), frame, src, out in zip(entries, frames, sources, outs):
        check_writable_target(out)
        outputs.setdefault(os.path.normcase(os.path.abspath(out)), (src, out, []))[2].append((path, tensors, meta,
                                                                                              frame))
    models = {}
    with tqdm(total=len(entries), desc="aov", unit="frame", disable=len(entries) <= 1) as bar:
        for src, out, parts in outputs.values():
            replaced, layout = {}, read_header(src)
            for path, tensors, meta, frame in parts:
                spec = meta["model"] or None
                if spec not in models:
                    models[spec] = load_model(spec)
                    models[spec].model.to(run_on)
                aov_files = [source_of(meta, None if frame is None else frame - int(meta["centre"]) + k, p)
                             for k, p in enumerate(json.loads(meta["window"]))]
                image = denoise_cached_frame(models[spec], path, tensors, meta, pattern, aov_files)
                partial = partial_layers(image.channels, pattern)
                if partial:
                    click.echo(f"ranad: warning: {src}: AOV layer(s) {', '.join(partial)} match {pattern!r} but lack "
                               f".R, .G or .B: left noisy", err=True)
                index = resolve_part(layout, meta.get("part") or None, src) if layout.multipart else 0
                if index in replaced:
                    raise RanadError(f"two caches hold part {index} of this file", path)
                replaced[index] = image
                bar.update(1)
            if not layout.multipart:
                write_deep(out, replaced[0])
            else:   # every denoised part, the file's other parts copied as they are
                write_parts(out, src, replaced)
    click.echo(f"denoised {len(entries)} frame(s) of AOVs matching {pattern!r}")

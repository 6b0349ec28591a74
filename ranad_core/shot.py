"""Denoising a shot: frames in, denoised frames (and caches) out, each written atomically.

The loop behind `ranad denoise`: reads a frame, checks it against the first (resolution and data window must
match across a sequence), denoises it in tiles sized to the memory budget, writes the output (and the AOV
cache) through a temporary file, and collects a summary. Frames whose output exists are skipped when asked,
so an interrupted farm task resumes where it stopped.

With a cross-frame model each frame is denoised with a window of its neighbours (consecutive frame numbers of the
same sequence, up to `window` frames, shorter at the ends of the sequence). The shot is streamed: frames are
read once and kept only while a window needs them.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

import numpy as np

from . import cache as cache_io
from . import heap
from .channels import REQUIRED, detect, motion_candidates
from .denoise import (ALIGN, CPU_TILE_BINS, choose_tile, denoise_window, halo_for, is_cross_frame, model_features,
                      tile_bytes, tiling_work)
from .deep import all_finite, nonfinite_bins
from .errors import RanadError
from .profile import stage
from .exr import check_copyable_parts, read_deep, read_header, resolve_part, write_parts


@dataclass
class ShotOptions:
    model_spec: str | None = None
    overrides: dict = field(default_factory=dict)    # channels.parse_overrides output
    tile: int | None = None                          # None: chosen from max_memory
    halo: int | None = None                          # None: the model's receptive field
    max_memory: float = 8e9                          # bytes, the peak to stay under
    keep_noisy: str | None = None
    keep_depth: bool = False                         # write the input's depths, not denoised ones
    bin_merge: float | None = None                   # binmerge gap (None: its default; 0: off)
    dark_radius: int | None = None                   # darkness radius (None: its default; 0: off)
    light_match: bool = True                         # lightmatch: local light within 2% of the noisy render's
    cache_dir: str | None = None
    skip_existing: bool = False
    strict: bool = False                             # non-finite samples, negative depths: error instead of fix
    window: int = 1                                  # frames per window (cross-frame models only)
    aovs: str | None = None                          # glob of AOV layers denoised with the same kernels
    kind: str = "auto"                               # deepz / deepoid: every frame must be of that kind
    parts: tuple = ()                                # --part: names or indices; () = every deep part with colour
    flow: str | None = None                          # --flow: flat EXR per frame (pattern) with per-pixel motion
    flow_direction: str | None = None                # prev | next
    flow_channels: tuple | None = None               # its x, y channels (default: the file's only pair)


@dataclass
class ShotSummary:
    frames: int = 0
    skipped: int = 0
    bins: int = 0
    nonfinite: int = 0
    dropped: int = 0                                 # neighbour bins motion carried out of the frame
    seconds: float = 0.0
    messages: list = field(default_factory=list)
    no_motion: bool = False                          # a cross-frame window ran without any motion data


def part_label(layout, index: int) -> str:
    """How messages name a part: 'part 1 'rgba.right'' (or 'part 1')."""
    name = layout.parts[index].name
    return f"part {index} {name!r}" if name else f"part {index}"


def part_key(layout, index: int):
    """The part's name where it has one (how the same part is found in the other frames), else its index."""
    return layout.parts[index].name or index


def select_parts(layout, path: str, wanted=(), overrides: dict | None = None) -> list[int]:
    """The deep parts of a file to denoise: `wanted` (--part names or indices, each a deep part whose channels
    `ranad denoise` can read), or by default every deep part with colour (R, G, B, A, Z). Every other part is
    passed through. RanadError naming the file and part when a wanted part is flat or unreadable, or when no
    part qualifies."""
    from .channels import detect_names

    def check(i: int) -> None:
        names = [c.name for c in layout.parts[i].channels if c.type != "uint"]
        try:
            detect_names(names, overrides, path)
        except RanadError as e:
            raise RanadError(f"{part_label(layout, i)}: {e.problem}" if layout.multipart else e.problem,
                             path) from None

    out = []
    for w in wanted or ():
        i = resolve_part(layout, w, path)
        if not layout.part_is_deep(i):
            raise RanadError(f"--part {w}: {part_label(layout, i)} is not deep (flat EXR part)", path)
        check(i)
        if i not in out:
            out.append(i)
    if out:
        return out
    deep = [i for i in range(len(layout.parts)) if layout.part_is_deep(i)]
    if not deep:
        raise RanadError("not a deep image (flat EXR); ranad needs deep EXRs", path)
    out = [i for i in deep if {c.name for c in layout.parts[i].channels} >= set(REQUIRED)]
    if not out:
        check(deep[0])          # raises: the missing required channels
    return out


def flow_file(opts: "ShotOptions", frame) -> str:
    """The --flow file of a frame: the pattern filled with its number (a plain name for a plain input)."""
    from .exr.sequence import format_frame, is_pattern

    if not is_pattern(opts.flow):
        return opts.flow
    if frame.frame is None:
        raise RanadError(f"has no frame number to fill the --flow pattern {opts.flow!r}", frame.path)
    return format_frame(opts.flow, frame.frame)


def check_flow_options(opts: "ShotOptions") -> None:
    """--flow needs --flow-direction; --flow-direction and --flow-channels need --flow; --cache does not record
    the flow (ranad aov would compensate without it), so the two are refused together."""
    from .flow import DIRECTIONS

    if opts.flow is None:
        if opts.flow_direction or opts.flow_channels:
            raise RanadError("--flow-direction/--flow-channels only apply with --flow PATTERN", None)
        return
    if opts.flow_direction not in DIRECTIONS:
        raise RanadError("--flow needs --flow-direction prev|next (which frame the flow points to)", None)
    if opts.flow_channels is not None and len(opts.flow_channels) != 2:
        raise RanadError(f"--flow-channels {','.join(opts.flow_channels)}: give two channels, x then y", None)
    if opts.cache_dir:
        raise RanadError("--cache does not record --flow yet (ranad aov would compensate without it); use --aovs "
                         "in the same run", None)


def prescan(frames, opts: "ShotOptions | None" = None) -> None:
    """Check every input's header before any work: the parts to denoise exist and are readable deep parts, the
    same in every frame, each with one display window for the whole sequence (data windows may differ from
    frame to frame: each frame is denoised and written at its own)."""
    opts = opts or ShotOptions()
    check_flow_options(opts)
    first = None
    for frame in frames:
        if opts.flow and not os.path.isfile(flow_file(opts, frame)):
            raise RanadError("no such file (the --flow of " + os.path.basename(frame.path) + ")",
                             flow_file(opts, frame))
        layout = read_header(frame.path)
        chosen = select_parts(layout, frame.path, opts.parts, opts.overrides)
        found = {part_key(layout, i): layout.parts[i].display_window for i in chosen}
        if first is None:
            first = (frame.path, found)
            continue
        if list(found) != list(first[1]):
            raise RanadError(f"denoises parts {list(found)}, the first frame {first[0]} parts {list(first[1])} "
                             "(frames of a sequence must have the same parts)", frame.path)
        for key, disp in found.items():
            if disp != first[1][key]:
                where = f" of part {key!r}" if len(found) > 1 else ""
                raise RanadError(f"display window {disp}{where} differs from {first[1][key]} of {first[0]} "
                                 "(frames of a sequence must share a display window)", frame.path)


@dataclass
class Preread:
    """Frames read before the shot (first_frame's): denoise_shot's frame store starts with them instead of reading
    them again (a whole read, 0.8 s of a 1080p frame), and the shot's seconds count the time their read took."""
    images: dict            # (path, part key or None) -> DeepImage; the frame store takes the dict over
    seconds: float = 0.0


def first_frame(path: str, opts: "ShotOptions"):
    """What a shot's report starts with, from its first frame: (the first part to denoise, its ChannelMap, its
    kind 'deepz'/'deepoid' (checked against opts.kind), the labels of the parts denoised, or [] for a
    single-part file, and the Preread that hands the image on to denoise_shot). The read is a "read" stage of an
    active profile."""
    layout = read_header(path)
    chosen = select_parts(layout, path, opts.parts, opts.overrides)
    part = part_key(layout, chosen[0]) if layout.multipart else None
    t0 = time.perf_counter()
    with stage("read"):
        img = read_deep(path, part=part)
    seconds = time.perf_counter() - t0
    mapping = detect(img, opts.overrides, path)
    found = check_kind(img, opts.kind, path)
    labels = [part_label(layout, i) for i in chosen] if layout.multipart else []
    return img, mapping, found, labels, Preread({(path, part): img}, seconds)


def choose_frame_tile(images, centre, halo: int, max_memory: float, where: str,
                      device_free: float = float("inf"), prior: bool = False, max_bins: int | None = None,
                      prior_frames: list | None = None) -> int:
    """The tile (choose_tile) that keeps this frame's denoising under the ceiling `max_memory` (memory.py) and, for
    a model on a GPU, inside `device_free` bytes of GPU memory (memory.device_free_bytes); a RanadError when even
    the smallest tile does not fit, or (`prior`: a model on the flat prior) when making the frame's prior would
    not (`prior_frames`: the frames whose prior is still to be made, None: `images`). The heap's kept memory is
    given back only when sizing the tiles with it counted as in use costs more than memory.GIVE_BACK_WORTH times
    the work (or fits nothing)."""
    from . import memory

    img = images[centre]

    def plan(resident: float) -> tuple:
        need = memory.prior_need(max_memory, images if prior_frames is None else prior_frames, centre,
                                 resident) if prior else 0.0
        budget, other = memory.tile_budget(max_memory, images, centre, resident)
        tile = choose_tile(img.offsets, img.width, img.height, halo, min(budget, device_free), len(images), max_bins)
        return tile, budget, other, need

    def work(tile: int) -> int:
        return tiling_work(img.offsets, img.width, img.height, tile, halo)

    resident, kept = memory.resident_bytes(give_back=False), heap.kept_bytes()
    # the sizing the give-back would allow (its estimate) first, the one without it last, so that the tile used is
    # the last one chosen
    hoped = plan(resident - kept)[0] if kept else None
    tile, budget, other, prior_need = plan(resident)
    if kept is None or tile == ALIGN or prior_need > max_memory or (
            kept and work(tile) > memory.GIVE_BACK_WORTH * work(hoped)):
        tile, budget, other, prior_need = plan(memory.resident_bytes())
    if tile == ALIGN or prior_need > max_memory:
        need = tile_bytes(img.offsets, img.width, img.height, ALIGN, halo, len(images))
        if need > budget or prior_need > max_memory:
            raise memory.too_small(max_memory, other, need, ALIGN, halo, where, prior_need)
        if need > device_free:
            raise memory.too_small_on_device(device_free, need, ALIGN, halo, where)
    return tile


def with_denoised_aovs(model, images, centre, mapping, result, pattern: str, source: str, flows=None):
    """result.image with the AOV layers matching `pattern` replaced by their kernel-reuse denoising."""
    from .aov import aov_layers, denoise_aovs

    img = images[centre]
    layers = aov_layers(img.channels, pattern)
    if not layers:
        raise RanadError(f"no AOV layers match {pattern!r} (layers with .R/.G/.B channels)", source)
    out = denoise_aovs(model, images, centre, mapping, layers, result.embeddings, result.perms, result.offsets,
                       flows, result.merge_gap if result.merges else 0.0, result.merges, result.split,
                       result.dark_radius, result.gain)
    vals = result.image.values.copy()
    for layer, chans in layers.items():
        for i, c in enumerate(chans):
            vals[:, result.image.channels.index(c)] = out[layer][:, i]
    return result.image.with_values(vals)


def window_of(frame, sequence: list, window: int) -> tuple[list, int]:
    """(the frames of `frame`'s window in `sequence`, the index of `frame` in it): consecutive frame numbers of
    the frame's own shot (Frame.sequence) only, at most (window-1)/2 on each side."""
    if window <= 1 or frame.frame is None:
        return [frame], 0
    by_number = {f.frame: f for f in sequence if f.frame is not None and f.sequence == frame.sequence}
    half = (window - 1) // 2
    before = []
    for k in range(1, half + 1):
        f = by_number.get(frame.frame - k)
        if f is None:
            break
        before.insert(0, f)
    after = []
    for k in range(1, half + 1):
        f = by_number.get(frame.frame + k)
        if f is None:
            break
        after.append(f)
    return before + [frame] + after, len(before)


class FrameStore:
    """Frames (one deep part each) read once and kept while a window may still need them (the shot is processed
    in order), with each frame's flat prior once a cross-frame window has made it (denoise.FramePrior)."""

    def __init__(self, keep: int, preread: dict | None = None):
        # preread ({(path, part): image}, frames read before the shot) is taken over, not copied: evicting a frame
        # drops the caller's reference too, so a long shot does not keep its first frame to the end
        self.keep, self.images, self.priors = max(1, keep), preread if preread is not None else {}, {}

    def get(self, frame, part=None):
        key = (frame.path, part)
        img = self.images.pop(key, None)
        if img is None:
            img = read_deep(frame.path, part=part)
        self.images[key] = img
        while len(self.images) > self.keep:
            self._evict()
        return img

    def _evict(self) -> None:
        key = next(iter(self.images))
        self.images.pop(key)
        self.priors.pop(key, None)

    def priors_of(self, frames, part=None) -> list:
        """Per frame, its FramePrior if one was kept, else None (the list denoise_window fills in)."""
        return [self.priors.get((f.path, part)) for f in frames]

    def keep_priors(self, frames, part, priors: list) -> None:
        for f, p in zip(frames, priors):
            if p is not None and (f.path, part) in self.images:
                self.priors[(f.path, part)] = p


KINDS = ("auto", "deepz", "deepoid")


def output_compression(img) -> str:
    """The compression an output gets: the input's where OpenEXR allows it for deep data (none, rle, zips),
    else zips (exr.fast.layout_of; write_deep keeps it, with the tiles and line order, by default)."""
    from .exr.fast import layout_of

    return layout_of(img.header).compression


def count_nonfinite(img) -> int:
    """Bins with a NaN/Inf value in any channel (what deep.replace_nonfinite replaces)."""
    from .deep import nonfinite_bins

    return nonfinite_bins(img.values)


NEGATIVE_DEPTH_SHARE = 0.001   # more bins than this behind the camera: a depth convention, not a stray sample


def check_depths(img, depth: str, source: str, strict: bool = False) -> int:
    """The bins with a negative depth (0 when none). Deep EXR depths are distances in front of the camera; a frame
    with more than NEGATIVE_DEPTH_SHARE of its bins behind it (or any, with --strict) was written in another
    convention (camera-space z pointing backwards), which would reverse the bins' order: refused."""
    z = np.asarray(img.channel(depth))
    negative = int(np.count_nonzero(z < 0))
    if negative and (strict or negative > NEGATIVE_DEPTH_SHARE * z.size):
        raise RanadError(f"{negative} of {z.size} bins have a negative depth {depth!r}; deep EXR depths are distances "
                         "in front of the camera (was it written as camera-space z?)", source)
    return negative


def check_kind(img, kind: str, source: str) -> str:
    """The frame's kind ('deepz' or 'deepoid', inspect.guess_kind's rule); with `kind` other than auto a frame
    of the other kind is a RanadError naming it (`--kind` states what the shot must be, and is checked)."""
    from .exr.inspect import guess_kind, object_id_channel

    if kind not in KINDS:
        raise RanadError(f"--kind {kind!r}: use one of {', '.join(KINDS)}", None)
    found = "deepoid" if guess_kind(img) == "deep-OID" else "deepz"
    if kind == "deepoid" and found != kind:
        why = ("it has no id channel" if object_id_channel(img) is None
               else f"its id channel {object_id_channel(img)!r} repeats within pixels")
        raise RanadError(f"--kind deepoid: not a deep-OID frame ({why})", source)
    if kind == "deepz" and found != kind:
        raise RanadError(f"--kind deepz: this is a deep-OID frame (id {object_id_channel(img)!r} separates every "
                         "pixel's bins); use --kind deepoid or auto", source)
    return found


def no_motion_message(img, model_name: str = "the cross-frame model") -> str:
    """The warning for a cross-frame window without any motion data (once per shot)."""
    hint = motion_candidates(img.channels)
    return (f"{model_name} runs WITHOUT motion compensation: no per-bin motion channels are mapped, so moving "
            "objects are blurred across frames. "
            + (f"Channels that may hold motion: {', '.join(hint)}. " if hint else "")
            + "Map them with --map motion_prev=X,Y (and/or motion_next=X,Y, with --motion-units/--motion-y), "
              "use --preset RENDERER, or --window 1 to denoise frames alone.")


def denoise_shot(jobs, loaded, opts: ShotOptions, frame_bar=None, tile_bar=None, on_frame=None,
                 sequence: list | None = None, warn=None, preread: Preread | None = None) -> ShotSummary:
    """jobs: [(Frame, output path)]; loaded: model.store.LoadedModel; `sequence`: every frame of the shot (the
    neighbours of a shard's frames; default: the jobs' frames). `frame_bar`/`tile_bar`: callables (n) for
    progress; `tile_bar.reset(total)` is called per part of each frame when present. `on_frame(job, image,
    result)` is called after each frame is written (with its first denoised part); `warn(message)` as soon as a
    warning arises (it is kept in the summary too). `preread`: frames already read (first_frame's Preread), which
    the frame store starts with instead of reading them again.

    Every deep part `select_parts` picks (--part, or each deep part with colour) is denoised with the same part
    of the neighbouring frames (found by name, else by index); the output holds every part of the input, the
    others copied byte for byte (exr.write_parts). Each frame keeps its own data window."""
    summary = ShotSummary(seconds=preread.seconds if preread else 0.0)
    heap.set_ceiling(opts.max_memory)   # kept freed memory goes back before it nears the ceiling (heap.relieve)
    model = loaded.model
    halo = halo_for(model) if opts.halo is None else opts.halo
    if opts.tile is None:
        from .memory import cap_kernel_cache

        cap_kernel_cache(opts.max_memory)
    window = opts.window if is_cross_frame(model) else 1
    sequence = sequence or [f for f, _ in jobs]
    store = None
    first_display = {}
    for frame, out in jobs:
        t0 = time.perf_counter()
        if opts.skip_existing and _already_done(frame, out, opts):
            summary.skipped += 1
            if frame_bar:
                frame_bar(1)
            continue
        members, centre = window_of(frame, sequence, window)
        layout = read_header(frame.path)
        chosen = select_parts(layout, frame.path, opts.parts, opts.overrides)
        check_copyable_parts(frame.path, layout, chosen)   # the parts copied as they are: fail now, not at the write
        if store is None:   # a window's frames and no more: the next window reads one new frame, sliding on
            store = FrameStore(window * len(chosen), preread.images if preread else None)
        replaced, reported = {}, False
        for index in chosen:
            key = part_key(layout, index)
            part = None if not layout.multipart else key
            where = frame.path if not layout.multipart else f"{frame.path} ({part_label(layout, index)})"
            tiles = layout.parts[index].tiles
            if tiles and tiles[2] != 0:   # OpenEXR's MIPMAP_LEVELS / RIPMAP_LEVELS
                msg = (f"{where}: a {'mip' if tiles[2] == 1 else 'rip'}mapped deep part: its full-resolution level "
                       f"is denoised and written as scan lines, without the other levels")
                if msg not in summary.messages:
                    summary.messages.append(msg)
            with stage("read"):
                try:
                    images = [store.get(f, part) for f in members]
                except RanadError as e:   # name the part whose chunks are bad (the file has others)
                    if not layout.multipart or e.problem.startswith("part "):
                        raise
                    raise RanadError(f"{part_label(layout, index)}: {e.problem}", e.path) from None
            img = images[centre]
            disp = first_display.setdefault(key, (frame.path, img.display_window))
            needed = detect(img, opts.overrides, where).value_channels()
            for f, other in zip(members, images):
                missing = [c for c in needed if c not in other.channels]
                if missing:   # the centre's channel map is every frame's: a neighbour lacking a channel of it
                    raise RanadError(f"lacks channel(s) {', '.join(missing[:6])}{', ...' if len(missing) > 6 else ''}"
                                     f" that {os.path.basename(frame.path)} has (the frames of a window are read "
                                     f"with one channel map)", f.path)
                if other.display_window != disp[1]:
                    raise RanadError(f"display window {other.display_window} differs from {disp[1]} of {disp[0]} "
                                     "(frames of a sequence must share a display window)", f.path)
            flows = None
            if opts.flow and len(images) > 1:
                from .flow import read_flow

                flows = [read_flow(flow_file(opts, f), im, opts.flow_direction, opts.flow_channels, opts.overrides)
                         for f, im in zip(members, images)]
            priors = store.priors_of(members, part)
            result, bad = _denoise_part(model, images, centre, flows, where, opts, summary, halo, tile_bar, warn,
                                        priors)
            store.keep_priors(members, part, priors)
            replaced[index] = result.image
            if opts.cache_dir:
                cache = cache_io.cache_path(opts.cache_dir, out, None if len(chosen) == 1 else str(key))
                with stage("cache"):
                    cache_io.write_cache(cache, img, result, loaded.model_id, opts.model_spec or "", frame.path,
                                         frame.frame, result.tile, halo,
                                         [m.path for m in members] if is_cross_frame(model) else None,
                                         opts.overrides, part=str(key) if layout.multipart else None)
            summary.bins += result.bins
            summary.nonfinite += max(result.nonfinite, bad)
            summary.dropped += result.dropped
            if on_frame and not reported:
                pending = (img, result)
                reported = True
        with stage("write"):
            write_parts(out, frame.path, replaced)
        summary.frames += 1
        summary.seconds += time.perf_counter() - t0
        if on_frame:
            on_frame((frame, out), *pending)
        # this frame's arrays (its images, results and output, a frame's size each) go before the next frame is
        # read and prepared, which --max-memory's accounting counts without them
        images = img = result = replaced = pending = flows = priors = None
        if frame_bar:
            frame_bar(1)
    return summary


def _already_done(frame, out: str, opts: ShotOptions) -> bool:
    """--skip-existing: the output is there and not empty (outputs are renamed into place whole, so an empty one
    is somebody else's), and with --cache so is every cache the frame writes (a job killed between the two, or
    run without --cache before, would otherwise leave `ranad aov` nothing to read for it)."""
    if not os.path.isfile(out) or os.path.getsize(out) == 0:
        return False
    if not opts.cache_dir:
        return True
    try:
        layout = read_header(frame.path)
        chosen = select_parts(layout, frame.path, opts.parts, opts.overrides)
    except RanadError:
        return False   # the run says what is wrong with it
    return all(os.path.isfile(cache_io.cache_path(opts.cache_dir, out, None if len(chosen) == 1 else
                                                  str(part_key(layout, i)))) for i in chosen)


def _denoise_part(model, images, centre, flows, where, opts, summary, halo, tile_bar, warn, priors=None):
    """One deep part of a frame, with the same part of its neighbours: checks, then denoise_window (`priors`: its
    list of the frames' flat priors, filled in there); returns (FrameResult with .tile set, NaN/Inf bins found in
    any channel)."""
    img = images[centre]
    mapping = detect(img, opts.overrides, where)
    if len(images) > 1 and not mapping.motion.found:
        # a centre frame without motion channels of its own: its neighbours' (frame t-1's motion to t+1 and t+1's
        # to t-1 carry them to it, one direction is enough) are read with the map they give
        for k, other in enumerate(images):
            try:
                found = k != centre and detect(other, opts.overrides, where).motion
            except RanadError:
                continue
            if found and found.found:
                mapping.motion = found
                break
    if opts.kind != "auto":                     # guess_kind sorts every bin: only when it is checked
        check_kind(img, opts.kind, where)
    bad = count_nonfinite(img)                  # every channel, not only those the model reads
    if bad and opts.strict:
        raise RanadError(f"{bad} bin(s) with NaN/Inf values", where)
    negative = check_depths(img, mapping.depth, where, opts.strict)
    if negative:
        summary.messages.append(f"{where}: {negative} bin(s) with a negative depth (read as 0)")
    if len(images) > 1 and not summary.no_motion:
        from .motion import has_any_motion

        if not has_any_motion(images, mapping.motion, flows):
            summary.no_motion = True
            msg = no_motion_message(img)
            summary.messages.append(msg)
            if warn:
                warn(msg)
    if opts.tile:
        tile = opts.tile
    else:
        from .memory import device_free_bytes

        device = next(model.parameters()).device
        # a cross-frame window makes only the flat priors not carried from an earlier window (denoise_window)
        pending = [im for im, p in zip(images, priors)
                   if p is None] if priors is not None and len(images) > 1 and is_cross_frame(model) else images
        tile = choose_frame_tile(images, centre, halo, opts.max_memory, where, device_free_bytes(device),
                                 model_features(model) == "prior" and bool(pending),
                                 CPU_TILE_BINS if device.type == "cpu" else None, pending)
    ntiles = sum(1 for _ in range(0, img.height, tile)) * sum(1 for _ in range(0, img.width, tile))
    if tile_bar is not None and hasattr(tile_bar, "reset"):
        tile_bar.reset(ntiles)
    result = denoise_window(model, images, centre, mapping, tile, halo, opts.keep_noisy,
                            opts.cache_dir is not None or bool(opts.aovs), tile_bar, flows, priors, opts.keep_depth,
                            opts.bin_merge, opts.dark_radius, opts.light_match)
    result.tile = tile
    if opts.aovs:
        with stage("aovs"):
            result.image = with_denoised_aovs(model, images, centre, mapping, result, opts.aovs, where, flows)
        from .aov import partial_layers

        partial = partial_layers(img.channels, opts.aovs)
        if partial:
            summary.messages.append(f"{where}: AOV layer(s) {', '.join(partial)} match {opts.aovs!r} but lack .R, .G "
                                    f"or .B: left noisy")
    if not all_finite(result.image.values):   # the inputs were made finite: NaN/Inf here is the model's own
        n = nonfinite_bins(result.image.values)
        raise RanadError(f"the model's output has NaN/Inf in {n} bin(s) (broken or overflowing weights?); "
                         "nothing written", where)
    nonfinite = max(result.nonfinite, bad)
    if nonfinite:
        if opts.strict:
            raise RanadError(f"{nonfinite} bin(s) with NaN/Inf values", where)
        summary.messages.append(f"{where}: {nonfinite} bin(s) with NaN/Inf values (replaced in every channel: depth "
                                "with the frame's largest finite depth, any other value with 0)")
    return result, bad

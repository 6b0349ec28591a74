"""What is in an EXR file, as plain data: the facts ``ranad info`` prints (and ``--json`` emits).

Kept apart from the CLI so that pipelines can call :func:`describe` directly, and so that the deep-Z vs
deep-OID guess lives in one place (``ranad denoise`` uses the same rule to pick its mode).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..deep import DeepImage
from . import read_layout, read_part
from .header import COMPRESSION_NAMES, DEEP_IMAGE_STATES

#: id channel names preferred as "the" object id, in order; otherwise the first uint channel
OBJECT_ID_NAMES = ("id", "Id", "ID", "objectid", "object_id", "objectId")


def object_id_channel(image: DeepImage) -> str | None:
    """The channel holding object ids: a uint channel (by OBJECT_ID_NAMES first), else a half or float channel of
    one of those names (some tools store ids as floats; bins of different objects must still keep apart)."""
    for name in OBJECT_ID_NAMES:
        if name in image.ids:
            return name
    first = next(iter(image.ids), None)
    if first is not None:
        return first
    return next((name for name in OBJECT_ID_NAMES if name in image.channels), None)


def object_ids(image: DeepImage) -> np.ndarray | None:
    """[N] the object ids of the bins (object_id_channel's values), None without an id channel."""
    name = object_id_channel(image)
    if name is None:
        return None
    return image.ids[name] if name in image.ids else image.channel(name)


def id_columns(image: DeepImage) -> dict:
    """name -> [N] of every channel that labels bins by object: the uint channels and a float object id channel
    (what keeps bins of different objects from merging)."""
    name = object_id_channel(image)
    if name is None or name in image.ids:
        return dict(image.ids)
    return {**image.ids, name: image.channel(name)}


def guess_kind(image: DeepImage) -> str:
    """``"deep-OID"`` when an id channel gives every bin of a pixel a different id, else ``"deep-Z"``.

    deep-OID files hold one bin per object per pixel (the paper's Sec. 2); a deep-Z file with ids has
    pixels where one object owns several depth bins. Images without ids are deep-Z.
    """
    ids = object_ids(image)
    if ids is None or image.num_bins == 0:
        return "deep-Z"
    pix = image.pixel_index()
    order = np.lexsort((ids, pix))
    p, i = pix[order], ids[order]
    repeated = np.any((p[1:] == p[:-1]) & (i[1:] == i[:-1]))
    return "deep-Z" if repeated else "deep-OID"


def thin_bins(image: DeepImage, mapping) -> int:
    """Bins that `ranad denoise` merges into the bin in front of them at the default gap (binmerge): thin bins of
    one surface, as renderers that merge a pixel's samples less than ranad's training data write. Found as
    denoise finds them: on the canonical channels of `mapping`, after the NaN/Inf policy."""
    from ..binmerge import groups_of
    from ..channels import ALPHA, DEPTH, DEPTH_BACK, DEPTHS
    from ..deep import pixel_chunks, replace_nonfinite

    if image.num_bins < 2:
        return 0
    # the merge reads alpha, depths and ids only, which the canonical image copies as they are; it is found a chunk
    # of whole pixels at a time (its float64 work arrays over a whole 16.7 M-bin frame took 2 GB)
    direct = [(ALPHA, mapping.alpha), (DEPTH, mapping.depth)] + ([(DEPTH_BACK, mapping.depth_back)]
                                                                 if mapping.depth_back else [])
    small = DeepImage(values=image.columns([src for _, src in direct]), offsets=image.offsets,
                      channels=[name for name, _ in direct], data_window=image.data_window)
    small = replace_nonfinite(small, DEPTHS)[0]   # over the whole frame: its largest depth fills non-finite ones
    thin, labels = 0, id_columns(image)
    for b0, b1, offs in pixel_chunks(small.offsets):
        part = DeepImage(values=small.values[b0:b1], offsets=offs, channels=small.channels,
                         ids={k: v[b0:b1] for k, v in labels.items()}, data_window=(0, 0, offs.size - 2, 0))
        srt, perm = part.sorted()
        groups = groups_of(srt, part, perm)
        thin += 0 if groups is None else part.num_bins - groups.merged
    return thin


def dark_pixels(image: DeepImage, mapping) -> int:
    """Pixels holding bins `ranad denoise` keeps exactly black at the default radius (darkness: exactly black
    windows, holdout objects), found on the frame as denoise's output step reads it (the NaN/Inf policy
    applied)."""
    from ..darkness import dark_bins
    from ..deep import replace_nonfinite

    dark = dark_bins(replace_nonfinite(image, mapping.depth_channels())[0], mapping)
    return 0 if dark is None else int(np.unique(image.pixel_index()[dark]).size)


def _deep_stats(image: DeepImage, mapping=None) -> dict[str, Any]:
    """`mapping`: the channels `ranad denoise` would read (None: it could not; no thin-bin or kept-black counts)."""
    counts = image.counts
    covered = counts > 0
    z = image.channel("Z") if "Z" in image.channels else None
    volume = bool(z is not None and "ZBack" in image.channels and np.any(image.channel("ZBack") > z))
    nonfinite = int(np.count_nonzero(~np.isfinite(image.values)))
    return {
        "bins": int(image.num_bins),
        "bins_per_pixel": {"min": int(counts.min()), "mean": float(counts.mean()), "max": int(counts.max()),
                           "mean_covered": float(counts[covered].mean()) if covered.any() else 0.0},
        "empty_pixels": float(1.0 - covered.mean()),
        "volume_samples": volume,
        "kind_guess": guess_kind(image),
        "id_channels": [c if c in image.ids else f"{c} (stored as {image.channel_types.get(c, 'float')})"
                        for c in id_columns(image)],
        "nonfinite_values": nonfinite,
        "measured_state": image.measured_state(),
        "thin_bins": 0 if mapping is None else thin_bins(image, mapping),
        "dark_pixels": 0 if mapping is None else dark_pixels(image, mapping),
    }


def describe(path: str | os.PathLike, stats: bool = True, overrides: dict | None = None) -> dict[str, Any]:
    """A JSON-ready description of every part of an EXR file (deep statistics for deep parts). `overrides`:
    a channels.mapping_options dict (--map, --preset), applied to what `ranad denoise` would read."""
    path = os.fspath(path)
    layout, src = read_layout(path)  # the headers only; chunks are read below when stats are asked for
    with src:
        return _describe(path, layout, src, stats, overrides)


def _describe(path: str, layout, src, stats: bool, overrides: dict | None) -> dict[str, Any]:
    out: dict[str, Any] = {"file": path, "file_size": src.size, "multipart": layout.multipart, "parts": []}
    for i, part in enumerate(layout.parts):
        dw, disp = part.data_window, part.display_window
        deep = layout.part_is_deep(i)
        tiled = layout.part_is_tiled(i)
        info: dict[str, Any] = {
            "index": i,
            "name": part.name,
            "type": part.type or (("deeptile" if tiled else "deepscanline") if deep
                                  else ("tiledimage" if tiled else "scanlineimage")),
            "deep": deep,
            "resolution": [dw[2] - dw[0] + 1, dw[3] - dw[1] + 1],
            "data_window": list(dw),
            "display_window": list(disp),
            "compression": COMPRESSION_NAMES.get(part.compression, str(part.compression)),
            "channels": {c.name: c.type for c in sorted(part.channels, key=lambda c: c.name.encode())},
            "deepImageState": (DEEP_IMAGE_STATES.get(part.get("deepImageState"))
                               if "deepImageState" in part.attrs else None),
            "id_manifest": any(k in part.attrs for k in ("idManifest", "EXRIdNames", "objectID")),
            "attributes": sorted(part.attrs),
        }
        if tiled and part.tiles:
            info["tiles"] = list(part.tiles[:2])
            info["levels"] = ("one", "mipmap", "ripmap")[part.tiles[2]] if part.tiles[2] < 3 else str(part.tiles[2])
        if deep:
            from ..channels import detect_names, motion_candidates
            from ..errors import RanadError

            names = [c.name for c in part.channels if c.type != "uint"]
            mapping = None
            try:
                mapping = detect_names(names, overrides)
                info["denoise_channels"] = mapping.describe()
                if not mapping.motion.found:
                    info["denoise_channels"]["motion_candidates"] = motion_candidates(names)
            except RanadError as e:
                info["denoise_channels"] = {"mode": f"cannot denoise: {e.problem}"}
        if deep and stats:
            info.update(_deep_stats(read_part(path, layout, src, i), mapping))
        out["parts"].append(info)
    return out


__all__ = ["describe", "guess_kind", "id_columns", "object_id_channel", "object_ids"]

"""The embedding cache `ranad denoise --cache DIR` writes and `ranad aov` reads (kernel reuse, paper Sec. 6.5.3).

One file per frame, `DIR/<output name>.ranadcache` (safetensors), holding what the reconstruction modules need
to rerun on other values:

- tensors, for every frame k of the window the frame was denoised with (k = 0 only for single-frame models):
  `embeddings.k` float16 [N_k, dim] (the backbone's per-bin output, bins sorted front to back, neighbours
  motion-compensated onto the centre frame; for input-keyed cross-frame models the temporal keys, and for the
  centre [N, 2 dim]: its backbone output, then its keys), `perm.k` int64 [N_k] (sorted row i is row perm[i] of the
  compensated frame; for the centre frame, of the file), `offsets.k` int64 [H*W+1], `z_stats` float64 [K, 2]
  (the depth standardisation used per frame); where thin bins were merged (binmerge), `merge.k` int64 [N_k] (each
  sorted bin's merged bin; embeddings and offsets are then the merged bins') and `split` float32 [N] (the
  centre's share-back factors); where the primary pass matched the light (lightmatch), `gain` float32 [H*W]
  (each pixel's gain of the denoised colour; absent in older caches: none);
- metadata (strings): `format` ("ranad-cache/1"), `model_id` (name@sha256 prefix of the weights), `model`
  (what --model resolved to), `input` (absolute path of the denoised file), `window` (JSON list of the
  window's input paths), `centre` (index of the denoised frame in it), `frame`, `layout_sha` (fingerprint
  of the centre's bin layout and depths: SHA-256 of offsets and Z), `mapping` (JSON of the channel map),
  `overrides` (JSON of the --map overrides, so `ranad aov` maps the channels the same way), `tile`, `halo`,
  `part` (the part of a multi-part file, by name or index; empty for single-part files), `merge_gap` (the
  binmerge gap, "0" when nothing merged), `dark_radius` (darkness' radius; absent in older caches: 0),
  `tensors_crc32` (CRC-32 of every tensor's name, type, shape and bytes; absent in older caches).

A cache is refused when its format, model id or layout fingerprint does not match what it is used with, or when
its tensors do not match their checksum (a disk or copy error: safetensors itself checks only the sizes).
"""

from __future__ import annotations

import hashlib
import json
import os
import zlib

import numpy as np

from .deep import DeepImage
from .errors import RanadError
from .fileutil import atomic_output
from .channels import DEPTH

FORMAT = "ranad-cache/1"
SUFFIX = ".ranadcache"


def layout_fingerprint(img: DeepImage) -> str:
    """SHA-256 (first 16 hex digits) of the bin layout (offsets) and depths (Z): equal for the beauty file and
    AOV files of the same frame, different for any other frame or render."""
    h = hashlib.sha256(np.ascontiguousarray(img.offsets, np.int64).tobytes())
    if DEPTH in img.channels:
        h.update(np.ascontiguousarray(img.channel(DEPTH), np.float32).tobytes())
    return h.hexdigest()[:16]


def tensors_checksum(tensors: dict) -> str:
    """CRC-32 (8 hex digits) of the tensors' names, types, shapes and bytes, in name order."""
    crc = 0
    for name in sorted(tensors):
        t = np.ascontiguousarray(tensors[name])
        crc = zlib.crc32(f"{name}:{t.dtype.str}:{t.shape}".encode(), crc)
        crc = zlib.crc32(memoryview(t).cast("B"), crc)
    return f"{crc:08x}"


def cache_path(folder: str, output: str, part: str | None = None) -> str:
    """`folder/<output name>.ranadcache`, or `<output name>.<part>.ranadcache` for one of several denoised parts
    of a multi-part file."""
    name = os.path.basename(output)
    if name.lower().endswith(".exr"):
        name = name[:-4]
    if part is not None:
        name += "." + "".join(c if c.isalnum() or c in "._-" else "_" for c in part)
    return os.path.join(folder, name + SUFFIX)


def write_cache(path: str, img: DeepImage, result, model_id: str, model_spec: str, input_path: str,
                frame: int | None, tile: int, halo: int, window_paths: list | None = None,
                overrides: dict | None = None, part: str | None = None) -> None:
    from safetensors.numpy import save_file

    tensors = {"z_stats": np.asarray(result.z_stats, np.float64).reshape(-1, 2)}
    for k, (emb, perm, offs) in enumerate(zip(result.embeddings, result.perms, result.offsets)):
        tensors[f"embeddings.{k}"] = np.ascontiguousarray(emb, np.float16)
        tensors[f"perm.{k}"] = np.ascontiguousarray(perm, np.int64)
        tensors[f"offsets.{k}"] = np.ascontiguousarray(offs, np.int64)
    for k, index in enumerate(result.merges or []):
        if index is not None:
            tensors[f"merge.{k}"] = np.ascontiguousarray(index, np.int64)
    if result.merges:
        tensors["split"] = np.ascontiguousarray(result.split, np.float32)
    if result.gain is not None:
        tensors["gain"] = np.ascontiguousarray(result.gain, np.float32)
    window = [os.path.abspath(p) for p in (window_paths or [input_path])]
    meta = {"format": FORMAT, "model_id": model_id, "model": model_spec, "input": os.path.abspath(input_path),
            "window": json.dumps(window), "centre": str(result.centre),
            "frame": "" if frame is None else str(frame), "layout_sha": layout_fingerprint(img),
            "mapping": json.dumps(result.mapping.describe()), "overrides": json.dumps(overrides or {}),
            "tile": str(tile), "halo": str(halo), "part": part or "",
            "merge_gap": repr(float(result.merge_gap)) if result.merges else "0",
            "dark_radius": str(int(result.dark_radius)), "tensors_crc32": tensors_checksum(tensors)}
    with atomic_output(path) as tmp:
        save_file(tensors, tmp, metadata=meta)


def read_cache(path: str) -> tuple[dict, dict]:
    """(tensors as numpy arrays, metadata); RanadError for files that are not ranad caches."""
    from safetensors import safe_open

    try:
        with safe_open(path, framework="np") as f:
            meta = dict(f.metadata() or {})
            tensors = {k: f.get_tensor(k) for k in f.keys()}
    except Exception as e:
        raise RanadError(f"not a ranad cache ({type(e).__name__})", path) from None
    if meta.get("format") != FORMAT:
        raise RanadError(f"cache format {meta.get('format')!r} is not {FORMAT!r}; rerun ranad denoise --cache", path)
    if "tensors_crc32" in meta and tensors_checksum(tensors) != meta["tensors_crc32"]:
        raise RanadError("corrupt cache (its tensors do not match their checksum); rerun ranad denoise --cache", path)
    return tensors, meta


def check_cache(meta: dict, path: str, model_id: str | None = None, img: DeepImage | None = None) -> None:
    """Refuse a stale cache: other weights, or another frame / bin layout than `img`."""
    if model_id is not None and meta.get("model_id") != model_id:
        raise RanadError(f"cache was made with model {meta.get('model_id')}, not {model_id}", path)
    if img is not None and meta.get("layout_sha") != layout_fingerprint(img):
        raise RanadError("cache does not match this file's bin layout or depths (another frame or render?)", path)

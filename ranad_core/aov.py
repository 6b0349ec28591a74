"""Light-group AOVs denoised with the cached kernels (paper Sec. 6.5.3).

RaNAD's reconstruction applies attention weights to noisy values, so the weights of the primary pass denoise any
number of AOVs: the cached backbone embeddings are fed to the reconstruction modules again, with all AOV channels
batched into the value dimension of each RaNA call (the kernels are computed once per scale for all of them).

Which kernels an AOV gets (the rule):

- layers named like a diffuse layer (`*diffuse*`, `*diff*`) use the diffuse kernels, like a specular layer
  (`*specular*`, `*spec*`) the specular kernels;
- every other layer (light groups holding both) is split per bin and channel in the proportions of the noisy
  beauty's own components: the share diffuse/beauty (plus the residual the split leaves out) goes through the
  diffuse kernels, specular/beauty through the specular kernels, emission/beauty passes through. Since those
  shares sum to one in every bin, light groups that sum to the noisy beauty give denoised light groups that sum
  to the denoised beauty (the primary pass rebuilds the beauty from exactly these operators).

With a cross-frame model the AOVs of every frame of the window are motion-compensated like the beauty was and
go through the same temporal step.
"""

from __future__ import annotations

import fnmatch

import numpy as np
import torch

from . import darkness, lightmatch
from .channels import ALIASES, DEPTH, DEPTHS, EMISSION, RGB, SPECULAR, ChannelMap, canonical
from .deep import DeepImage, replace_nonfinite, unsort
from .errors import RanadError
from .model.inputs import ModelInputs, modulation
from .model.layers import Layout

MAX_VALUE_CHANNELS = 63          # the RaNA kernels' widest value head is 64 channels


def _rgb_parts(channels, pattern: str) -> dict:
    """layer name -> {R/G/B: channel name} of the layers matching the glob `pattern` (.r/.g/.b too: Karma's LPE
    layers)."""
    found = {}
    for c in channels:
        if "." not in c:
            continue
        layer, comp = c.rsplit(".", 1)
        if fnmatch.fnmatchcase(layer, pattern) and comp.upper() in RGB:
            found.setdefault(layer, {})[comp.upper()] = c
    return found


def aov_layers(channels, pattern: str) -> dict:
    """layer name -> its (R, G, B) channel names, for the layers matching the glob `pattern`."""
    return {k: tuple(v[x] for x in RGB) for k, v in sorted(_rgb_parts(channels, pattern).items()) if len(v) == 3}


def partial_layers(channels, pattern: str) -> list:
    """Layers matching `pattern` that have some but not all of .R/.G/.B: aov_layers leaves them out (they stay
    noisy, and light groups no longer sum to the denoised beauty), which the commands say."""
    return sorted(k for k, v in _rgb_parts(channels, pattern).items() if k and len(v) < 3)


def kernel_rule(layer: str) -> str:
    low = layer.lower()
    if any(a.lower() in low for a in ALIASES["diffuse"]):
        return "diffuse"
    if any(a.lower() in low for a in ALIASES["specular"]):
        return "specular"
    return "colour"


def _values(img: DeepImage, m: ChannelMap, layers: dict, perm: np.ndarray) -> dict:
    """Per reconstruction ('diffuse', 'specular', 'pass') the [N, 3 * len(layers)] values of one (compensated)
    frame in sorted order; 'pass' holds the emission share that is not denoised. Non-finite values follow the
    one NaN/Inf policy (deep.replace_nonfinite) before anything is computed."""
    img = replace_nonfinite(img, m.depth_channels())[0]
    canon, residual = canonical(img, m)
    n = img.num_bins
    beauty = img.columns(m.beauty).astype(np.float64)

    def get(names):
        return canon.columns(names).astype(np.float64) if names[0] in canon.channels else np.zeros((n, 3))

    spec = get(SPECULAR) if m.split else np.zeros((n, 3))
    emit = get(EMISSION)
    safe = np.where(np.abs(beauty) > 1e-12, beauty, 1.0)
    r_s = np.where(np.abs(beauty) > 1e-12, spec / safe, 0.0)
    r_e = np.where(np.abs(beauty) > 1e-12, emit / safe, 0.0)
    r_d = 1.0 - r_s - r_e
    out = {"diffuse": [], "specular": [], "pass": []}
    for layer, chans in layers.items():
        v = img.columns(chans).astype(np.float64)
        rule = kernel_rule(layer)
        if rule == "diffuse" or (rule == "specular" and not m.split):
            parts = (v, 0 * v, 0 * v)
        elif rule == "specular":
            parts = (0 * v, v, 0 * v)
        else:
            parts = (v * r_d, v * r_s, v * r_e)
        for key, p in zip(("diffuse", "specular", "pass"), parts):
            out[key].append(p)
    return {k: torch.from_numpy(np.concatenate(v, 1)[perm].astype(np.float32)) for k, v in out.items()}


def denoise_aovs(model, images: list, centre: int, mapping: ChannelMap, layers: dict, embeddings: list,
                 perms: list, offsets: list, flows: list | None = None, merge_gap: float = 0.0,
                 merges: list | None = None, split: np.ndarray | None = None, dark_radius: int = 0,
                 gain: np.ndarray | None = None) -> dict:
    """Denoised AOV layers of frame `centre`: layer -> [N, 3] in the file's bin order.

    images: the window's frames holding the beauty channels the mapping names and the AOV channels, not yet
    motion-compensated; embeddings/perms/offsets: per window frame, as the primary pass made them (the cache);
    flows: the per-pixel flows the primary pass used, if any; merge_gap/merges/split: the thin bins the primary
    pass merged (binmerge: its gap, per frame the group of each sorted bin or None, the centre's share-back
    factors): the AOVs are merged and shared back the same way; dark_radius: the primary pass's (darkness): the
    bins it kept black keep their noisy AOVs; gain: the primary pass's light-matching gain per pixel (lightmatch;
    None: it applied none), applied to the denoised layers the same way."""
    from . import binmerge
    from .denoise import is_cross_frame
    from .motion import compensate

    cross = is_cross_frame(model)
    dev = next(model.parameters()).device   # the kernels run where the model is, as in the primary pass
    moved, _ = compensate(images, centre, flows, mapping.motion) if len(images) > 1 else (images, 0)
    h, w = images[centre].height, images[centre].width
    gated = bool((model.single if cross else model).config.layer_gate)
    vals, window, centre_groups = [], [], None
    for k, img in enumerate(moved):
        srt, srt_perm = canonical(img, mapping)[0].sorted(copy=False)   # the canonical copy is ours
        if len(srt_perm) != len(perms[k]) or not np.array_equal(srt_perm, perms[k]):
            raise RanadError("the AOV frames do not match the cached bin layout (another render?)", None)
        vals.append(_values(img, mapping, layers, perms[k]))
        cached = merges[k] if merges else None
        groups = None
        if cached is not None:   # the groups of the primary pass, which merged after its NaN/Inf policy
            groups = binmerge.groups_of(replace_nonfinite(srt, DEPTHS)[0], img, srt_perm, merge_gap)
        if (groups is None) != (cached is None) or (groups is not None and not np.array_equal(groups.index, cached)):
            raise RanadError("the AOV frames do not match the cached bin merges (another render?)", None)
        if groups is not None:
            srt = binmerge.merge(srt, groups)
            vals[-1] = {name: torch.from_numpy(binmerge.merge_values(t.numpy(), groups, "composite")
                                               .astype(np.float32)) for name, t in vals[-1].items()}
            if k == centre:
                centre_groups = groups
        rows = int(np.asarray(offsets[k])[-1])
        if any(t.shape[0] != rows for t in vals[-1].values()) or len(embeddings[k]) != rows:
            raise RanadError("the AOV frames do not match the cached bins (merged thin bins not given?)", None)
        vals[-1] = {name: t.to(dev) for name, t in vals[-1].items()}
        layout = Layout.of(torch.as_tensor(offsets[k]), h, w)
        mod = modulation(srt)   # what the primary pass demodulated the diffuse layer by (demodulating models)
        depth = None   # a layer-gated model's kernels read the bins' depths (reconstruction.layer_gate), as they did
        if gated:
            depth = torch.from_numpy(replace_nonfinite(srt, DEPTHS)[0].channel(DEPTH)[:, None].astype(np.float32))
        window.append(ModelInputs(layout, None, {}, None if mod is None else torch.from_numpy(mod), depth).to(dev))
    feats = [torch.from_numpy(np.asarray(e, np.float16)).float().to(dev) for e in embeddings]
    total = vals[centre]["diffuse"].shape[1]
    denoised = {"diffuse": [], "specular": []}
    with torch.inference_mode():
        for a in range(0, max(total, 1), MAX_VALUE_CHANNELS):
            b = min(total, a + MAX_VALUE_CHANNELS)
            for name in ("diffuse", "specular"):
                if name not in (model.single.recon if cross else model.recon):
                    denoised[name].append(vals[centre][name][:, a:b])   # a model without that layer: as is
                    continue
                if cross:
                    for inp, v in zip(window, vals):
                        inp.layers = {name: v[name][:, a:b]}
                    res = model.reconstruct(feats, window, centre)[name]
                else:
                    res = model.reconstruct_layer(name, feats[0], window[0], vals[0][name][:, a:b])
                denoised[name].append(res)
    total_out = torch.cat(denoised["diffuse"], 1) + torch.cat(denoised["specular"], 1)
    if gain is not None:
        gain = np.asarray(gain, np.float32).reshape(-1)
        if gain.shape[0] != h * w or not np.isfinite(gain).all():
            raise RanadError("the cache's light-matching gains do not match the frame (a damaged cache?)", None)
        total_out = total_out * torch.from_numpy(lightmatch.bin_factors(gain, offsets[centre])).to(dev)
    total_out = total_out + vals[centre]["pass"]
    out = total_out.cpu().numpy()
    if centre_groups is not None:
        factors = None if split is None else np.asarray(split, np.float64).reshape(-1)
        if factors is None or factors.shape[0] != centre_groups.index.shape[0] or not np.isfinite(factors).all():
            raise RanadError("the cache's share-back factors do not match its bin merges (a damaged cache?)", None)
        out = binmerge.split(out, centre_groups, factors)
    out = unsort(out, perms[centre])
    noisy = replace_nonfinite(images[centre], mapping.depth_channels())[0]   # the primary pass's _assemble input
    dark = darkness.dark_bins(noisy, mapping, dark_radius)
    if dark is not None:
        out[dark] = noisy.columns([c for chans in layers.values() for c in chans])[dark]
    return {layer: out[:, 3 * i:3 * i + 3] for i, layer in enumerate(layers)}


def _dark_radius(meta: dict, cache_path: str) -> int:
    """The cache's darkness radius ("0" for caches written before it existed: their pass kept nothing black)."""
    try:
        radius = int(meta.get("dark_radius", "0"))
    except ValueError:
        radius = -1
    if radius < 0:
        raise RanadError(f"dark_radius {meta.get('dark_radius')!r} is not a radius (a damaged cache?)", cache_path)
    return radius


def denoise_cached_frame(loaded, cache_path: str, tensors: dict, meta: dict, pattern: str, aov_files: list):
    """The AOV file of one cached frame with its layers matching `pattern` denoised by the cached kernels (what
    `ranad aov` writes). `aov_files`: per window frame, the file holding its AOVs (the beauty itself, or another
    file with the same bin layout). The cache is checked against the model and the beauty it was made from."""
    import json

    from . import cache as cache_io
    from .channels import detect
    from .exr import read_deep

    cache_io.check_cache(meta, cache_path, loaded.model_id)
    window = json.loads(meta["window"])
    centre = int(meta["centre"])
    part = meta.get("part") or None          # the part of a multi-part file the cache was made from
    beauty = [read_deep(p, part=part) for p in window]
    cache_io.check_cache(meta, cache_path, None, beauty[centre])
    aov_imgs = [read_deep(p, part=part) if p != b else b_img for p, b, b_img in zip(aov_files, window, beauty)]
    layers = aov_layers(aov_imgs[centre].channels, pattern)
    if not layers:
        raise RanadError(f"no AOV layers match {pattern!r} (layers with .R/.G/.B channels)", aov_files[centre])
    names = [c for chans in layers.values() for c in chans]
    combined = []
    for p, b_img, a_img in zip(aov_files, beauty, aov_imgs):
        if a_img is b_img:
            combined.append(b_img)
            continue
        if not (a_img.offsets.shape == b_img.offsets.shape and (a_img.offsets == b_img.offsets).all()):
            raise RanadError("bin layout differs from the denoised beauty's (another render?)", p)
        cols = a_img.columns(names)
        keep = [c for c in b_img.channels if c not in names]
        base = b_img.select(keep)
        combined.append(base.with_values(np.concatenate([base.values, cols], 1), keep + names))
    mapping = detect(beauty[centre], json.loads(meta.get("overrides", "{}")), window[centre])
    k = len(window)
    merges = [tensors.get(f"merge.{i}") for i in range(k)]
    try:
        result = denoise_aovs(loaded.model, combined, centre, mapping, layers,
                              [tensors[f"embeddings.{i}"] for i in range(k)],
                              [tensors[f"perm.{i}"] for i in range(k)], [tensors[f"offsets.{i}"] for i in range(k)],
                              None, float(meta.get("merge_gap", "0")), merges if any(x is not None for x in merges)
                              else None, tensors.get("split"), _dark_radius(meta, cache_path), tensors.get("gain"))
    except RanadError as e:   # the cache and the files disagree: name the cache
        if e.path is None:
            raise RanadError(e.problem, cache_path) from None
        raise
    target = replace_nonfinite(aov_imgs[centre], mapping.depth_channels())[0]   # the one NaN/Inf policy
    vals = target.values.copy()
    for layer, chans in layers.items():
        for i, c in enumerate(chans):
            vals[:, target.channels.index(c)] = result[layer][:, i]
    return target.with_values(vals)

"""Renderer channel names -> the semantic layers the model reads (one place for the mapping).

The model reads canonical channels: `diffuse.RGB`, `specular.RGB` (premultiplied radiance, the two layers it
denoises with their own kernels), `emission.RGB` (passed through), `albedo.RGB` and `N.XYZ` (guides), `A`, `Z`,
`ZBack` and `coverage`. A `ChannelMap` says which file channels hold each of them. It is found automatically:

- the beauty is `R, G, B` (required), with `A` and `Z` (required) and `ZBack` (optional);
- every other layer is looked up by its aliases (`diffuse`/`diff`, `specular`/`spec`, `emission`/`emit`,
  `albedo`, `N`/`normal`), with components `R/G/B`, `r/g/b`, `X/Y/Z` or `x/y/z` (`layer.R` naming);
- `--map layer=name` overrides: `diffuse=diff_direct` (a layer prefix) or `diffuse=dR,dG,dB` (three channels).

Modes (what `ranad info` reports and `ranad denoise` uses):

- full: diffuse and specular present. Anything in the beauty that is neither (the residual R - diffuse -
  specular - emission, e.g. transmission or subsurface) is denoised with the diffuse kernels, so the rebuilt
  beauty still contains it.
- no split: no diffuse/specular layers. The beauty minus emission goes through the diffuse reconstruction
  (the model was trained to expect this: `ranad train --p-no-split`).
- without guides: no albedo/normal; the model sees zeros there (trained with `--p-no-aux`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .deep import DeepImage
from .errors import RanadError

ALIASES = {
    "diffuse": ("diffuse", "diff", "Diffuse", "DIFFUSE"),
    "specular": ("specular", "spec", "Specular", "SPECULAR"),
    "emission": ("emission", "emit", "Emission", "EMISSION"),
    "albedo": ("albedo", "Albedo", "diffuse_albedo", "denoise_albedo"),
    "normal": ("N", "normal", "Normal", "normals", "N_world"),
}
COMPONENTS = {"rgb": (("R", "G", "B"), ("r", "g", "b")), "xyz": (("X", "Y", "Z"), ("x", "y", "z"))}
CANONICAL = {"diffuse": "diffuse", "specular": "specular", "emission": "emission", "albedo": "albedo", "normal": "N"}
# Per-bin copies of per-pixel values that ranad itself adds to the canonical image (never read from or written to
# files): the flat prior (OIDN's denoised flattened beauty of the bin's pixel; `PRIOR_NOAUX` the same without the
# albedo/normal guides, for training's reduced-mode crops) and the pixel's flattened noisy beauty.
PRIOR = ("ranad_prior.R", "ranad_prior.G", "ranad_prior.B")
PRIOR_NOAUX = ("ranad_prior_noaux.R", "ranad_prior_noaux.G", "ranad_prior_noaux.B")
FLAT_NOISY = ("ranad_flat.R", "ranad_flat.G", "ranad_flat.B")


@dataclass
class ChannelMap:
    """File channel names of each semantic layer (None: absent)."""
    beauty: tuple = ("R", "G", "B")
    alpha: str = "A"
    depth: str = "Z"
    depth_back: str | None = None
    coverage: str | None = None
    layers: dict = field(default_factory=dict)   # semantic name -> (3 channel names) or None

    @property
    def split(self) -> bool:
        return bool(self.layers.get("diffuse")) and bool(self.layers.get("specular"))

    @property
    def guides(self) -> bool:
        return bool(self.layers.get("albedo")) and bool(self.layers.get("normal"))

    def mode(self) -> str:
        parts = ["full" if self.split else "no split (beauty through the diffuse kernels)"]
        parts.append("with albedo/normal guides" if self.guides else "without guides")
        return ", ".join(parts)

    def describe(self) -> dict:
        d = {"beauty": ",".join(self.beauty), "alpha": self.alpha, "depth": self.depth,
             "depth_back": self.depth_back or "-"}
        d.update({k: (",".join(v) if v else "-") for k, v in self.layers.items()})
        d["mode"] = self.mode()
        return d


def _find_layer(channels: list, names, kind: str):
    for name in names:
        for comps in COMPONENTS[kind]:
            cand = tuple(f"{name}.{c}" for c in comps)
            if all(c in channels for c in cand):
                return cand
    return None


def parse_overrides(items) -> dict:
    """['diffuse=diff', 'albedo=aR,aG,aB'] -> {'diffuse': 'diff', 'albedo': ('aR', 'aG', 'aB')}."""
    out = {}
    for item in items or ():
        if "=" not in item:
            raise RanadError(f"cannot read --map {item!r} (expected layer=prefix or layer=c1,c2,c3)", None)
        key, val = (s.strip() for s in item.split("=", 1))
        if key not in ALIASES:
            raise RanadError(f"--map {item!r}: unknown layer {key!r} (known: {', '.join(ALIASES)})", None)
        parts = tuple(p.strip() for p in val.split(",") if p.strip())
        if len(parts) not in (1, 3):
            raise RanadError(f"--map {item!r}: give one layer prefix or three channels", None)
        out[key] = parts[0] if len(parts) == 1 else parts
    return out


def detect(img: DeepImage, overrides: dict | None = None, source: str | None = None) -> ChannelMap:
    """The ChannelMap of `img`; RanadError naming `source` when a required channel is missing."""
    return detect_names(img.channels, overrides, source)


def detect_names(channels, overrides: dict | None = None, source: str | None = None) -> ChannelMap:
    """The ChannelMap of a list of value channel names (what `ranad info` shows before any pixel is read)."""
    ch = list(channels)
    missing = [c for c in ("R", "G", "B", "A", "Z") if c not in ch]
    if missing:
        raise RanadError(f"missing required channel(s) {', '.join(missing)} (have {', '.join(ch)})", source)
    m = ChannelMap(depth_back="ZBack" if "ZBack" in ch else None, coverage="coverage" if "coverage" in ch else None)
    for layer, names in ALIASES.items():
        kind = "xyz" if layer == "normal" else "rgb"
        m.layers[layer] = _find_layer(ch, names, kind)
    for layer, val in (overrides or {}).items():
        kind = "xyz" if layer == "normal" else "rgb"
        found = _find_layer(ch, (val,), kind) if isinstance(val, str) else (val if all(c in ch for c in val) else None)
        if found is None:
            raise RanadError(f"--map {layer}={val if isinstance(val, str) else ','.join(val)}: no such channels", source)
        m.layers[layer] = found
    return m


def canonical(img: DeepImage, m: ChannelMap) -> tuple[DeepImage, np.ndarray | None]:
    """(the canonical image the model reads, the beauty residual [N, 3] or None).

    In full mode the residual is beauty - diffuse - specular - emission (what the split leaves out); in no-split
    mode the canonical diffuse is beauty - emission and there is no residual."""
    cols, names = [], []

    def put(name, data):
        names.append(name)
        cols.append(np.asarray(data, np.float32))

    def get(layer):
        chans = m.layers.get(layer)
        return None if not chans else np.stack([img.channel(c) for c in chans], 1)

    beauty = np.stack([img.channel(c) for c in m.beauty], 1)
    emission = get("emission")
    residual = None
    if m.split:
        diffuse, specular = get("diffuse"), get("specular")
        residual = beauty - diffuse - specular - (emission if emission is not None else 0)
        for i, c in enumerate("RGB"):
            put(f"diffuse.{c}", diffuse[:, i])
            put(f"specular.{c}", specular[:, i])
    else:
        diffuse = beauty - (emission if emission is not None else 0)
        for i, c in enumerate("RGB"):
            put(f"diffuse.{c}", diffuse[:, i])
    if emission is not None:
        for i, c in enumerate("RGB"):
            put(f"emission.{c}", emission[:, i])
    for layer, comps in (("albedo", "RGB"), ("normal", "XYZ")):
        data = get(layer) if m.guides else None
        if data is not None:
            for i, c in enumerate(comps):
                put(f"{CANONICAL[layer]}.{c}", data[:, i])
    put("A", img.channel(m.alpha))
    put("Z", img.channel(m.depth))
    if m.depth_back:
        put("ZBack", img.channel(m.depth_back))
    if m.coverage:
        put("coverage", img.channel(m.coverage))
    values = np.stack(cols, 1) if cols else np.zeros((img.num_bins, 0), np.float32)
    out = DeepImage(values=values, offsets=img.offsets, channels=names, data_window=img.data_window,
                    display_window=img.display_window)
    return out, residual

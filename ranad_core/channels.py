"""Renderer channel names -> the semantic layers the model reads (one place for the mapping).

The model reads canonical channels: `diffuse.RGB`, `specular.RGB` (premultiplied radiance, the two layers it
denoises with their own kernels), `emission.RGB` (passed through), `albedo.RGB` and `N.XYZ` (guides), `A`, `Z`,
`ZBack` and `coverage`. A `ChannelMap` says which file channels hold each of them. It is found automatically:

- the beauty is `R, G, B` (required), with `A` and `Z` (required) and `ZBack` (optional);
- every other layer is looked up by its aliases (`diffuse`/`diff`, `specular`/`spec`, `emission`/`emit`,
  `albedo`, `N`/`normal`), with components `R/G/B`, `r/g/b`, `X/Y/Z` or `x/y/z` (`layer.R` naming);
- `--map layer=name` overrides: `diffuse=diff_direct` (a layer prefix) or `diffuse=dR,dG,dB` (three channels),
  or a sum of layers, `diffuse=diffuse_direct+diffuse_indirect` (the model denoises the sum; the output writes
  the denoised sum back into the parts in the proportions of their noisy values, per bin and channel);
- motion (per bin, what motion compensation of cross-frame windows reads): `motion_prev.X/Y` and
  `motion_next.X/Y` by default; `--map motion_prev=mv.X,mv.Y` (two channels) or `--map motion_prev=mv` (a
  prefix with .X/.Y, .x/.y, .R/.G, .r/.g or .u/.v) name a renderer's channels, and `MotionSpec` converts them
  to the canonical meaning: pixels per frame, x right, y down, from this bin to its position in the
  previous/next frame (`--motion-units pixels|ndc|velocity`, `--fps`, `--shutter`, `--motion-y up|down`);
- `--preset RENDERER` (presets.py) tries a renderer's documented AOV names before the generic aliases.

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
# normals may come as .R/.G/.B too (V-Ray's normals, Redshift's and Karma's N), as the README's Renderers section says
COMPONENTS = {"rgb": (("R", "G", "B"), ("r", "g", "b")),
              "xyz": (("X", "Y", "Z"), ("x", "y", "z"), ("R", "G", "B"), ("r", "g", "b")),
              "xy": (("X", "Y"), ("x", "y"), ("R", "G"), ("r", "g"), ("u", "v"), ("U", "V"))}
CANONICAL = {"diffuse": "diffuse", "specular": "specular", "emission": "emission", "albedo": "albedo", "normal": "N"}
# The canonical channels by name (what `canonical` builds from a file's channels; the model inputs, metrics,
# baselines, motion and caches read these, never a file's own names).
RGB = ("R", "G", "B")
ALPHA, DEPTH, DEPTH_BACK, COVERAGE = "A", "Z", "ZBack", "coverage"
DEPTHS = (DEPTH, DEPTH_BACK)
REQUIRED = (*RGB, ALPHA, DEPTH)
DIFFUSE = tuple(f"diffuse.{c}" for c in RGB)
SPECULAR = tuple(f"specular.{c}" for c in RGB)
EMISSION = tuple(f"emission.{c}" for c in RGB)
ALBEDO = tuple(f"albedo.{c}" for c in RGB)
NORMAL = ("N.X", "N.Y", "N.Z")
# Per-bin copies of per-pixel values that ranad itself adds to the canonical image (never read from or written to
# files): the flat prior (OIDN's denoised flattened beauty of the bin's pixel; `PRIOR_NOAUX` the same without the
# albedo/normal guides, for training's reduced-mode crops) and the pixel's flattened noisy beauty.
PRIOR = ("ranad_prior.R", "ranad_prior.G", "ranad_prior.B")
PRIOR_NOAUX = ("ranad_prior_noaux.R", "ranad_prior_noaux.G", "ranad_prior_noaux.B")
FLAT_NOISY = ("ranad_flat.R", "ranad_flat.G", "ranad_flat.B")

#: per-bin motion layers, in their canonical names (pixels per frame, x right, y down; ranad synth writes them)
MOTION_LAYERS = ("motion_prev", "motion_next")
CANONICAL_MOTION = {k: (f"{k}.X", f"{k}.Y") for k in MOTION_LAYERS}
MOTION_UNITS = ("pixels", "ndc", "velocity")
#: names that look like motion data (what the "no motion" warning points at when none is mapped)
MOTION_HINTS = ("motion", "mv", "velocity", "vel", "flow", "dpdtime", "vector")


@dataclass(frozen=True)
class MotionSpec:
    """Which channels hold per-bin motion, and how to read them as canonical motion (pixels per frame, x right,
    y down, from a bin to its position in the previous/next frame).

    units: `pixels` (displacement in pixels over `shutter` frames), `ndc` (displacement as a fraction of the
    display window's width/height over `shutter` frames), `velocity` (pixels per second; divided by `fps`).
    y_up: the file's y axis points up (screen space), so y is negated."""
    prev: tuple | None = None
    next: tuple | None = None
    units: str = "pixels"
    fps: float | None = None
    shutter: float = 1.0
    y_up: bool = False

    @property
    def found(self) -> bool:
        return bool(self.prev or self.next)

    def channels(self, direction: str) -> tuple | None:
        return self.prev if direction == "motion_prev" else self.next

    def scale(self, img: DeepImage) -> tuple[float, float]:
        """Factors from the file's values to canonical pixels per frame, (x, y)."""
        if self.units == "velocity":
            sx = sy = 1.0 / float(self.fps)
        elif self.units == "ndc":
            dw = img.display_window
            sx, sy = (dw[2] - dw[0] + 1) / self.shutter, (dw[3] - dw[1] + 1) / self.shutter
        else:
            sx = sy = 1.0 / self.shutter
        return sx, (-sy if self.y_up else sy)

    def vectors(self, img: DeepImage, direction: str) -> np.ndarray | None:
        """[N, 2] float32 canonical motion of `img`'s bins towards `direction` ('motion_prev' or 'motion_next'),
        or None when that direction is not mapped (or the frame lacks the channels). Non-finite values are 0."""
        chans = self.channels(direction)
        if not chans or not all(c in img.channels for c in chans):
            return None
        v = img.columns(chans).astype(np.float64)
        v = np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0) * np.asarray(self.scale(img))
        return v.astype(np.float32)

    @classmethod
    def canonical(cls) -> "MotionSpec":
        """ranad's own channels (what `ranad synth` writes): motion_prev/motion_next.X/Y in pixels."""
        return cls(prev=CANONICAL_MOTION["motion_prev"], next=CANONICAL_MOTION["motion_next"])

    def describe(self) -> str:
        if not self.found:
            return "none"
        parts = [f"{k}={','.join(v)}" for k, v in (("motion_prev", self.prev), ("motion_next", self.next)) if v]
        conv = self.units + (f" at {self.fps:g} fps" if self.units == "velocity" else "")
        if self.units != "velocity" and self.shutter != 1.0:
            conv += f" over {self.shutter:g} frame(s)"
        return f"{' '.join(parts)} ({conv}, y {'up' if self.y_up else 'down'})"


@dataclass
class ChannelMap:
    """File channel names of each semantic layer (None: absent)."""
    beauty: tuple = ("R", "G", "B")
    alpha: str = "A"
    depth: str = "Z"
    depth_back: str | None = None
    coverage: str | None = None
    layers: dict = field(default_factory=dict)   # semantic name -> (3 channel names), a tuple of such (sum), None
    motion: MotionSpec = field(default_factory=MotionSpec)
    preset: str | None = None

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
             "depth_back": self.depth_back or "-",
             "coverage": self.coverage or "from the alphas"}   # model.inputs.contribution where a file has none
        d.update({k: describe_layer(v) for k, v in self.layers.items()})
        d["motion"] = self.motion.describe()
        if self.preset:
            d["preset"] = self.preset
        d["mode"] = self.mode()
        return d

    def value_channels(self) -> list:
        """Every file channel the map reads a value from, motion aside (a frame without motion is warned about,
        not refused): what each frame of a window must carry."""
        names = [*self.beauty, self.alpha, self.depth, self.depth_back, self.coverage]
        names += [c for chans in self.layers.values() for part in layer_parts(chans) for c in part]
        return [c for c in dict.fromkeys(names) if c]

    def depth_channels(self) -> tuple:
        """The file channels holding depth (what the NaN/Inf policy fills with the frame's largest depth)."""
        return tuple(c for c in (self.depth, self.depth_back) if c)


def layer_parts(chans) -> list:
    """The (R, G, B) channel triples a layer entry sums: [] when absent, one for a plain layer."""
    if not chans:
        return []
    return [tuple(p) for p in chans] if isinstance(chans[0], (tuple, list)) else [tuple(chans)]


def describe_layer(chans) -> str:
    return "+".join(",".join(p) for p in layer_parts(chans)) or "-"


def layer_values(img: DeepImage, chans) -> np.ndarray | None:
    """[N, 3] float32 values of a layer entry (the sum of its parts), None when absent."""
    parts = layer_parts(chans)
    if not parts:
        return None
    out = img.columns(parts[0]).astype(np.float32, copy=False)
    for p in parts[1:]:
        out = out + img.columns(p).astype(np.float32, copy=False)
    return out


def split_layer(img: DeepImage, chans, total: np.ndarray) -> list:
    """[(channel triple, [N, 3] values)] writing `total` back into a layer entry: a plain layer gets `total`; a
    sum's parts get it in the proportions of their noisy values (per bin and channel; where the noisy parts sum
    to 0, in their proportions over the whole frame, or equal shares), so the parts sum to `total`."""
    parts = layer_parts(chans)
    if len(parts) == 1:
        return [(parts[0], total)]
    noisy = [np.nan_to_num(img.columns(p).astype(np.float64)) for p in parts]
    s = sum(noisy)
    ok = np.abs(s) > 1e-12
    safe = np.where(ok, s, 1.0)
    frame = sum(v.sum(0) for v in noisy)
    frame_ok = np.abs(frame) > 1e-12
    out = []
    for p, v in zip(parts, noisy):
        fallback = np.where(frame_ok, v.sum(0) / np.where(frame_ok, frame, 1.0), 1.0 / len(parts))
        out.append((p, (total * np.where(ok, v / safe, fallback)).astype(np.float32)))
    return out


def _find_layer(channels, names, kind: str):
    for name in names:
        for comps in COMPONENTS[kind]:
            cand = tuple(f"{name}.{c}" for c in comps)
            if all(c in channels for c in cand):
                return cand
    return None


def _parse_value(key: str, val: str, item: str):
    """One --map value: a prefix (str), explicit channels (tuple), or a sum {'sum': [prefix or channels, ...]}."""
    width = 2 if key in MOTION_LAYERS else 3
    terms = [t.strip() for t in val.split("+")]
    if len(terms) > 1 and key in MOTION_LAYERS:
        raise RanadError(f"--map {item!r}: motion layers cannot be summed", None)
    out = []
    for t in terms:
        parts = tuple(p.strip() for p in t.split(",") if p.strip())
        if len(parts) not in (1, width):
            what = "two channels" if width == 2 else "three channels"
            raise RanadError(f"--map {item!r}: give a layer prefix or {what}" + (" per summed layer" if len(terms) > 1
                                                                                 else ""), None)
        out.append(parts[0] if len(parts) == 1 else parts)
    return out[0] if len(out) == 1 else {"sum": out}


def parse_overrides(items) -> dict:
    """['diffuse=diff', 'albedo=aR,aG,aB', 'diffuse=a+b', 'motion_prev=mv.X,mv.Y'] -> {'diffuse': 'diff', ...}
    (a prefix, a tuple of channels, or {'sum': [...]}); JSON-able, so a cache records it."""
    out = {}
    for item in items or ():
        if "=" not in item:
            raise RanadError(f"cannot read --map {item!r} (expected layer=prefix, layer=c1,c2,c3 or layer=a+b)", None)
        key, val = (s.strip() for s in item.split("=", 1))
        if key not in ALIASES and key not in MOTION_LAYERS:
            raise RanadError(f"--map {item!r}: unknown layer {key!r} (known: {', '.join((*ALIASES, *MOTION_LAYERS))})",
                             None)
        if not val:
            raise RanadError(f"--map {item!r}: no channels given", None)
        out[key] = _parse_value(key, val, item)
    return out


def mapping_options(maps=(), preset: str | None = None, motion_units: str | None = None, fps: float | None = None,
                    shutter: float | None = None, motion_y: str | None = None) -> dict:
    """The whole channel-mapping recipe of a command line as one JSON-able dict (what `detect` reads and a cache
    records): the --map overrides, the preset, and the motion conversion (None: not given, so the preset's or
    the default: pixels per frame, y down). Inconsistent options are RanadErrors."""
    from .presets import PRESETS

    out = parse_overrides(maps)
    if preset is not None:
        if preset not in PRESETS:
            raise RanadError(f"--preset {preset!r}: unknown renderer (known: {', '.join(PRESETS)})", None)
        out["preset"] = preset
    given = any(v is not None for v in (motion_units, fps, shutter, motion_y))
    # the options not given keep the preset's conversion (one option used to reset the others to pixels, y down)
    base = dict(PRESETS[preset].motion_conversion) if preset is not None else {}
    motion_units, motion_y = motion_units or base.get("units") or "pixels", motion_y or base.get("y") or "down"
    if motion_units not in MOTION_UNITS:
        raise RanadError(f"--motion-units {motion_units!r}: use one of {', '.join(MOTION_UNITS)}", None)
    if motion_y not in ("up", "down"):
        raise RanadError(f"--motion-y {motion_y!r}: use up or down", None)
    if motion_units == "velocity" and fps is None:
        raise RanadError("--motion-units velocity needs --fps (frames per second)", None)
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise RanadError(f"--fps {fps}: must be a positive number", None)
    if fps is not None and motion_units != "velocity":
        raise RanadError("--fps only applies to --motion-units velocity", None)
    if shutter is not None:
        if motion_units == "velocity":
            raise RanadError("--shutter applies to displacements (pixels, ndc), not to velocities", None)
        if not (np.isfinite(shutter) and shutter > 0):
            raise RanadError(f"--shutter {shutter}: must be a positive number of frames", None)
    if given:
        out["motion"] = {"units": motion_units, "fps": fps, "shutter": shutter, "y": motion_y}
    return out


def detect(img: DeepImage, overrides: dict | None = None, source: str | None = None) -> ChannelMap:
    """The ChannelMap of `img`; RanadError naming `source` when a required channel is missing (or stored as
    UINT, which holds ids, not colour, alpha or depth)."""
    as_ids = [c for c in REQUIRED if c not in img.channels and c in img.ids]
    if as_ids:
        raise RanadError(f"channel(s) {', '.join(as_ids)} stored as UINT; ranad reads {', '.join(REQUIRED)} as half or "
                         f"float", source)
    return detect_names(img.channels, overrides, source)


def _resolve(ch: list, key: str, val, source):
    """Channels of one mapping value (see `_parse_value`; lists from JSON are channel tuples); None: not found."""
    kind = "xy" if key in MOTION_LAYERS else ("xyz" if key == "normal" else "rgb")
    if isinstance(val, dict):
        parts = [_resolve(ch, key, v, source) for v in val["sum"]]
        return None if any(p is None for p in parts) else tuple(parts)
    if isinstance(val, str):
        return _find_layer(ch, (val,), kind)
    val = tuple(val)
    return val if all(c in ch for c in val) else None


def detect_names(channels, overrides: dict | None = None, source: str | None = None) -> ChannelMap:
    """The ChannelMap of a list of value channel names (what `ranad info` shows before any pixel is read)."""
    from .presets import PRESETS

    ch = list(channels)
    opts = dict(overrides or {})
    missing = [c for c in ("R", "G", "B", "A", "Z") if c not in ch]
    if missing:
        raise RanadError(f"missing required channel(s) {', '.join(missing)} (have {', '.join(ch)})", source)
    m = ChannelMap(depth_back="ZBack" if "ZBack" in ch else None, coverage="coverage" if "coverage" in ch else None)
    preset = PRESETS.get(opts.get("preset")) if opts.get("preset") else None
    for layer, names in ALIASES.items():
        kind = "xyz" if layer == "normal" else "rgb"
        if preset and layer in preset.layers:          # the renderer's names only (no generic alias)
            m.layers[layer] = next((f for f in (_resolve(ch, layer, v, source) for v in preset.layers[layer]) if f),
                                   None)
        else:
            m.layers[layer] = _find_layer(ch, names, kind)
    motion = {k: _find_layer(ch, (k,), "xy") for k in MOTION_LAYERS}
    conv = dict(opts.get("motion") or {})
    if preset:
        m.preset = preset.name
        for k in MOTION_LAYERS:
            for val in preset.motion.get(k, ()):
                found = _resolve(ch, k, val, source)
                if found:
                    motion[k] = found
                    break
        if "motion" not in opts:
            conv = dict(preset.motion_conversion)
    for key, val in opts.items():
        if key not in ALIASES and key not in MOTION_LAYERS:
            continue
        found = _resolve(ch, key, val, source)
        if found is None:
            raise RanadError(f"--map {key}={_show(val)}: no such channels (have {', '.join(ch)})", source)
        if key in MOTION_LAYERS:
            motion[key] = found
        else:
            m.layers[key] = found
    _check_distinct(m, source)
    m.motion = MotionSpec(prev=motion["motion_prev"], next=motion["motion_next"], units=conv.get("units") or "pixels",
                          fps=conv.get("fps"), shutter=conv.get("shutter") or 1.0, y_up=conv.get("y") == "up")
    return m


def _check_distinct(m: ChannelMap, source) -> None:
    """Refuse a map that reads one channel for two radiance layers (--map diffuse=specular, diffuse=a+a, a layer
    on R,G,B): the denoised layers are written back into their channels, so two results would land in one place,
    the other layer's own channels would stay noisy and the beauty would be rebuilt from parts that never summed
    to it. (The guides, albedo and normals, are only read.)"""
    owner = {c: "beauty" for c in m.beauty}
    for layer in ("diffuse", "specular", "emission"):
        for part in layer_parts(m.layers.get(layer)):
            for c in part:
                if c in owner:
                    what = f"{layer} reads {c} twice" if owner[c] == layer else f"{owner[c]} and {layer} both read {c}"
                    raise RanadError(f"channel map: {what} (each layer needs channels of its own; see --map)", source)
                owner[c] = layer


def _show(val) -> str:
    if isinstance(val, dict):
        return "+".join(_show(v) for v in val["sum"])
    return val if isinstance(val, str) else ",".join(val)


def motion_candidates(channels) -> list:
    """Channels whose names suggest motion data (for the warning when no motion is mapped)."""
    return [c for c in channels if any(h in c.split(".")[0].lower() for h in MOTION_HINTS)]


def canonical(img: DeepImage, m: ChannelMap) -> tuple[DeepImage, np.ndarray | None]:
    """(the canonical image the model reads, the beauty residual [N, 3] or None).

    In full mode the residual is beauty - diffuse - specular - emission (what the split leaves out); in no-split
    mode the canonical diffuse is beauty - emission and there is no residual.

    Built in one row-wise gather of every column that is a plain copy of a file channel (with a renderer's usual
    one-part layers, all of them), then the computed blocks written over their placeholders: joining per-layer
    blocks cost a gather per layer and a copy of the whole image more (1.5 s of a 2.9 M-bin frame against 0.15-0.8
    s, the larger where the output lands on fresh pages)."""
    blocks = []   # (canonical names, source channel names to copy, or an [N, k] array)

    def part_names(layer):
        parts = layer_parts(m.layers.get(layer))
        return None if not parts else parts[0] if len(parts) == 1 else False   # False: a sum, computed

    def get(layer):
        return layer_values(img, m.layers.get(layer))

    emission_src = part_names("emission")
    residual = None
    if m.split:
        dif, spe = part_names("diffuse"), part_names("specular")
        if dif and spe:
            blocks.append(([c for i in range(3) for c in (DIFFUSE[i], SPECULAR[i])],
                           [c for i in range(3) for c in (dif[i], spe[i])]))
        else:
            blocks.append(([c for i in range(3) for c in (DIFFUSE[i], SPECULAR[i])],
                           np.stack([get("diffuse"), get("specular")], 2).reshape(img.num_bins, 6)))
    elif emission_src is None:
        blocks.append((list(DIFFUSE), list(m.beauty)))
    else:
        blocks.append((list(DIFFUSE), img.columns(m.beauty) - get("emission")))
    if emission_src is not None:
        blocks.append((list(EMISSION), list(emission_src) if emission_src else get("emission")))
    for layer, canonical_names in (("albedo", ALBEDO), ("normal", NORMAL)):
        src = part_names(layer) if m.guides else None
        if src is not None:
            blocks.append((list(canonical_names), list(src) if src else get(layer)))
    direct = [(ALPHA, m.alpha), (DEPTH, m.depth)]
    if m.depth_back:
        direct.append((DEPTH_BACK, m.depth_back))
    if m.coverage:
        direct.append((COVERAGE, m.coverage))
    for names_ in (PRIOR, FLAT_NOISY):   # a flat prior ranad attached to the frame (carried through compensation)
        if all(c in img.channels for c in names_):
            direct += [(c, c) for c in names_]
    blocks.append(([c for c, _ in direct], [src for _, src in direct]))

    names = [c for block_names, _ in blocks for c in block_names]
    index = [img.channel_index(s) if isinstance(src, list) else 0 for _, src in blocks for s in
             (src if isinstance(src, list) else range(np.shape(src)[1]))]
    values = np.take(img.values, index, axis=1)
    at = 0
    for block_names, src in blocks:
        if not isinstance(src, list):
            values[:, at:at + len(block_names)] = np.asarray(src, np.float32).reshape(img.num_bins, len(block_names))
        at += len(block_names)
    if m.split:
        col = {c: i for i, c in enumerate(names)}
        cols = lambda group: np.take(values, [col[c] for c in group], axis=1)   # noqa: E731
        residual = img.columns(m.beauty) - cols(DIFFUSE) - cols(SPECULAR)
        if emission_src is not None:
            residual = residual - cols(EMISSION)
    out = DeepImage(values=values, offsets=img.offsets, channels=names, data_window=img.data_window,
                    display_window=img.display_window)
    return out, residual

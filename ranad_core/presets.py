"""Renderer presets (`--preset`): each renderer's documented deep AOV names and motion conventions.

A preset lists, per semantic layer of channels.py, the channel names to try first (a layer prefix, explicit
channels, or a sum of layers); layers it does not find fall back to the generic aliases, and `--map` overrides
both. Its motion entries name the renderer's per-bin motion channels and how to convert them to ranad's
canonical motion (pixels per frame, x right, y down; see channels.MotionSpec). The sources are cited per preset
and in the README's "Renderers" section.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Preset:
    name: str
    layers: dict                     # semantic layer -> tuple of candidate values, first found wins
    motion: dict = field(default_factory=dict)             # motion_prev/motion_next -> candidate values
    motion_conversion: dict = field(default_factory=dict)  # units, fps, shutter, y (channels.mapping_options)
    sources: tuple = ()
    note: str = ""


PRESETS: dict = {}

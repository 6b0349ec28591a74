"""DeepImage: the one ragged container for deep pixels, and its vectorised operations.

Layout (DESIGN.md, "The ragged layout"): an image of H x W pixels (the EXR data window) holds
``values`` float32 [N, C] (one row per bin/sample, one column per non-id channel) and ``offsets`` int64
[H*W+1] (cumulative bin counts, row-major pixels; pixel i owns rows ``offsets[i]:offsets[i+1]``).
This is FlashAttention's ``cu_seqlens`` / TensorFlow's ``row_splits``. Id channels (uint32 in the file) are
kept apart in ``ids`` as exact integers: never averaged, filtered or cast to float.

Bins are kept in the file's order, so a read/write round trip is exact. Code that needs depth order calls
:meth:`DeepImage.sorted` which also returns the permutation, so results can go back to the input's order.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

Window = tuple[int, int, int, int]  # (xmin, ymin, xmax, ymax), inclusive, as in EXR box2i

#: file pixel types of EXR channels, as stored in :attr:`DeepImage.channel_types`
PIXEL_TYPES = ("uint", "half", "float")


@dataclass
class DeepImage:
    """A deep image: ragged per-pixel bins plus everything needed to write it back unchanged.

    Attributes:
        values: float32 [N, C], the non-id channels, columns in the order of ``channels``.
        offsets: int64 [H*W+1], cumulative bin counts over row-major pixels of the data window.
        channels: names of the columns of ``values`` (e.g. ``R``, ``G``, ``B``, ``A``, ``Z``, ``ZBack``).
        ids: name -> uint32 [N] for every uint channel, exact.
        data_window: (xmin, ymin, xmax, ymax) inclusive; ``values`` covers exactly this window.
        display_window: (xmin, ymin, xmax, ymax) inclusive.
        channel_types: name -> "half" | "float" | "uint" for every channel (values and ids), the type
            each channel had in the file (writing back reproduces it).
        header: the file's attributes, name -> ``ranad_core.exr.header.Attribute`` (type name and raw
            bytes), passed through byte for byte by the writer except the structural ones it regenerates.
    """

    values: np.ndarray
    offsets: np.ndarray
    channels: list[str]
    ids: dict[str, np.ndarray] = field(default_factory=dict)
    data_window: Window = (0, 0, 0, 0)
    display_window: Window | None = None
    channel_types: dict[str, str] = field(default_factory=dict)
    header: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.values = np.ascontiguousarray(self.values, dtype=np.float32)
        self.offsets = np.ascontiguousarray(self.offsets, dtype=np.int64)
        self.channels = list(self.channels)
        self.ids = {k: np.ascontiguousarray(v, dtype=np.uint32) for k, v in self.ids.items()}
        self.data_window = tuple(int(v) for v in self.data_window)
        if self.display_window is None:
            self.display_window = self.data_window
        self.display_window = tuple(int(v) for v in self.display_window)
        for name in self.channels:
            self.channel_types.setdefault(name, "half" if name not in ("Z", "ZBack") else "float")
        for name in self.ids:
            self.channel_types.setdefault(name, "uint")
        self.validate()

    # ---- shape -------------------------------------------------------------------------------------
    @property
    def width(self) -> int:
        return self.data_window[2] - self.data_window[0] + 1

    @property
    def height(self) -> int:
        return self.data_window[3] - self.data_window[1] + 1

    @property
    def num_pixels(self) -> int:
        return self.width * self.height

    @property
    def num_bins(self) -> int:
        return int(self.offsets[-1])

    @property
    def counts(self) -> np.ndarray:
        """int64 [H*W]: bins per pixel."""
        return np.diff(self.offsets)

    def validate(self) -> None:
        """Raise ValueError if the arrays disagree with each other (a programming error, not user input)."""
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"empty data window {self.data_window}")
        if self.offsets.shape != (self.num_pixels + 1,):
            raise ValueError(f"offsets has shape {self.offsets.shape}, expected ({self.num_pixels + 1},)")
        if self.offsets[0] != 0 or (self.offsets.size > 1 and np.any(np.diff(self.offsets) < 0)):
            raise ValueError("offsets must start at 0 and be non-decreasing")
        if self.values.ndim != 2 or self.values.shape != (self.num_bins, len(self.channels)):
            raise ValueError(f"values has shape {self.values.shape}, expected ({self.num_bins}, {len(self.channels)})")
        for k, v in self.ids.items():
            if v.shape != (self.num_bins,):
                raise ValueError(f"id channel {k!r} has shape {v.shape}, expected ({self.num_bins},)")
        dup = set(self.channels) & set(self.ids)
        if dup or len(set(self.channels)) != len(self.channels):
            raise ValueError(f"duplicate channel names {sorted(dup) or self.channels}")

    # ---- per-bin indices ---------------------------------------------------------------------------
    def pixel_index(self) -> np.ndarray:
        """int64 [N]: the row-major pixel each bin belongs to."""
        return np.repeat(np.arange(self.num_pixels, dtype=np.int64), self.counts)

    def bin_index(self) -> np.ndarray:
        """int64 [N]: each bin's position within its pixel (0 for the first bin of a pixel)."""
        return np.arange(self.num_bins, dtype=np.int64) - np.repeat(self.offsets[:-1], self.counts)

    # ---- channels ----------------------------------------------------------------------------------
    def channel_index(self, name: str) -> int:
        try:
            return self.channels.index(name)
        except ValueError:
            raise KeyError(f"no channel {name!r} (have {', '.join(self.channels)})") from None

    def has(self, name: str) -> bool:
        return name in self.channels or name in self.ids

    def channel(self, name: str) -> np.ndarray:
        """float32 [N] view of one non-id channel, or the uint32 [N] id channel of that name."""
        if name in self.ids:
            return self.ids[name]
        return self.values[:, self.channel_index(name)]

    def with_values(self, values: np.ndarray, channels: list[str] | None = None) -> "DeepImage":
        """Same layout, ids and header, new per-bin values (and optionally channel names)."""
        channels = self.channels if channels is None else list(channels)
        types = {k: v for k, v in self.channel_types.items() if k in channels or k in self.ids}
        return replace(self, values=values, channels=channels, channel_types=types)

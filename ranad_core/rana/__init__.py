"""RaNA, the ragged neighbourhood attention operator (paper Sec. 3): one op API for every backend.

``rana`` is the op; :mod:`.reference` its plain-torch oracle; :mod:`.layout` builds the query/key layouts
the model needs (self-attention, bin-dropout down-sampling, up-sampling, temporal windows) from ragged
offsets; :mod:`.neighborhood` defines the disc.
"""

from .layout import (bin_pixels, concat_frames, downsample_layout, pixel_offsets_of,
                     self_attention_layout)
from .neighborhood import disc
from .op import rana
from .reference import rana_reference

__all__ = ["rana", "rana_reference", "disc", "bin_pixels", "self_attention_layout", "downsample_layout",
           "concat_frames", "pixel_offsets_of"]

"""The memory ceiling behind `--max-memory`: how much of it is left for the model's tiles.

The process's peak is what it already holds when a frame starts (torch, the model, the frames read: its resident
set, measured rather than modelled), plus what denoising the frame adds besides the tiles (working copies of the
frame and its neighbours, the output: `frame_working_bytes`), plus the idle buffers the C++ kernels keep for reuse
(bounded by RANAD_RANA_BUFFER_CACHE_MB, which `cap_kernel_cache` sizes to the ceiling), plus the tiles' working
memory (denoise.BYTES_PER_BIN per bin of the largest haloed window). The tiles get what is left; when that is too
little for one minimal tile the frame cannot be denoised within the ceiling, and the error says how much it needs.
Before the tiles, making the frame's inputs and flat prior peaks once (`prior_peak_bytes`: OIDN's scratch, released
before the tiles start); that peak has to fit the ceiling as well.

On a GPU (`--device cuda`) the tiles' working memory sits in the GPU's memory, which `--max-memory` does not
describe: the tiles are then also sized to what the GPU has free when the frame starts (`device_free_bytes`, less
the same margin), so a smaller card gets smaller tiles rather than an out-of-memory error mid-frame.
"""

from __future__ import annotations

import os

from . import heap
from .errors import RanadError

KERNEL_CACHE_ENV = "RANAD_RANA_BUFFER_CACHE_MB"
KERNEL_CACHE_DEFAULT_MB = 2048       # the kernels' own default (cuda/rana_cpu_buffers.h)
MARGIN = 0.04                        # of the ceiling: allocator slack, Python objects, progress bars
# A frame's tiles are first sized with the heap's kept memory counted as in use (resident_bytes(give_back=False)):
# giving it back means faulting it in again as the frame's tensors reuse it. Only when that sizing would compute
# more than GIVE_BACK_WORTH times the work of the sizing with the kept memory given back (estimated from
# heap.kept_bytes), or fit nothing, is it given back and the frame sized again. Measured on bench/shot.py's 5-frame
# 960x540 shot (runs/generalization-s39): giving back at every frame start returned 2-3.5 GB each time, and
# faulting it in again took 3.9-4.0 M page faults and 16 s of system time with the cross-frame default; without it
# 1.05 M and 6 s, the shot 57.3 / 59.2 -> 54.3 / 55.6 s (two alternating rounds) in 18 tiles instead of 10 (1.14x
# the frame's bins computed instead of 1.07x: four frames sized smaller, at most 1.25x the work) and a lower peak
# (4.3-4.4 against 4.7-4.9 GB); with the single-frame default 40.9 / 41.6 -> 38.3 / 38.7 s, the same tiles.
GIVE_BACK_WORTH = 1.5


def resident_bytes(give_back: bool = True) -> int:
    """This process's resident set now (Linux /proc; 0 where it cannot be read), after the heap has given back
    the free memory it keeps for reuse (heap.py), so the figure is what the process uses. `give_back=False`: as it
    is, the kept memory counted as in use (an upper bound, and no pages to fault in again; see GIVE_BACK_WORTH)."""
    if give_back:
        heap.give_back()
    return heap.resident_now()


def cap_kernel_cache(max_memory: float) -> None:
    """Bounds the kernels' idle-buffer cache to 1/16 of the ceiling (64 MB to its 2 GB default) unless the user set
    RANAD_RANA_BUFFER_CACHE_MB. Read by the kernels when they first run, so it takes effect in a process that has
    not run them yet (a `ranad` command)."""
    if KERNEL_CACHE_ENV not in os.environ:
        os.environ[KERNEL_CACHE_ENV] = str(int(max(64, min(KERNEL_CACHE_DEFAULT_MB, max_memory / 16 / 2**20))))


def kernel_cache_bytes() -> float:
    try:
        return float(os.environ.get(KERNEL_CACHE_ENV, KERNEL_CACHE_DEFAULT_MB)) * 2**20
    except ValueError:
        return KERNEL_CACHE_DEFAULT_MB * 2**20


def frame_working_bytes(images: list, centre: int) -> float:
    """Bytes a frame's denoising holds beside the tiles, on top of the frames already read: the canonical and
    sorted copies with the flat prior's channels, the outputs, small per-pixel images; for each neighbour its
    compensated, sorted copy. Measured (the 1080p frame of bench/denoise.py tiled from heldout_g1/scene_0005,
    2.9 M bins, 422 MB of values): 922 MB held after the frame's inputs are made, plus 128 MB of outputs. Taken
    here as 2x the values + 64 B per bin + 128 B per pixel for the centre, the values + 64 B per bin + 128 B per
    pixel per neighbour. The flat prior's OIDN scratch is released before the tiles (prior.released_oidn); it is
    part of the transient `prior_peak_bytes`."""
    c = images[centre]
    extra = 2.0 * c.values.nbytes + 64.0 * c.num_bins + 128.0 * c.width * c.height
    extra += sum(im.values.nbytes + 64.0 * im.num_bins + 128.0 * im.width * im.height
                 for i, im in enumerate(images) if i != centre)
    return extra


def prior_peak_bytes(images: list, centre: int) -> float:
    """The transient peak of making a frame's inputs and flat prior, on top of the frames already read: the
    canonical and sorted copies, the prior's columns, the flattened images and OIDN's scratch (about 580 B per
    pixel at 1080p). Measured on the same frame as frame_working_bytes: 2247 MB above the resident set. Taken as
    2.5x the values + 64 B per bin + 600 B per pixel of the largest frame of the window (frames are prepared one at
    a time), which gave 2.49 GB there. A frame without bins gets no OIDN run (prior.flat_images), only its
    flattened images: 64 B per pixel (an empty 4000 x 4000 frame was refused at the default 8G for OIDN's 10 GB)."""
    return max(2.5 * im.values.nbytes + 64.0 * im.num_bins + (600.0 if im.num_bins else 64.0) * im.width * im.height
               for im in images)


def fmt(n: float) -> str:
    if n >= 2**30:
        return f"{n / 2**30:.2f} GB"
    return f"{n / 2**20:.0f} MB" if n >= 10 * 2**20 else f"{n / 2**20:.1f} MB"


def tile_budget(max_memory: float, images: list, centre: int, resident: float | None = None) -> tuple[float, float]:
    """(bytes the tiles may use, bytes everything else takes) under the ceiling `max_memory` for this frame;
    `resident`: the process's resident set to count (None: resident_bytes())."""
    resident = resident_bytes() if resident is None else resident
    other = resident + frame_working_bytes(images, centre) + kernel_cache_bytes() + MARGIN * max_memory
    return max_memory - other, other


def prior_need(max_memory: float, images: list, centre: int, resident: float | None = None) -> float:
    """Bytes the frame's inputs and flat prior need at their peak, the process's resident set included (`resident`,
    None: resident_bytes()); more than `max_memory` means the frame cannot be prepared within the ceiling, whatever
    the tiles."""
    resident = resident_bytes() if resident is None else resident
    return resident + prior_peak_bytes(images, centre) + kernel_cache_bytes() + MARGIN * max_memory


def device_free_bytes(device) -> float:
    """Bytes the tiles may use on `device`: for a CUDA device, what the driver reports free plus what torch's
    allocator holds unused (it reuses that first), less MARGIN of the card's total; unbounded for the CPU (the
    ceiling `--max-memory` covers it)."""
    import torch

    device = torch.device(device)
    if device.type != "cuda":
        return float("inf")
    free, total = torch.cuda.mem_get_info(device)
    cached = torch.cuda.memory_reserved(device) - torch.cuda.memory_allocated(device)
    return float(free + cached - MARGIN * total)


def too_small_on_device(free: float, minimal_tile: float, tile: int, halo: int, where: str) -> RanadError:
    """The error for a GPU whose free memory does not fit one minimal tile."""
    return RanadError(f"the GPU has {fmt(max(free, 0))} free for the tiles, and one {tile}-pixel tile with its "
                      f"{halo}-pixel halo needs {fmt(minimal_tile)}: free GPU memory or run with --device cpu", where)


def too_small(max_memory: float, other: float, minimal_tile: float, tile: int, halo: int, where: str,
              prior: float = 0.0) -> RanadError:
    """The error for a ceiling that does not fit one minimal tile, or (`prior`: prior_need) the peak of making the
    frame's inputs and flat prior, with the size that fits both."""
    need = max(other + minimal_tile, prior)
    made = (f"; making its inputs and flat prior needs {fmt(prior)} (OIDN's buffers included)"
            if prior > max_memory else "")
    return RanadError(f"--max-memory {fmt(max_memory)} is too small for this frame: {fmt(other)} is held or needed "
                      f"besides the tiles (the process, the frames, their working copies, the kernels' buffers) and "
                      f"one {tile}-pixel tile with its {halo}-pixel halo needs {fmt(minimal_tile)}{made}; use at "
                      f"least --max-memory {fmt(need * 1.05)}", where)

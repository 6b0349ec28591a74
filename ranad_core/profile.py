"""Where a denoise run's time goes: wall-clock seconds per pipeline stage (`ranad denoise --profile`), and the
process's CPU seconds in each (all threads together): their ratio, the threads kept busy, shows the stages that
run serially on a machine with many cores.

The pipeline marks its stages with `with stage(name):`; nothing is recorded (and the marks cost a global lookup)
unless a `profiling()` block is active. Stages named "parent/child" are inside their parent and are listed under
it, not added to the total. Tiles are also recorded one by one (bins, seconds), since the tile size and halo are
what a user tunes.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field

STAGES = ("read", "motion", "inputs", "inputs/sort and prior", "tiles", "tiles/gather", "tiles/backbone",
          "tiles/reconstruction", "tiles/scatter", "assemble", "aovs", "cache", "write")


@dataclass
class Profile:
    seconds: dict = field(default_factory=dict)
    cpu: dict = field(default_factory=dict)        # process CPU seconds (every thread's) per stage
    calls: dict = field(default_factory=dict)
    # per tile: (the centre frame's bins in the haloed window, its core bins, seconds, the bins of every frame's
    # window: more than the first for a cross-frame window)
    tiles: list = field(default_factory=list)

    def add(self, name: str, secs: float, cpu_secs: float = 0.0) -> None:
        self.seconds[name] = self.seconds.get(name, 0.0) + secs
        self.cpu[name] = self.cpu.get(name, 0.0) + cpu_secs
        self.calls[name] = self.calls.get(name, 0) + 1

    def total(self) -> float:
        return sum(v for k, v in self.seconds.items() if "/" not in k)

    def table(self) -> str:
        """A markdown table: stage, seconds, share of the total, calls, CPU seconds and threads busy (CPU over wall
        seconds); then the per-tile summary."""
        total = self.total() or 1e-12
        order = [s for s in STAGES if s in self.seconds] + sorted(set(self.seconds) - set(STAGES))
        lines = ["| stage | seconds | share | calls | cpu seconds | threads busy |", "|---|---|---|---|---|---|"]
        for name in order:
            label = ("  - " + name.split("/", 1)[1]) if "/" in name else name
            secs, cpu = self.seconds[name], self.cpu.get(name, 0.0)
            lines.append(f"| {label} | {secs:.2f} | {100 * secs / total:.1f}% | {self.calls[name]} | {cpu:.2f} | "
                         f"{cpu / max(secs, 1e-12):.2f} |")
        cpu_total = sum(v for k, v in self.cpu.items() if "/" not in k)
        lines.append(f"| total | {self.total():.2f} | 100% | | {cpu_total:.2f} | "
                     f"{cpu_total / max(self.total(), 1e-12):.2f} |")
        if self.tiles:
            bins = [t[0] for t in self.tiles]
            core = sum(t[1] for t in self.tiles)
            secs = [t[2] for t in self.tiles]
            window = [t[3] for t in self.tiles]
            lines.append("")
            lines.append(f"{len(self.tiles)} tile(s): {min(bins)}-{max(bins)} bins with the halo, "
                         f"{sum(bins) / max(core, 1):.2f}x the frame's bins computed (halo overlap)"
                         + (f", {min(window)}-{max(window)} with the window's other frames" if window != bins else "")
                         + f"; {min(secs):.2f}-{max(secs):.2f} s per tile, "
                         f"{1e6 * sum(secs) / max(sum(window), 1):.1f} us per haloed bin")
        return "\n".join(lines)


_active: Profile | None = None


@contextlib.contextmanager
def stage(name: str):
    """Times the block into the active profile (if any)."""
    if _active is None:
        yield
        return
    t, c = time.perf_counter(), time.process_time()
    try:
        yield
    finally:
        _active.add(name, time.perf_counter() - t, time.process_time() - c)


def record_tile(bins: int, core_bins: int, seconds: float, window_bins: int | None = None) -> None:
    """A tile of the active profile: the centre frame's bins with the halo and in the core, its seconds, and the
    bins of every frame of its window (default: the centre's alone)."""
    if _active is not None:
        _active.tiles.append((bins, core_bins, seconds, bins if window_bins is None else window_bins))


@contextlib.contextmanager
def profiling():
    """Activates a fresh Profile for the block and yields it."""
    global _active
    previous, _active = _active, Profile()
    try:
        yield _active
    finally:
        _active = previous

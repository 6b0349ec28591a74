"""Option parsers shared by several commands."""

from __future__ import annotations

import math

import click


class FiniteFloat(click.FloatRange):
    """click.FloatRange that refuses NaN and infinities (FloatRange lets NaN through its bounds: every comparison
    with it is false)."""

    def convert(self, value, param, ctx):
        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return rv


def int_list(text: str) -> tuple:
    """'4,16,64' -> (4, 16, 64); positive integers only."""
    try:
        vals = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise click.BadParameter(f"expected comma-separated integers, got {text!r}") from None
    if not vals or min(vals) < 1:
        raise click.BadParameter("sample counts must be positive")
    return vals


def width_range(text: str) -> tuple:
    """'2' -> (2.0, 2.0); '1.5:3' -> (1.5, 3.0): a filter width, or a range drawn from per scene, in [1, 6]."""
    parts = text.split(":")
    try:
        lo, hi = (float(parts[0]), float(parts[-1])) if len(parts) <= 2 else (None, None)
    except ValueError:
        lo = hi = None
    if lo is None or not 1.0 <= lo <= hi <= 6.0:
        raise click.BadParameter(f"expected a width W or a range A:B within 1..6 pixels, got {text!r}")
    return lo, hi


def device_option(what: str, note: str = ""):
    """The `--device auto|cpu|cuda` option of the commands that run the model (ranad_core.device.resolve)."""
    return click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True,
                        help=f"Where {what} (auto: the GPU when torch sees one and the CUDA RaNA kernels build for "
                             f"it, else the CPU; cuda: the GPU or an error saying what is missing).{note}")

"""Option parsers shared by several commands."""

from __future__ import annotations

import click


def int_list(text: str) -> tuple:
    """'4,16,64' -> (4, 16, 64); positive integers only."""
    try:
        vals = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise click.BadParameter(f"expected comma-separated integers, got {text!r}") from None
    if not vals or min(vals) < 1:
        raise click.BadParameter("sample counts must be positive")
    return vals

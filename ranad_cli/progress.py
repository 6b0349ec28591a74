"""Progress bars for long work: on stderr, only when there is more than one item or a terminal."""

from __future__ import annotations

from typing import Iterable, TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(items: Iterable[T], total: int, desc: str, unit: str = "frame") -> Iterable[T]:
    return tqdm(items, total=total, desc=desc, unit=unit, disable=total <= 1, leave=True, dynamic_ncols=True)

"""Frame sequences: file-name patterns, frame ranges, input expansion, output naming and farm shards.

Studios hand a denoiser whole shots, not single files, and name them in three conventions at once:
``name.####.exr`` (Nuke/Houdini, one ``#`` per digit of zero padding), ``name.%04d.exr`` (printf, also
unpadded ``%d``) and ``name.@@@@.exr`` (RV/Katana, one ``@`` per digit). This module turns such specs
into concrete :class:`Frame` paths so that the rest of ranad only ever sees plain file names.

Frame numbers are formatted exactly like printf's ``%0Nd`` in every convention (so frame ``-5`` with
four digits of padding is ``-005``: the sign counts toward the width). A file found on disk belongs
to a pattern only if formatting its frame number gives back its exact name, which keeps scanning and
formatting consistent: ``name.#.exr`` matches ``name.1001.exr`` (a number wider than the pad is fine)
but not ``name.0001.exr`` (that file would be frame 1 of ``name.####.exr``).

Pure Python, no image library: everything here is about names, so it is cheap to test.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from typing import Sequence, TypeVar

from ..errors import RanadError
from ..fileutil import not_a_file

__all__ = [
    "Frame",
    "is_pattern",
    "format_frame",
    "parse_frame_range",
    "expand_inputs",
    "output_path",
    "shard",
]

# One frame placeholder: a run of '#', a run of '@', or printf '%d' / '%0Nd' / '%Nd'.
_TOKEN = re.compile(r"#+|@+|%0*(\d*)d")

T = TypeVar("T")


@dataclass(frozen=True)
class Frame:
    """One input file; ``frame`` is its frame number, or None for a plain file name (no pattern). ``sequence``:
    the pattern it was found by (None for a plain name), so that a cross-frame window takes its neighbours from
    the frame's own shot when several shots are given (not part of equality)."""

    path: str
    frame: int | None = None
    sequence: str | None = field(default=None, compare=False)


def _find_token(pattern: str) -> re.Match[str] | None:
    """The frame placeholder in the *file name* part of ``pattern`` (folders may contain '#' or '@').

    More than one placeholder is refused rather than guessed at: ``shot.####.v##.exr`` is ambiguous.
    """
    base = os.path.basename(pattern)
    tokens = list(_TOKEN.finditer(base))
    if not tokens:
        return None
    if len(tokens) > 1:
        raise RanadError("more than one frame placeholder in this name (use one of ####, %04d, @@@@)", pattern)
    # Re-anchor the match on the whole string so callers can slice ``pattern`` directly.
    return _TOKEN.match(pattern, len(pattern) - len(base) + tokens[0].start())


def _pad_width(token: str) -> int:
    """Zero-pad width of a placeholder: count of '#'/'@', or N of '%0Nd' (0 for '%d')."""
    if token[0] in "#@":
        return len(token)
    digits = token[1:-1].lstrip("0")  # "%04d" -> "4"; "%d" -> ""
    return int(digits) if digits else 0


def is_pattern(s: str | os.PathLike) -> bool:
    """True if the file name part of ``s`` holds a frame placeholder (``####``, ``%04d``, ``%d``, ``@@@@``)."""
    s = os.fspath(s)
    return _TOKEN.search(os.path.basename(s)) is not None


def format_frame(pattern: str | os.PathLike, frame: int) -> str:
    """The file name of ``frame`` in ``pattern``, zero padded like printf's ``%0Nd``.

    ``format_frame("a.####.exr", 7) == "a.0007.exr"``; numbers wider than the pad are written in full.
    """
    pattern = os.fspath(pattern)
    m = _find_token(pattern)
    if m is None:
        raise RanadError("not a frame pattern (use name.####.exr, name.%04d.exr or name.@@@@.exr)", pattern)
    width = _pad_width(m.group(0))
    return f"{pattern[:m.start()]}{frame:0{width}d}{pattern[m.end():]}"


# One comma-separated part: "N", "A-B" or "A-BxS"; A, B may be negative ("-10--5").
_RANGE_PART = re.compile(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*(?:x\s*(\d+)\s*)?)?")


#: frames one range may name: a shot is thousands; 3-999999999 built a list of a billion before finding frame 3
#: missing
MAX_FRAMES = 1_000_000


def parse_frame_range(s: str) -> list[int]:
    """Frames named by a range string: ``1001-1010``, ``1001-1100x2`` (every 2nd), ``1001``, or
    comma-separated combinations such as ``1001-1005,1010``. Negative frames are allowed (``-5-5``).

    The result keeps the order written and drops repeats, so ``1-3,2`` is ``[1, 2, 3]``. A range whose
    end comes before its start, a zero step, or anything unparsable is a RanadError naming the string:
    silently processing the wrong frames on a farm costs far more than a refusal.
    """
    if not isinstance(s, str) or not s.strip():
        raise RanadError(f"empty frame range {s!r} (expected e.g. 1001-1010, 1001-1100x2 or 1001,1005)")
    frames: list[int] = []
    seen: set[int] = set()
    for part in s.split(","):
        m = _RANGE_PART.fullmatch(part)
        if m is None:
            raise RanadError(
                f"cannot read frame range {s!r} at {part.strip()!r} "
                "(expected e.g. 1001-1010, 1001-1100x2 or 1001,1005)",
                None,
            )
        start = int(m.group(1))
        end = int(m.group(2)) if m.group(2) is not None else start
        step = int(m.group(3)) if m.group(3) is not None else 1
        if step <= 0:
            raise RanadError(f"frame range {s!r}: step must be at least 1", None)
        if end < start:
            raise RanadError(f"frame range {s!r}: {part.strip()!r} ends before it starts", None)
        if len(frames) + len(range(start, end + 1, step)) > MAX_FRAMES:   # before a list of a billion frames
            raise RanadError(f"frame range {s!r} names more than {MAX_FRAMES} frames", None)
        for f in range(start, end + 1, step):
            if f not in seen:
                seen.add(f)
                frames.append(f)
    return frames


def _scan(pattern: str) -> list[int]:
    """Frame numbers of the files on disk that ``pattern`` names, sorted.

    A file counts only if ``format_frame`` gives its exact name back (see the module docstring).
    """
    m = _find_token(pattern)
    assert m is not None
    folder, base = os.path.split(pattern)
    offset = len(pattern) - len(base)
    prefix, suffix = base[: m.start() - offset], base[m.end() - offset :]
    regex = re.compile(re.escape(prefix) + r"(-?\d+)" + re.escape(suffix))
    try:
        names = os.listdir(folder or ".")
    except FileNotFoundError:
        raise RanadError("folder does not exist", folder) from None
    except NotADirectoryError:
        raise RanadError("is not a folder", folder) from None
    except PermissionError:
        raise RanadError("folder is not readable", folder) from None
    width = _pad_width(m.group(0))
    found = set()
    for name in names:
        hit = regex.fullmatch(name)
        if hit is None:
            continue
        n = int(hit.group(1))
        if f"{n:0{width}d}" == hit.group(1) and os.path.isfile(os.path.join(folder, name)):
            found.add(n)
    return sorted(found)


def expand_inputs(
    specs: Sequence[str | os.PathLike], frames: str | None = None, allow_gaps: bool = False
) -> list[Frame]:
    """Turn command-line input specs into concrete files, checking they exist before any work starts.

    - A pattern with ``frames`` (a :func:`parse_frame_range` string): exactly those frames; a missing one
      is ``RanadError("frame N is missing", its_path)`` so a farm job fails at once, not hours later.
    - A pattern without ``frames``: every matching frame on disk, sorted. None found is an error, and so
      is a hole inside the found range (named by its first missing frame: a half-rendered shot is
      usually a mistake) unless ``allow_gaps`` is true.
    - A plain name: that file, with ``frame=None``; ``frames`` does not apply to it.

    Repeated files (same absolute path) are kept once, at their first position.
    """
    wanted = parse_frame_range(frames) if frames is not None else None
    out: list[Frame] = []
    seen: set[str] = set()

    def add(path: str, frame: int | None, pattern: str | None = None) -> None:
        key = os.path.abspath(path)
        if key not in seen:
            seen.add(key)
            out.append(Frame(path, frame, pattern))

    for spec in specs:
        spec = os.fspath(spec)
        if not is_pattern(spec):
            if not os.path.isfile(spec):
                raise not_a_file(spec)
            add(spec, None)
            continue
        if wanted is not None:
            for n in wanted:
                path = format_frame(spec, n)
                if not os.path.isfile(path):
                    raise RanadError(f"frame {n} is missing", path)
                add(path, n, spec)
            continue
        found = _scan(spec)
        if not found:
            raise RanadError("no frames match this pattern", spec)
        if not allow_gaps:
            present = set(found)
            for n in range(found[0], found[-1] + 1):
                if n not in present:
                    raise RanadError(
                        f"frame {n} is missing (found frames {found[0]}-{found[-1]} with gaps; "
                        "give a frame range to choose frames)",
                        format_frame(spec, n),
                    )
        for n in found:
            add(format_frame(spec, n), n, spec)
    return out


def output_path(
    out_spec: str | os.PathLike, frame: Frame, n_inputs: int, ext: str | None = None
) -> str:
    """Where the result for input ``frame`` goes.

    - ``out_spec`` is a pattern: the input's frame number fills it (an input without a frame number
      cannot, which is an error rather than a guess).
    - ``out_spec`` is an existing folder (or ends with a path separator): the input's file name inside
      it, with its extension replaced by ``ext`` (``".png"`` or ``"png"``) when given. Writing onto the
      input file itself is refused, since the input would be lost if the job died half-way.
    - Otherwise ``out_spec`` is one file, which only makes sense for a single input: several inputs
      written to one name would overwrite each other.
    """
    out_spec = os.fspath(out_spec)
    if is_pattern(out_spec):
        if frame.frame is None:
            raise RanadError(f"has no frame number to fill the output pattern {out_spec}", frame.path)
        path = format_frame(out_spec, frame.frame)
    elif os.path.isdir(out_spec) or out_spec.endswith((os.sep, "/")):
        if not os.path.isdir(out_spec):
            raise RanadError("output folder does not exist", out_spec)
        name = os.path.basename(frame.path)
        if ext is not None:
            name = os.path.splitext(name)[0] + (ext if ext.startswith(".") else "." + ext)
        path = os.path.join(out_spec, name)
    elif n_inputs > 1:
        raise RanadError("several inputs need an output pattern (name.####.exr) or a folder", out_spec)
    else:
        path = out_spec
    if os.path.exists(frame.path) and os.path.exists(path) and os.path.samefile(path, frame.path):
        raise RanadError("output would overwrite the input; choose another name", path)
    return path


def output_paths(out_spec: str | os.PathLike, frames: Sequence[Frame], ext: str | None = None) -> list[str]:
    """:func:`output_path` of every input, refusing two inputs that would be written to the same file (two
    shots' frame 1 into one pattern, two folders' x.exr into one folder): the second would silently replace the
    first. The same input listed again (one file's parts, each with its AOV cache) goes to the same output."""
    paths, first = [], {}
    n_inputs = len({os.path.abspath(f.path) for f in frames})
    for f in frames:
        path = output_path(out_spec, f, n_inputs, ext)
        key = os.path.normcase(os.path.abspath(path))
        if key in first and os.path.abspath(first[key]) != os.path.abspath(f.path):
            raise RanadError(f"{first[key]} and {f.path} would both be written to this output; give each its own "
                             f"pattern or folder", path)
        first[key] = f.path
        paths.append(path)
    return paths


def shard(items: Sequence[T], spec: str) -> list[T]:
    """The part of ``items`` that farm task ``I`` of ``N`` handles, from a spec ``"I/N"`` (I is 1-based).

    Task I takes items I-1, I-1+N, I-1+2N, ... so the N tasks cover every item exactly once and, for
    a shot, each task gets frames spread over the whole range (similar cost per task).
    """
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", spec or "")
    if m is None:
        raise RanadError(f"cannot read shard {spec!r} (expected I/N, e.g. 1/4)", None)
    i, n = int(m.group(1)), int(m.group(2))
    if n < 1 or not 1 <= i <= n:
        raise RanadError(f"shard {spec!r}: need 1 <= I <= N", None)
    return list(items[i - 1 :: n])

"""The EXR byte codecs that deep parts use: NONE, RLE, ZIPS and ZIP (one zlib stream per chunk).

RLE and ZIP(S) both first split the bytes into even and odd halves and apply a delta predictor, exactly as
OpenEXR's ImfZip/ImfRle do; they are written here with numpy so whole chunks are processed without Python
loops over bytes. A packed block as large as its unpacked size is stored raw (OpenEXR's rule).
"""

from __future__ import annotations

import zlib

import numpy as np

NONE, RLE, ZIPS, ZIP = 0, 1, 2, 3
ZLIB_LEVEL = 4  # OpenEXR's default zipCompressionLevel


class CodecError(ValueError):
    """The compressed bytes of a chunk cannot be decoded (corrupt or truncated data)."""


def _unpredict_deinterleave(t: np.ndarray) -> bytes:
    d = t.copy()
    d[1:] -= 128  # uint8 wraps modulo 256, as the C code does
    t = np.cumsum(d, dtype=np.uint8)
    out = np.empty_like(t)
    half = (t.size + 1) // 2
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return out.tobytes()


def _interleave_predict(raw: bytes) -> bytes:
    b = np.frombuffer(raw, dtype=np.uint8)
    t = np.concatenate([b[0::2], b[1::2]])
    d = t.copy()
    d[1:] = t[1:] - t[:-1] + 128
    return d.tobytes()


def _rle_decode(data: bytes, expected: int) -> np.ndarray:
    """OpenEXR RLE: a signed count byte; negative -> that many literal bytes, else count+1 repeats."""
    src = np.frombuffer(data, dtype=np.int8)
    out = np.empty(expected, dtype=np.uint8)
    pos = opos = 0
    n = src.size
    raw = np.frombuffer(data, dtype=np.uint8)
    # The run structure is inherently sequential; runs are long in practice, so a loop over runs is cheap.
    while pos < n:
        c = int(src[pos])
        if c < 0:
            cnt = -c
            if pos + 1 + cnt > n or opos + cnt > expected:
                raise CodecError("RLE literal run overflows")
            out[opos:opos + cnt] = raw[pos + 1:pos + 1 + cnt]
            pos += 1 + cnt
        else:
            cnt = c + 1
            if pos + 1 >= n or opos + cnt > expected:
                raise CodecError("RLE repeat run overflows")
            out[opos:opos + cnt] = raw[pos + 1]
            pos += 2
        opos += cnt
    if opos != expected:
        raise CodecError(f"RLE data decodes to {opos} bytes, expected {expected}")
    return out


def decompress(code: int, data: bytes, expected: int) -> bytes:
    """Decode one packed block of a deep chunk (sample-count table or sample data)."""
    if expected == 0:
        return b""
    if code == NONE or len(data) == expected:
        if len(data) != expected:
            raise CodecError(f"uncompressed block has {len(data)} bytes, expected {expected}")
        return data
    if code in (ZIPS, ZIP):
        try:
            raw = zlib.decompress(data)
        except zlib.error as e:
            raise CodecError(f"zlib: {e}") from None
        if len(raw) != expected:
            raise CodecError(f"zip block decodes to {len(raw)} bytes, expected {expected}")
        return _unpredict_deinterleave(np.frombuffer(raw, dtype=np.uint8))
    if code == RLE:
        return _unpredict_deinterleave(_rle_decode(data, expected))
    raise CodecError(f"compression {code} is not handled by the fast codec")


def compress(code: int, raw: bytes) -> bytes:
    """Encode one block; returns ``raw`` itself when compression would not make it smaller."""
    if code == NONE or not raw:
        return raw
    if code in (ZIPS, ZIP):
        packed = zlib.compress(_interleave_predict(raw), ZLIB_LEVEL)
        return packed if len(packed) < len(raw) else raw
    raise CodecError(f"compression {code} cannot be written by the fast codec")

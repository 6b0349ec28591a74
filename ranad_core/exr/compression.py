"""The EXR byte codecs that deep parts use: NONE, RLE, ZIPS and ZIP (one zlib stream per chunk).

RLE and ZIP(S) both first split the bytes into even and odd halves and apply a delta predictor, exactly as
OpenEXR's ImfZip/ImfRle do; they are written here with numpy so whole chunks are processed without Python
loops over bytes. A packed block as large as its unpacked size is stored raw (OpenEXR's rule).
"""

from __future__ import annotations

import sys
import zlib

import numpy as np

NONE, RLE, ZIPS, ZIP = 0, 1, 2, 3
ZLIB_LEVEL = 4  # OpenEXR's default zipCompressionLevel


class CodecError(ValueError):
    """The compressed bytes of a chunk cannot be decoded (corrupt or truncated data)."""


TORCH_FROM = 1 << 16   # bytes: blocks from this size take torch's prefix sum when torch is loaded (_torch)


def _torch():
    """torch, where the process has already imported it (the command line always has), else None. Its uint8
    prefix sum runs at about 3 GB/s against numpy's 0.5 GB/s (numpy's uint8 accumulate is a generic loop): undoing
    the predictor took more CPU than zlib's inflate itself (377 against 721 MB/s on a 1080p frame's bins). Never
    imported here: reading a file with the codec alone does not pay torch's import."""
    return sys.modules.get("torch")


def _unpredict_deinterleave(t: np.ndarray) -> bytes:
    d = t.copy()
    d[1:] -= 128  # uint8 wraps modulo 256, as the C code does
    torch = _torch() if d.size >= TORCH_FROM else None
    if torch is not None:   # the same bytes (a serial loop in torch too: no threads of its own inside ours)
        t = torch.cumsum(torch.from_numpy(d), 0, dtype=torch.uint8).numpy()
    else:
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
    if code == RLE:
        packed = _rle_encode(np.frombuffer(_interleave_predict(raw), dtype=np.uint8))
        return packed if len(packed) < len(raw) else raw
    raise CodecError(f"compression {code} cannot be written by the fast codec")


RLE_MAX_RUN = 127  # bytes per run (OpenEXR's MAX_RUN_LENGTH); a repeat needs at least 3 equal bytes


def _rle_encode(raw: np.ndarray) -> bytes:
    """OpenEXR RLE, vectorised: runs of 3 or more equal bytes become (count - 1, byte), everything between
    them literal runs (-count, bytes...), each run at most RLE_MAX_RUN bytes (OpenEXR's rleUncompress reads
    it)."""
    n = raw.size
    if n == 0:
        return b""
    starts = np.r_[0, np.flatnonzero(raw[1:] != raw[:-1]) + 1]
    lengths = np.diff(np.r_[starts, n])
    rep = lengths >= 3
    # segments: each repeated run alone, consecutive short runs merged into one literal segment
    new = np.ones(starts.size, bool)
    new[1:] = rep[1:] | rep[:-1]
    seg = np.cumsum(new) - 1
    seg_start = starts[new]
    seg_len = np.bincount(seg, weights=lengths).astype(np.int64)
    seg_rep = rep[new]
    # pieces of at most RLE_MAX_RUN bytes
    npieces = -(-seg_len // RLE_MAX_RUN)
    first = np.repeat(np.cumsum(npieces) - npieces, npieces)
    k = np.arange(int(npieces.sum())) - first
    owner = np.repeat(np.arange(seg_len.size), npieces)
    pstart = seg_start[owner] + k * RLE_MAX_RUN
    plen = np.minimum(RLE_MAX_RUN, seg_len[owner] - k * RLE_MAX_RUN)
    prep = seg_rep[owner]
    size = 1 + np.where(prep, 1, plen)
    pos = np.cumsum(size) - size
    out = np.empty(int(size.sum()), np.uint8)
    out[pos] = np.where(prep, plen - 1, 256 - plen).astype(np.uint8)
    out[pos[prep] + 1] = raw[pstart[prep]]
    ls, ll, lp = pstart[~prep], plen[~prep], pos[~prep] + 1
    within = np.arange(int(ll.sum())) - np.repeat(np.cumsum(ll) - ll, ll)
    out[np.repeat(lp, ll) + within] = raw[np.repeat(ls, ll) + within]
    return out.tobytes()

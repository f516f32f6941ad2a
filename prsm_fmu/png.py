"""PNG files of RGBA pixels: the figures' encoder.

Pillow's PNG encoder (through ``savefig``) chooses a row filter per row by trying all five, which
costs more than the compression itself: ~20 ms of CPU per figure at zlib level 1, against ~8 ms
here, where every row is stored unfiltered (filter type 0) and compressed at zlib level 1.  The
pixels are the same (PNG is lossless; the files are ~10 % larger).  The chunks written: IHDR
(8-bit RGBA, no interlace), pHYs (the dpi as pixels per metre, as Pillow writes it), tEXt
(``key`` → ``value``, Latin-1, as matplotlib's ``Software`` entry), IDAT, IEND.
"""

from __future__ import annotations

import struct
import zlib
from typing import Mapping

import numpy as np

__all__ = ["encode_rgba", "SIGNATURE"]

#: the eight bytes every PNG file starts with
SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind))))


def encode_rgba(pixels: np.ndarray, dpi: float, text: Mapping[str, str] | None = None,
                level: int = 1) -> bytes:
    """The PNG file of ``pixels`` (rows × columns × 4, uint8, RGBA, top row first).

    Parameters
    ----------
    pixels : ndarray
        The image, shape (height, width, 4), dtype uint8.
    dpi : float
        Resolution [dots per inch], stored as pixels per metre (pHYs).
    text : mapping, optional
        tEXt entries (keys and values of Latin-1 text).
    level : int
        zlib compression level, 0..9.
    """
    px = np.asarray(pixels)
    if px.ndim != 3 or px.shape[2] != 4 or px.dtype != np.uint8:
        raise ValueError(f"pixels: shape {px.shape}, dtype {px.dtype}: must be (height, width, 4) "
                         "uint8 (RGBA)")
    h, w = px.shape[:2]
    if not (1 <= h < 2**31 and 1 <= w < 2**31):
        raise ValueError(f"pixels: {w} × {h}: each side must be in [1, 2**31 - 1]")
    if not (np.isfinite(dpi) and dpi > 0):
        raise ValueError(f"dpi = {dpi!r}: must be a finite number > 0")
    rows = np.empty((h, 1 + 4 * w), dtype=np.uint8)
    rows[:, 0] = 0                                   # filter type 0 (none) on every row
    rows[:, 1:] = px.reshape(h, 4 * w)
    ppm = int(dpi / 0.0254 + 0.5)                    # as Pillow rounds it
    out = [SIGNATURE,
           _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)),
           _chunk(b"pHYs", struct.pack(">IIB", ppm, ppm, 1))]
    for key, value in (text or {}).items():
        out.append(_chunk(b"tEXt", key.encode("latin-1") + b"\0" + value.encode("latin-1")))
    out += [_chunk(b"IDAT", zlib.compress(rows.data, level)), _chunk(b"IEND", b"")]
    return b"".join(out)

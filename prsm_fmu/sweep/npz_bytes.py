"""The bytes of an uncompressed ``.npz`` file, laid out in memory in one pass.

``numpy.savez`` writes each array through :mod:`zipfile` (a member opened, its ``.npy`` header
formatted, the data written, the member's header sought back to and rewritten): for the 24
series of 1001 samples of a sweep point that costs about as much as the point's own
simulation outside the compiled loop.  :func:`npz_chunks` gives the same file content —
a ZIP archive (PKWARE APPNOTE 6.3, §4.3) of stored (uncompressed) members ``<name>.npy``, each
the array in the ``.npy`` format 1.0 with the header numpy itself writes
(:func:`numpy.lib.format.write_array_header_1_0`) — as a list of byte strings for one write.
``numpy.load`` reads it as it reads ``numpy.savez``'s (tests/test_sweep_series_files.py).

Only what ``numpy.savez`` would store without pickling and without ZIP64 takes this path:
plain ``numpy.ndarray`` values of a non-object dtype whose ``.npy`` header fits format 1.0,
ASCII names, fewer than 65 535 members and an archive below 4 GiB; for anything else
:func:`npz_chunks` returns None and the caller writes with ``numpy.savez``.
"""

from __future__ import annotations

import functools
import io
import struct
import time
import zlib
from typing import Mapping

import numpy as np
from numpy.lib import format as npy_format

__all__ = ["npz_chunks"]

# APPNOTE 6.3 §4.3.7 (local file header), §4.3.12 (central directory header), §4.3.16 (end of
# central directory record); little-endian, no padding
_LOCAL = struct.Struct("<IHHHHHIIIHH")
_CENTRAL = struct.Struct("<IHHHHHHIIIHHHHHII")
_END = struct.Struct("<IHHHHIIH")
_VERSION = 20                       # 2.0: stored members, no ZIP64
_MADE_BY = (3 << 8) | _VERSION      # made on Unix (external attributes hold the mode)
_MODE = 0o600 << 16                 # the mode zipfile gives a member it writes
_LIMIT = 0xFFFFFFFF                 # largest size and offset without ZIP64
_MAX_MEMBERS = 0xFFFF


@functools.lru_cache(maxsize=64)
def _header(descr: str, fortran_order: bool, shape: tuple[int, ...]) -> bytes | None:
    """numpy's own ``.npy`` 1.0 header (magic included) of such an array, or None if it does
    not fit format 1.0."""
    buf = io.BytesIO()
    try:
        npy_format.write_array_header_1_0(
            buf, {"descr": descr, "fortran_order": fortran_order, "shape": shape})
    except ValueError:
        return None
    return buf.getvalue()


def _dos_time(seconds: float) -> tuple[int, int]:
    """(time, date) of ``seconds`` in MS-DOS form (local time, 2 s resolution), as zipfile."""
    t = time.localtime(seconds)
    year = max(t.tm_year, 1980)
    return ((t.tm_hour << 11) | (t.tm_min << 5) | (t.tm_sec // 2),
            ((year - 1980) << 9) | (t.tm_mon << 5) | t.tm_mday)


def npz_chunks(arrays: Mapping[str, object]) -> list[bytes] | None:
    """The content of ``numpy.savez(file, **arrays)`` as byte strings to write in order.

    Parameters
    ----------
    arrays : mapping of str to numpy.ndarray
        The members: ``name`` is stored as ``name.npy``.

    Returns
    -------
    list of bytes or None
        The file's bytes in pieces, or None where the module docstring says (the caller
        writes with ``numpy.savez``).
    """
    if len(arrays) >= _MAX_MEMBERS:
        return None
    dos_time, dos_date = _dos_time(time.time())
    chunks: list[bytes] = []
    central: list[bytes] = []
    offset = 0
    for key, arr in arrays.items():
        if type(arr) is not np.ndarray or arr.dtype.hasobject or not key.isascii():
            return None
        header_data = npy_format.header_data_from_array_1_0(arr)
        header = _header(header_data["descr"], header_data["fortran_order"],
                         header_data["shape"])
        if header is None:
            return None
        # the data as numpy.lib.format.write_array lays it out
        data = arr.tobytes(order="F" if header_data["fortran_order"] else "C")
        name = f"{key}.npy".encode("ascii")
        size = len(header) + len(data)
        crc = zlib.crc32(data, zlib.crc32(header))
        if offset + _LOCAL.size + len(name) + size > _LIMIT:
            return None
        chunks.append(_LOCAL.pack(0x04034B50, _VERSION, 0, 0, dos_time, dos_date, crc, size,
                                  size, len(name), 0))
        chunks += [name, header, data]
        central.append(_CENTRAL.pack(0x02014B50, _MADE_BY, _VERSION, 0, 0, dos_time, dos_date,
                                     crc, size, size, len(name), 0, 0, 0, 0, _MODE, offset)
                       + name)
        offset += _LOCAL.size + len(name) + size
    central_size = sum(len(c) for c in central)
    if offset + central_size > _LIMIT:
        return None
    chunks += central
    chunks.append(_END.pack(0x06054B50, 0, 0, len(central), len(central), central_size, offset,
                            0))
    return chunks

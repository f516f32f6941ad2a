"""Write an output file whole or not at all: a temporary file in the same folder, renamed.

A command interrupted (Ctrl-C) or failing while it writes leaves the previous file, or none,
never a half-written one: :func:`atomic_path` hands out a temporary name next to the target
(same folder, so the rename is atomic on POSIX file systems; same extension, so matplotlib and
numpy pick the right format) and renames it over the target only when the block completes;
:func:`write_atomic` does the same for bytes already in memory, with one open, write and
rename.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

__all__ = ["atomic_path", "write_atomic"]


@contextmanager
def _beside(path: str | os.PathLike) -> Iterator[tuple[int, str]]:
    """(open descriptor, name) of a new empty file next to ``path``:
    ``.<name>.<random>.part<ext>``, created exclusively with the mode ``open()`` gives (0666
    less the umask: the kernel applies it).  The block closes the descriptor; on success the
    file is renamed to ``path``, else removed."""
    target = Path(path)
    while True:
        tmp = str(target.parent / f".{target.name}.{os.urandom(6).hex()}.part{target.suffix}")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:         # 48 random bits taken: draw again
            continue
    try:
        yield fd, tmp
        os.replace(tmp, target)
    except BaseException:
        try:
            os.remove(tmp)
        except FileNotFoundError:
            pass
        raise


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """Yield a temporary file name; on success rename it to ``path``, else remove it.

    Parameters
    ----------
    path : str or path-like
        The file to write.

    Yields
    ------
    str
        The temporary file to write instead (it exists, empty).
    """
    with _beside(path) as (fd, tmp):
        os.close(fd)
        yield tmp


def write_atomic(path: str | os.PathLike, chunks: Iterable[bytes]) -> None:
    """Write ``chunks`` one after the other as the file ``path``, whole or not at all.

    Parameters
    ----------
    path : str or path-like
        The file to write.
    chunks : iterable of bytes
        Its content.
    """
    with _beside(path) as (fd, _):
        try:
            data = memoryview(b"".join(chunks))
            while data:                 # os.write may write less than it is given
                data = data[os.write(fd, data):]
        finally:
            os.close(fd)

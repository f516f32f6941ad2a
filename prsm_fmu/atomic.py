"""Write an output file whole or not at all: a temporary file in the same folder, renamed.

A command interrupted (Ctrl-C) or failing while it writes leaves the previous file, or none,
never a half-written one: :func:`atomic_path` hands out a temporary name next to the target
(same folder, so the rename is atomic on POSIX file systems; same extension, so matplotlib and
numpy pick the right format) and renames it over the target only when the block completes.
"""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_path"]


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
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".part{target.suffix}",
                               dir=target.parent)
    os.close(fd)
    # mkstemp makes it private (0600): give it the mode open() would, 0666 less the umask
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        try:
            os.remove(tmp)
        except FileNotFoundError:
            pass
        raise

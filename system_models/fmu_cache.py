"""An FMU's files unpacked once and kept: a run loads the FMU from its unpacked copy.

Unzipping the PRSM FMU (136 members, ~2.5 MB) took ~0.07 s of every ``prsm-ema run`` before
the co-simulation could start.  The copy is kept under the SHA-256 of the FMU file's bytes
(never stale: a rebuilt FMU is another key), in a directory of the user's own (mode 0700, in the
system's temporary directory, as :func:`fmu_build.native.cached_library` keeps its libraries), so
no other user can put a library there.  A copy is unpacked into a temporary directory beside it
and renamed into place whole: a run that races another finds either no copy or a complete one
(the loser of the race removes its own).

A second instance of the same FMU alive in the same process gets a private copy (removed when it
ends), as before this cache: two instances never share one loaded library.  Where the cache
cannot be used (a directory not the user's own, a read-only file system) every instance gets a
private copy, also as before.
"""

from __future__ import annotations

import getpass
import hashlib
import os
import shutil
import stat
import tempfile
import threading
from pathlib import Path

__all__ = ["cache_root", "unpack", "release"]

#: the cached copies alive in this process (a second instance of the same FMU gets its own)
_in_use: set[str] = set()
_lock = threading.Lock()


def cache_root() -> Path:
    """``<temporary directory>/prsm-fmu-unpacked-<user>``: where the copies are kept."""
    return Path(tempfile.gettempdir()) / f"prsm-fmu-unpacked-{getpass.getuser()}"


def _own_private_dir(path: Path) -> bool:
    """``path`` is a real directory (no symlink) of this user, closed to everyone else (never
    on a system without POSIX owners, Windows: every instance gets a private copy there)."""
    if not hasattr(os, "getuid"):
        return False
    try:
        st = os.lstat(path)
    except OSError:
        return False
    return (stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid()
            and stat.S_IMODE(st.st_mode) & 0o077 == 0)


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:32]


def _private_copy(path: Path) -> str:
    from fmpy import extract

    return extract(str(path))


def _complete(unzipdir: Path) -> bool:
    """The copy has the FMU's model description (the last file :func:`_cached_copy` checks for
    before renaming a copy into place)."""
    return (unzipdir / "modelDescription.xml").is_file()


def _cached_copy(path: Path) -> str | None:
    """The cached copy of the FMU at ``path`` (unpacked now if missing), or None where the
    cache cannot be used."""
    import zipfile

    root = cache_root()
    try:
        root.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError:
        return None
    if not _own_private_dir(root):
        return None
    target = root / f"{path.stem}-{_digest(path)}"
    if _complete(target):
        return str(target)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.stem}-", dir=root))
        try:
            with zipfile.ZipFile(path) as z:
                z.extractall(tmp)
            if not _complete(tmp):
                return None
            try:
                os.rename(tmp, target)
            except OSError:
                # another run renamed its copy into place first (a non-empty target), or an
                # incomplete leftover is there: use a complete one, else none
                if not _complete(target):
                    return None
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    except (OSError, zipfile.BadZipFile):
        return None
    return str(target)


def unpack(path: str | os.PathLike) -> tuple[str, bool]:
    """(directory, private): the FMU at ``path`` unpacked.  ``private``: a copy of this
    instance alone, to remove with :func:`release`; else the shared cached copy (module
    docstring), which :func:`release` only marks free."""
    p = Path(path)
    cached = _cached_copy(p)
    with _lock:
        shared = cached is not None and cached not in _in_use
        if shared:
            _in_use.add(cached)
    return (cached, False) if shared else (_private_copy(p), True)


def release(unzipdir: str, private: bool) -> None:
    """The instance that used ``unzipdir`` has ended: a private copy is removed, the cached one
    is free for the next instance of this process."""
    if private:
        shutil.rmtree(unzipdir, ignore_errors=True)
    else:
        with _lock:
            _in_use.discard(unzipdir)

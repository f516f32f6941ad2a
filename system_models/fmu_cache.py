"""An FMU's files unpacked once and kept: a run loads the FMU from its unpacked copy.

Unzipping the PRSM FMU (136 members, ~2.5 MB) took ~0.07 s of every ``prsm-ema run`` before
the co-simulation could start.  The copy is kept under the SHA-256 of the FMU file's bytes
(never stale: a rebuilt FMU is another key), in a directory of the user's own (mode 0700, in the
system's temporary directory, :func:`prsm_fmu.compiled.user_cache_dir`, as
:func:`prsm_fmu.compiled.cached_library` keeps its libraries), so no other user can put a
library there.  A copy is unpacked into a temporary directory beside it
and renamed into place whole: a run that races another finds either no copy or a complete one
(the loser of the race removes its own).

A second instance of the same FMU alive in the same process gets a private copy (removed when it
ends), as before this cache: two instances never share one loaded library.  Where the cache
cannot be used (a directory not the user's own, a read-only file system, no POSIX owners or
locks) every instance gets a private copy, also as before.

The copies do not pile up (each rebuild of an FMU is a new one, ~6 MB): an instance holds a
shared ``flock`` on its copy's directory while it lives, and whenever a new copy is made, the
copies no instance holds and none has used for :data:`PRUNE_AFTER` are removed (each under an
exclusive lock taken without waiting, so never one in use), with the half-unpacked leftovers of
runs killed that long ago.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import stat
import tempfile
import threading
import time
from pathlib import Path

__all__ = ["cache_root", "unpack", "release", "PRUNE_AFTER"]

#: a copy no instance holds and none has used for this long [s] is removed when a new copy is
#: made
PRUNE_AFTER = 3600.0

#: the cached copies alive in this process -> the descriptor holding their shared lock (a
#: second instance of the same FMU gets a private copy)
_in_use: dict[str, int] = {}
_lock = threading.Lock()


def cache_root() -> Path:
    """``<temporary directory>/prsm-fmu-unpacked-<user>``: where the copies are kept
    (:func:`prsm_fmu.compiled.user_cache_dir`)."""
    from prsm_fmu.compiled import user_cache_dir

    return user_cache_dir("unpacked")


def _own_private_dir(path: Path) -> bool:
    """``path`` is a real directory (no symlink) of this user, closed to everyone else (never
    on a system without POSIX owners or ``flock``, Windows: every instance gets a private copy
    there)."""
    if not hasattr(os, "getuid"):
        return False
    try:
        import fcntl  # noqa: F401
    except ImportError:
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
    _prune(root, keep=target)
    return str(target)


def _held(target: Path) -> int | None:
    """An open descriptor of the copy ``target`` holding a shared lock on it (its use marked
    now), or None if the copy is gone (removed while this waited for the lock)."""
    import fcntl

    try:
        fd = os.open(target, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH)
        # the directory locked is the one at ``target`` still, and whole
        if os.fstat(fd).st_ino == os.stat(target).st_ino and _complete(target):
            os.utime(target)
            return fd
    except OSError:
        pass
    os.close(fd)
    return None


def _prune(root: Path, keep: Path) -> None:
    """Remove the copies under ``root`` (but ``keep``) that no instance holds and none has used
    for :data:`PRUNE_AFTER`, and half-unpacked leftovers as old."""
    import fcntl

    now = time.time()
    for d in root.iterdir():
        try:
            if d == keep or now - d.lstat().st_mtime < PRUNE_AFTER:
                continue
        except OSError:
            continue
        if d.name.startswith("."):                   # a killed run's half-unpacked copy
            shutil.rmtree(d, ignore_errors=True)
            continue
        try:
            fd = os.open(d, os.O_RDONLY)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:                              # an instance holds it
            os.close(fd)
            continue
        try:
            shutil.rmtree(d, ignore_errors=True)
        finally:
            os.close(fd)


def unpack(path: str | os.PathLike) -> tuple[str, bool]:
    """(directory, private): the FMU at ``path`` unpacked.  ``private``: a copy of this
    instance alone, to remove with :func:`release`; else the shared cached copy (module
    docstring), held (its shared lock) until :func:`release`."""
    p = Path(path)
    for _ in range(2):                   # twice: a copy removed as this took it is made again
        cached = _cached_copy(p)
        if cached is None:
            break
        with _lock:
            if cached in _in_use:        # a live instance of this process has it
                break
            fd = _held(Path(cached))
            if fd is not None:
                _in_use[cached] = fd
                return cached, False
    return _private_copy(p), True


def release(unzipdir: str, private: bool) -> None:
    """The instance that used ``unzipdir`` has ended: a private copy is removed; the cached one
    is let go (its lock released: free for the next instance, and for a prune once unused
    long enough)."""
    if private:
        shutil.rmtree(unzipdir, ignore_errors=True)
    else:
        with _lock:
            fd = _in_use.pop(unzipdir, None)
        if fd is not None:
            os.close(fd)                 # the shared lock goes with it

"""Shared libraries of the C sources for Windows, Linux and macOS, cross-compiled on Linux.

The compiler is Zig's C compiler (clang with the C libraries of every target built in), from
PyPI (``pip install ziglang``, in the ``fmu`` extra): ``python -m ziglang cc -target ...``.
It builds, on this machine and without a vendor SDK,

========== ====================== =========================== ==========================
FMI 2.0    FMI 3.0                target                      C runtime allowed
========== ====================== =========================== ==========================
linux64    x86_64-linux           x86_64-linux-gnu.2.17       libc.so.6, libm.so.6 (glibc ≤ 2.17)
win64      x86_64-windows         x86_64-windows-gnu          UCRT (api-ms-win-crt-*.dll), KERNEL32.dll
darwin64   x86_64-darwin,         x86_64-macos, aarch64-macos /usr/lib/libSystem.B.dylib
           aarch64-darwin         (darwin64: one universal file of both)
========== ====================== =========================== ==========================

glibc 2.17 is the manylinux2014 baseline (RHEL/CentOS 7): a library linked against it loads on
every later glibc.  Every library built is read back (:mod:`fmu_build.binary_check`) and the
build fails naming what is wrong: a function not exported, a library other than the platform's
C runtime, a glibc symbol version above 2.17, a wrong architecture.

Zig keeps what it compiled (the C runtimes of each target: minutes the first time for Windows)
in ``ZIG_GLOBAL_CACHE_DIR``; unless set, that is ``<user cache>/prsm-fmu/zig`` (``XDG_CACHE_HOME``
or ``~/.cache``), and ``ZIG_LOCAL_CACHE_DIR`` is the build's temporary directory.  Each library
built is kept in ``<user cache>/prsm-fmu/libraries`` under the hash of everything it is built
from (every file of the source directory, target, flags, definitions, Zig's version) and reused,
checked again, when the same library is built again.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import struct
import subprocess
import sys
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

from prsm_fmu.compiled import COMPILE_FLAGS   # the flags of every target (one definition)

from . import binary_check
from .errors import BuildError

__all__ = ["Platform", "PLATFORMS", "FMI2_PLATFORMS", "PYTHONFMU_PLATFORMS", "compile_for",
           "check_library", "zig_available", "universal_macho", "COMPILE_FLAGS"]


@dataclass(frozen=True)
class Platform:
    """One FMI 2.0 platform folder and how to build and check its library."""

    name: str                                  #: FMI 2.0 folder under binaries/
    fmi3: tuple[str, ...]                      #: FMI 3.0 folders (one per architecture)
    targets: tuple[str, ...]                   #: Zig targets, in the order of ``arches``
    arches: tuple[str, ...]                    #: architectures (binary_check.Slice.arch)
    suffix: str                                #: file name suffix of the library
    libraries: tuple[str, ...]                 #: libraries it may load (``*``: any suffix)
    max_glibc: tuple[int, ...] | None = None   #: highest glibc symbol version (Linux)
    #: linker flags; ``{name}`` is the library's file name (macOS: its install name, which
    #: would otherwise be the temporary path it was linked at)
    link_flags: tuple[str, ...] = ()


PLATFORMS = {
    "linux64": Platform("linux64", ("x86_64-linux",), ("x86_64-linux-gnu.2.17",), ("x86_64",),
                        ".so", ("libc.so.6", "libm.so.6"), (2, 17)),
    "win64": Platform("win64", ("x86_64-windows",), ("x86_64-windows-gnu",), ("x86_64",), ".dll",
                      ("api-ms-win-crt-*", "KERNEL32.dll")),
    "darwin64": Platform("darwin64", ("x86_64-darwin", "aarch64-darwin"),
                         ("x86_64-macos", "aarch64-macos"), ("x86_64", "arm64"), ".dylib",
                         ("/usr/lib/libSystem.B.dylib",),
                         link_flags=("-Wl,-install_name,@rpath/{name}",)),
}
#: what ``prsm-fmu-build --native`` builds by default
FMI2_PLATFORMS = tuple(PLATFORMS)
#: the platforms pythonfmu 0.7 ships its wrapper for (its resources/binaries/)
PYTHONFMU_PLATFORMS = ("linux64", "win64")


def zig_available() -> bool:
    """Whether ``python -m ziglang`` can run (the ``ziglang`` package is installed)."""
    try:
        import ziglang  # noqa: F401
    except ImportError:
        return False
    return True


def _user_cache() -> Path:
    """``<XDG_CACHE_HOME or ~/.cache>/prsm-fmu``."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "prsm-fmu"


def _zig_env(local_cache: Path) -> dict[str, str]:
    env = dict(os.environ)
    env.setdefault("ZIG_GLOBAL_CACHE_DIR", str(_user_cache() / "zig"))
    env.setdefault("ZIG_LOCAL_CACHE_DIR", str(local_cache))
    return env


def _library_key(platform: Platform, src: Path, sources: tuple[str, ...],
                 defines: tuple[str, ...], name: str) -> str:
    """Hash of everything a library is built from: every file in ``src`` (sources and
    headers), the sources compiled, the targets, flags, definitions, link flags and Zig's
    version."""
    from importlib.metadata import version

    h = hashlib.sha256()
    for part in (repr((platform, sources, defines, name, COMPILE_FLAGS)), version("ziglang")):
        h.update(part.encode() + b"\0")
    for f in sorted(src.iterdir()):
        if f.is_file():
            h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:32]


def universal_macho(parts: list[bytes]) -> bytes:
    """A universal ("fat") Mach-O file of thin 64-bit Mach-O files, each at a 16 KiB boundary
    (what ``lipo -create`` writes; macOS loads the slice of its CPU)."""
    align = 14
    header = struct.pack(">II", 0xCAFEBABE, len(parts))
    offset = 1 << align
    entries, body = [], b""
    for p in parts:
        cpu, sub = struct.unpack_from("<ii", p, 4)
        pad = -(offset + len(body)) % (1 << align)
        body += b"\0" * pad
        entries.append(struct.pack(">iiIII", cpu, sub & 0x00FFFFFF, offset + len(body), len(p),
                                   align))
        body += p
    head = header + b"".join(entries)
    return head + b"\0" * (offset - len(head)) + body


def check_library(path: Path, platform: Platform, exports: tuple[str, ...]) -> None:
    """Read ``path`` back and fail naming what makes it unfit for ``platform``.

    Raises
    ------
    BuildError
        One line per problem: an export missing, a library not allowed, a glibc version too
        new, the wrong architectures or not a shared library.
    """
    try:
        binary = binary_check.inspect(path)
    except binary_check.BinaryFormatError as exc:
        raise BuildError(f"{platform.name}/{path.name}: {exc}") from None
    found = binary_check.problems(binary, arches=platform.arches, exports=exports,
                                  libraries=platform.libraries, max_glibc=platform.max_glibc)
    if found:
        raise BuildError(f"{platform.name}/{path.name} is not fit for {platform.name}:\n  "
                         + "\n  ".join(found))


def compile_for(platform: str, src: Path, sources: tuple[str, ...], out: Path,
                exports: tuple[str, ...], defines: tuple[str, ...] = (),
                arches: tuple[str, ...] | None = None, link: tuple[str, ...] = (),
                allow: tuple[str, ...] = ()) -> Path:
    """Compile ``sources`` (in ``src``, headers there too) into the shared library ``out`` for
    ``platform`` (a key of :data:`PLATFORMS`) with Zig's C compiler, and check it
    (:func:`check_library`) for the functions ``exports``.

    Parameters
    ----------
    platform : str
        ``linux64``, ``win64`` or ``darwin64``.
    src : Path
        Directory of the sources and headers.
    sources : tuple of str
        The C files compiled.
    out : Path
        The library written (its parent is created).
    exports : tuple of str
        Functions it must export.
    defines : tuple of str
        Extra ``-D`` definitions (``NAME`` or ``NAME=VALUE``).
    arches : tuple of str, optional
        Only these of the platform's architectures (FMI 3.0: one library per architecture);
        default all (darwin64: one universal file).
    link : tuple of str
        Extra linker arguments (``-ldl``).
    allow : tuple of str
        Libraries the result may load besides the platform's C runtime (``libdl.so.2``).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    BuildError
        For an unknown platform, ziglang missing, a compiler error, or a library unfit for the
        platform (named).
    """
    if platform not in PLATFORMS:
        raise BuildError(f"platform {platform!r} is not allowed: must be one of "
                         f"{', '.join(PLATFORMS)}")
    if not zig_available():
        raise BuildError(f"building for {platform} needs Zig's C compiler: pip install ziglang "
                         "(in the fmu extra: pip install -e \".[fmu]\")")
    p = PLATFORMS[platform]
    if arches is not None:
        if not arches or any(a not in p.arches for a in arches):
            raise BuildError(f"architectures {arches!r} not allowed for {platform}: must be "
                             f"of {', '.join(p.arches)}")
        keep = [i for i, a in enumerate(p.arches) if a in arches]
        p = replace(p, targets=tuple(p.targets[i] for i in keep), arches=tuple(arches))
    if link or allow:                        # part of the platform, so of the cache's key too
        p = replace(p, link_flags=p.link_flags + tuple(link), libraries=p.libraries + tuple(allow))
    out.parent.mkdir(parents=True, exist_ok=True)
    # a library built before from the same files is reused (Zig's own cache misses here: the
    # sources are in a new temporary directory each build); it is checked again below
    libs = _user_cache() / "libraries"
    cached = libs / (_library_key(p, src, sources, defines, out.name) + p.suffix)
    if cached.is_file():
        check_library(cached, p, exports)
        shutil.copyfile(cached, out)
        return out
    with tempfile.TemporaryDirectory(prefix=f"prsm_{platform}_") as tmp:
        tmp = Path(tmp)
        env = _zig_env(tmp / "zig-local")
        parts = []
        for target, arch in zip(p.targets, p.arches):
            lib = tmp / f"{arch}{p.suffix}"
            cmd = [sys.executable, "-m", "ziglang", "cc", "-target", target, *COMPILE_FLAGS,
                   "-Wall", f"-I{src}", *(f"-D{d}" for d in defines),
                   *(str(src / s) for s in sources), "-o", str(lib),
                   *(f.format(name=out.name) for f in p.link_flags), "-lm"]
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp)
            if proc.returncode != 0:
                raise BuildError(f"zig cc -target {target} failed:\n{proc.stderr[-4000:]}")
            parts.append(lib.read_bytes())
        data = parts[0] if len(parts) == 1 else universal_macho(parts)
        staged = tmp / out.name
        staged.write_bytes(data)
        check_library(staged, p, exports)
        libs.mkdir(mode=0o700, parents=True, exist_ok=True)
        part = libs / f".{cached.name}.{os.getpid()}"
        shutil.copyfile(staged, part)
        os.replace(part, cached)             # whole, so a concurrent build finds it complete
        shutil.move(str(staged), out)
    return out

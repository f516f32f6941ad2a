"""What a shared library exports and imports, read from the file itself (ELF, PE, Mach-O).

Small parsers written with :mod:`struct` (no tool needed, the same on every build machine):

- **ELF** (Linux, 64-bit little-endian): the dynamic symbol table (``.dynsym``) for the
  functions defined and the ones needed, ``DT_NEEDED`` for the libraries, and the version needs
  (``.gnu.version_r``, ``.gnu.version``) for the glibc symbol versions each import binds to;
- **PE32+** (Windows x64): the export directory's names and the import directory's DLLs and
  function names;
- **Mach-O** (macOS, thin 64-bit or universal): the symbol table (``LC_SYMTAB``: external
  defined symbols, without the leading underscore) and the ``LC_LOAD_DYLIB`` family.

:func:`inspect` returns a :class:`Binary`; :func:`problems` lists, one line each, what makes a
library unfit for a platform (:mod:`fmu_build.platforms` says what each platform allows).
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Binary", "Slice", "inspect", "glibc_version", "problems", "BinaryFormatError"]


class BinaryFormatError(ValueError):
    """The file is not a shared library this module reads."""


@dataclass
class Slice:
    """One architecture's code: what it defines and what it needs."""

    arch: str                                      #: x86_64 or arm64
    exports: set[str] = field(default_factory=set)         #: functions/data defined, visible
    imports: dict[str, str] = field(default_factory=dict)  #: undefined symbol -> version ("" none)
    libraries: list[str] = field(default_factory=list)     #: libraries loaded (DT_NEEDED, DLLs, dylibs)


@dataclass
class Binary:
    """A shared library: its format and one slice per architecture (two in a universal Mach-O)."""

    format: str                                    #: ELF, PE or Mach-O
    kind: str                                      #: shared (ELF ET_DYN, PE DLL, MH_DYLIB) or other
    slices: list[Slice]


# ---- ELF ------------------------------------------------------------------------------------------
_ELF_MACHINES = {62: "x86_64", 183: "arm64"}


def _cstr(data: bytes, offset: int) -> str:
    end = data.index(b"\0", offset)
    return data[offset:end].decode("utf-8", "replace")


def _elf(data: bytes) -> Binary:
    if data[4] != 2 or data[5] != 1:
        raise BinaryFormatError("only 64-bit little-endian ELF is read")
    e_type, e_machine = struct.unpack_from("<HH", data, 16)
    e_shoff, = struct.unpack_from("<Q", data, 40)
    e_shentsize, e_shnum, e_shstrndx = struct.unpack_from("<HHH", data, 58)
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, e_shoff + i * e_shentsize)
                for i in range(e_shnum)]
    # (name, type, flags, addr, offset, size, link, info, addralign, entsize)
    by_type: dict[int, tuple] = {}
    for s in sections:
        by_type.setdefault(s[1], s)
    sl = Slice(_ELF_MACHINES.get(e_machine, f"machine {e_machine}"))
    dynamic = by_type.get(6)                        # SHT_DYNAMIC
    if dynamic is not None:
        strtab = sections[dynamic[6]][4]
        for off in range(dynamic[4], dynamic[4] + dynamic[5], 16):
            tag, val = struct.unpack_from("<qQ", data, off)
            if tag == 0:
                break
            if tag == 1:                            # DT_NEEDED
                sl.libraries.append(_cstr(data, strtab + val))
    versions: dict[int, str] = {}
    verneed = by_type.get(0x6ffffffe)               # SHT_GNU_verneed
    if verneed is not None:
        strtab = sections[verneed[6]][4]
        off = verneed[4]
        for _ in range(verneed[7]):                 # sh_info: number of entries
            _, cnt, _, aux, nxt = struct.unpack_from("<HHIII", data, off)
            a = off + aux
            for _ in range(cnt):
                _, _, other, name, anext = struct.unpack_from("<IHHII", data, a)
                versions[other] = _cstr(data, strtab + name)
                a += anext
            if not nxt:
                break
            off += nxt
    dynsym = by_type.get(11)                        # SHT_DYNSYM
    if dynsym is None:
        raise BinaryFormatError("the ELF file has no dynamic symbol table")
    strtab = sections[dynsym[6]][4]
    versym = by_type.get(0x6fffffff)                # SHT_GNU_versym
    for i in range(dynsym[5] // 24):
        name_off, info, _, shndx, _, _ = struct.unpack_from("<IBBHQQ", data, dynsym[4] + 24 * i)
        name = _cstr(data, strtab + name_off)
        if not name or (info >> 4) not in (1, 2):   # STB_GLOBAL, STB_WEAK
            continue
        if shndx == 0:                              # SHN_UNDEF
            ver = struct.unpack_from("<H", data, versym[4] + 2 * i)[0] & 0x7fff if versym else 0
            sl.imports[name] = versions.get(ver, "")
        else:
            sl.exports.add(name)
    return Binary("ELF", "shared" if e_type == 3 else "other", [sl])


# ---- PE ---------------------------------------------------------------------------------------------
def _pe(data: bytes) -> Binary:
    pe, = struct.unpack_from("<I", data, 0x3C)
    if data[pe:pe + 4] != b"PE\0\0":
        raise BinaryFormatError("no PE signature")
    machine, n_sections = struct.unpack_from("<HH", data, pe + 4)
    opt_size, characteristics = struct.unpack_from("<HH", data, pe + 20)
    opt = pe + 24
    if struct.unpack_from("<H", data, opt)[0] != 0x20B:
        raise BinaryFormatError("only PE32+ (64-bit) is read")
    n_dirs, = struct.unpack_from("<I", data, opt + 108)
    dirs = [struct.unpack_from("<II", data, opt + 112 + 8 * i) for i in range(min(n_dirs, 16))]
    sections = [struct.unpack_from("<IIII", data, opt + opt_size + 40 * i + 8)
                for i in range(n_sections)]         # virtual size, address, raw size, raw pointer

    def at(rva: int) -> int:
        for vsize, vaddr, rsize, raw in sections:
            if vaddr <= rva < vaddr + max(vsize, rsize):
                return raw + rva - vaddr
        raise BinaryFormatError(f"RVA {rva:#x} is in no section")

    sl = Slice({0x8664: "x86_64", 0xAA64: "arm64"}.get(machine, f"machine {machine:#x}"))
    exp_rva, exp_size = dirs[0]
    if exp_rva:
        e = at(exp_rva)
        n_names, _, names = struct.unpack_from("<III", data, e + 24)
        for i in range(n_names):
            sl.exports.add(_cstr(data, at(struct.unpack_from("<I", data, at(names) + 4 * i)[0])))
    imp_rva, _ = dirs[1]
    if imp_rva:
        d = at(imp_rva)
        while True:
            lookup, _, _, name, first = struct.unpack_from("<IIIII", data, d)
            if not (lookup or name or first):
                break
            dll = _cstr(data, at(name))
            sl.libraries.append(dll)
            t = at(lookup or first)
            while (entry := struct.unpack_from("<Q", data, t)[0]):
                if not entry >> 63:                 # by name, not by ordinal
                    sl.imports[_cstr(data, at(entry & 0x7FFFFFFF) + 2)] = dll
                t += 8
            d += 20
    return Binary("PE", "shared" if characteristics & 0x2000 else "other", [sl])


# ---- Mach-O -----------------------------------------------------------------------------------------
_MACHO_CPUS = {0x01000007: "x86_64", 0x0100000C: "arm64"}
_LOAD_DYLIB = (0xC, 0x80000018, 0x8000001F, 0x80000023)   # LOAD, LOAD_WEAK, REEXPORT, LOAD_UPWARD


def _macho_thin(data: bytes, base: int) -> tuple[Slice, int]:
    magic, cpu, _, filetype, ncmds, _, _ = struct.unpack_from("<IiiIIII", data, base)
    if magic != 0xFEEDFACF:
        raise BinaryFormatError("only 64-bit little-endian Mach-O is read")
    sl = Slice(_MACHO_CPUS.get(cpu, f"cpu {cpu:#x}"))
    off = base + 32
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", data, off)
        if cmd in _LOAD_DYLIB:
            sl.libraries.append(_cstr(data, off + struct.unpack_from("<I", data, off + 8)[0]))
        elif cmd == 0x2:                            # LC_SYMTAB
            symoff, nsyms, stroff, _ = struct.unpack_from("<IIII", data, off + 8)
            for i in range(nsyms):
                strx, ntype, _, _, _ = struct.unpack_from("<IBBHQ", data, base + symoff + 16 * i)
                if ntype & 0xE0 or not ntype & 0x01:    # debugging entry, or not external
                    continue
                name = _cstr(data, base + stroff + strx)
                name = name[1:] if name.startswith("_") else name
                if ntype & 0x0E == 0x0E:            # N_SECT: defined here
                    sl.exports.add(name)
                elif ntype & 0x0E == 0:             # N_UNDF
                    sl.imports[name] = ""
        off += size
    return sl, filetype


def _macho(data: bytes) -> Binary:
    if data[:4] == b"\xca\xfe\xba\xbe":
        n, = struct.unpack_from(">I", data, 4)
        slices, kinds = [], set()
        for i in range(n):
            _, _, offset, _, _ = struct.unpack_from(">iiIII", data, 8 + 20 * i)
            sl, filetype = _macho_thin(data, offset)
            slices.append(sl)
            kinds.add(filetype)
        return Binary("Mach-O", "shared" if kinds == {6} else "other", slices)
    sl, filetype = _macho_thin(data, 0)
    return Binary("Mach-O", "shared" if filetype == 6 else "other", [sl])


def inspect(path: str | Path) -> Binary:
    """Read a shared library's exports, imports and libraries.

    Raises
    ------
    BinaryFormatError
        When the file is not a 64-bit ELF, PE32+ or Mach-O file (or is damaged).
    """
    data = Path(path).read_bytes()
    try:
        if data[:4] == b"\x7fELF":
            return _elf(data)
        if data[:2] == b"MZ":
            return _pe(data)
        if data[:4] in (b"\xcf\xfa\xed\xfe", b"\xca\xfe\xba\xbe"):
            return _macho(data)
    except (struct.error, IndexError, ValueError) as exc:
        if isinstance(exc, BinaryFormatError):
            raise
        raise BinaryFormatError(f"{Path(path).name}: damaged ({exc})") from None
    raise BinaryFormatError(f"{Path(path).name}: not an ELF, PE or Mach-O file")


def glibc_version(version: str) -> tuple[int, ...] | None:
    """``GLIBC_2.17`` -> (2, 17); None for another version name."""
    m = re.fullmatch(r"GLIBC_(\d+(?:\.\d+)*)", version)
    return tuple(int(p) for p in m.group(1).split(".")) if m else None


def problems(binary: Binary, *, arches: tuple[str, ...], exports: tuple[str, ...],
             libraries: tuple[str, ...], max_glibc: tuple[int, ...] | None = None) -> list[str]:
    """What makes ``binary`` unfit: one line per problem, empty if none.

    Parameters
    ----------
    arches : tuple of str
        The architectures it must hold, each once (``("x86_64", "arm64")``).
    exports : tuple of str
        Functions it must export.
    libraries : tuple of str
        Libraries it may load: exact names, or patterns ending in ``*`` (case-insensitive).
    max_glibc : tuple of int, optional
        Highest glibc symbol version an import may bind to (ELF).
    """
    out = []
    if binary.kind != "shared":
        out.append(f"is a {binary.format} file but not a shared library")
    got = sorted(s.arch for s in binary.slices)
    if got != sorted(arches):
        out.append(f"holds architectures {got}, expected {sorted(arches)}")

    def allowed(lib: str) -> bool:
        low = lib.lower()
        return any(low.startswith(p[:-1].lower()) if p.endswith("*") else low == p.lower()
                   for p in libraries)

    for s in binary.slices:
        missing = [f for f in exports if f not in s.exports]
        if missing:
            out.append(f"{s.arch}: does not export {', '.join(missing)}")
        extra = [lib for lib in s.libraries if not allowed(lib)]
        if extra:
            out.append(f"{s.arch}: loads {', '.join(extra)}; allowed: {', '.join(libraries)}")
        if max_glibc is not None:
            newer = sorted(f"{n}@{v}" for n, v in s.imports.items()
                           if (g := glibc_version(v)) is not None and g > max_glibc)
            if newer:
                out.append(f"{s.arch}: needs glibc newer than {'.'.join(map(str, max_glibc))}: "
                           + ", ".join(newer))
    return out

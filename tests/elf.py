"""A small reader of ELF64 little-endian shared libraries, for the tests of the FMUs' binaries:
the functions a library exports and the symbol versions it needs (what ``nm -D`` and
``objdump -T`` print)."""
from __future__ import annotations

import struct

SHT_DYNSYM = 11
SHT_GNU_VERNEED = 0x6FFFFFFE


def _sections(data: bytes) -> list[tuple]:
    """The section headers: (name, type, flags, addr, offset, size, link, info, align, entsize)."""
    assert data[:4] == b"\x7fELF" and data[4] == 2 and data[5] == 1, "not an ELF64 little-endian file"
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", data, 0x3A)
    return [struct.unpack_from("<IIQQQQIIQQ", data, shoff + k * shentsize) for k in range(shnum)]


def _string(data: bytes, table: int, at: int) -> str:
    return data[table + at:data.index(b"\0", table + at)].decode()


def exports(data: bytes) -> set[str]:
    """The defined global functions (.dynsym)."""
    sections = _sections(data)
    names = set()
    for _, kind, _, _, offset, size, link, _, _, entsize in sections:
        if kind != SHT_DYNSYM:
            continue
        for k in range(size // entsize):
            name, info, _, shndx, _, _ = struct.unpack_from("<IBBHQQ", data, offset + k * entsize)
            if shndx != 0 and info >> 4 == 1 and info & 0xF == 2:   # defined, STB_GLOBAL, STT_FUNC
                names.add(_string(data, sections[link][4], name))
    return names


def version_needs(data: bytes) -> dict[str, set[str]]:
    """The symbol versions needed, by library (.gnu.version_r): {"libc.so.6": {"GLIBC_2.14", ...}}."""
    sections = _sections(data)
    needs: dict[str, set[str]] = {}
    for _, kind, _, _, offset, _, link, count, _, _ in sections:
        if kind != SHT_GNU_VERNEED:
            continue
        strings = sections[link][4]
        entry = offset
        for _ in range(count):
            _, n_aux, file, aux, following = struct.unpack_from("<HHIII", data, entry)
            versions = needs.setdefault(_string(data, strings, file), set())
            at = entry + aux
            for _ in range(n_aux):
                _, _, _, name, next_aux = struct.unpack_from("<IHHII", data, at)
                versions.add(_string(data, strings, name))
                at += next_aux
            entry += following
    return needs

"""Which functions were on the emulated Uno's stack at its deepest point.

The runner (tools/avrsim ``--stats FILE --stack FILE``) keeps a copy of the stack's bytes
(SP + 1 .. RAMEND) taken when the lowest stack pointer was reached. On the AVR a call pushes
its return address, a flash word address, high byte at the lower address. The walk starts at
RAMEND and follows the calls: a return address must come right after a call instruction
(CALL, RCALL, ICALL, EICALL), and it must return into the function the previous one called
(known from the call instruction, but for ICALL), so the stale return addresses that earlier,
deeper calls left in the frames are skipped. The chain ends at the function the deepest
point was in, or was interrupted in (the interrupt's own frame is what lies above it). With
how many bytes of stack each frame took, it says where to look when the RAM budget
(:mod:`protoduino_dev.rambudget`) gets tight.
"""

from __future__ import annotations

import bisect
import subprocess
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True, slots=True)
class Frame:
    """One return address found on the stack: the function it returns into, and the bytes
    of stack from it to the next return address below (towards RAMEND: the caller's side)."""

    function: str
    depth: int  # bytes from RAMEND to this return address


def _flash(elf: Path) -> bytes:
    out = subprocess.run(
        ["avr-objcopy", "-O", "binary", "-j", ".text", str(elf), "/dev/stdout"],
        check=True,
        capture_output=True,
        timeout=60,
    ).stdout
    return out


def _symbols(elf: Path) -> tuple[list[int], list[str]]:
    out = subprocess.run(
        ["avr-nm", "-n", str(elf)], check=True, capture_output=True, text=True, timeout=60
    ).stdout
    starts: list[int] = []
    names: list[str] = []
    for line in out.splitlines():
        fields = line.split()
        if len(fields) == 3 and fields[1] in "tTW":
            starts.append(int(fields[0], 16))
            names.append(fields[2].lstrip(".").split(".")[0])
    return starts, names


def _after_call(flash: bytes, address: int) -> bool:
    """Whether the instruction just before byte ``address`` of flash is a call."""
    if address < 4 or address > len(flash):
        return False
    word4 = flash[address - 4] | flash[address - 3] << 8
    word2 = flash[address - 2] | flash[address - 1] << 8
    return (
        (word4 & 0xFE0E) == 0x940E  # CALL k (32-bit)
        or (word2 & 0xF000) == 0xD000  # RCALL k
        or word2 in (0x9509, 0x9519)  # ICALL, EICALL
    )


def _callee(flash: bytes, address: int) -> int | None:
    """The byte address the call just before ``address`` jumps to; None for ICALL/EICALL."""
    word4 = flash[address - 4] | flash[address - 3] << 8
    if (word4 & 0xFE0E) == 0x940E:
        high = ((word4 >> 3) & 0x3E) | (word4 & 1)
        low = flash[address - 2] | flash[address - 1] << 8
        return (high << 16 | low) * 2
    word2 = flash[address - 2] | flash[address - 1] << 8
    if (word2 & 0xF000) == 0xD000:
        offset = word2 & 0x0FFF
        if offset & 0x800:
            offset -= 0x1000
        return address + offset * 2
    return None


def walk(elf: Path, stack: bytes) -> list[Frame]:
    """The call chain in ``stack`` (the runner's --stack bytes), outermost (main) first."""
    flash = _flash(elf)
    starts, names = _symbols(elf)

    def function(address: int) -> int:
        return bisect.bisect_right(starts, address) - 1

    frames: list[Frame] = []
    top = len(stack)
    into: int | None = None  # the function the last call went to; None: any
    for i in range(len(stack) - 2, -1, -1):
        address = (stack[i] << 8 | stack[i + 1]) * 2
        if not _after_call(flash, address):
            continue
        at = function(address)
        if at < 0 or (into is not None and at != into):
            continue
        frames.append(Frame(names[at], top - i))
        callee = _callee(flash, address)
        into = function(callee) if callee is not None else None
    return frames


def describe(frames: list[Frame]) -> str:
    """``main 17 > pb_decode_inner 115 > ...``: each function and its depth in bytes."""
    return " > ".join(f"{f.function} {f.depth}" for f in frames)

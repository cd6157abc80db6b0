"""Where the programs that protoduino runs or flashes come from.

The simulated board (``pd_sim``, the firmware core on this machine), the emulated Uno's runner
(``avrsim``, simavr) with the firmware's ELF (and the Mega 2560's, ``protoduino-mega.elf``,
which the same runner emulates), and the firmware's hex per board that ``protoduino flash``
uploads (``protoduino.hex`` for the Uno, ``protoduino-mega.hex``, ``protoduino-nano.hex``).

* An installed wheel carries them, built when the wheel was built, as package data in
  ``protoduino/_programs/``, so ``pip install protoduino`` is all a user needs.
* An installed distribution may declare a program source (entry point group
  ``protoduino.programs``, see :mod:`protoduino.plugins`): a callable ``(name) -> Path``. The
  development tools (``protoduino-dev``, installed in a source checkout by
  ``./tools/dev.sh setup``) declare one that builds from the current sources with ``make``, so
  that tests and demos never run a stale copy. That is why a declared source takes precedence.
  The runtime never imports the tools: they declare themselves, the dependency flows from them.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources
from pathlib import Path

from . import plugins
from .errors import ArgumentError, BuildError

NATIVE_SIM = "pd_sim"
RUNNER = "avrsim"
FIRMWARE_ELF = "protoduino.elf"
FIRMWARE_HEX = "protoduino.hex"
#: The firmware built for the Mega 2560 (``make avr BOARD=mega``).
MEGA_FIRMWARE_ELF = "protoduino-mega.elf"
#: The hex ``protoduino flash --board mega`` and ``--board nano`` upload.
MEGA_FIRMWARE_HEX = "protoduino-mega.hex"
NANO_FIRMWARE_HEX = "protoduino-nano.hex"
#: Every program name :func:`locate` knows.
NAMES = (
    NATIVE_SIM,
    RUNNER,
    FIRMWARE_ELF,
    FIRMWARE_HEX,
    MEGA_FIRMWARE_ELF,
    MEGA_FIRMWARE_HEX,
    NANO_FIRMWARE_HEX,
)
#: Folder of the bundled programs inside the package.
BUNDLE_DIR = "_programs"


def bundled(name: str) -> Path | None:
    """The copy of ``name`` shipped inside this installation, or None."""
    entry = resources.files(__package__) / BUNDLE_DIR / name
    # A wheel installs as plain files, so the resource is a real path that a child process
    # can run; a zipped installation would not be, and counts as not bundled.
    if isinstance(entry, Path) and entry.is_file():
        return entry
    return None


def locate(name: str) -> Path:
    """The path of program ``name``: from a declared program source if any, else bundled."""
    if name not in NAMES:
        raise ArgumentError(f"unknown program {name!r}; choose from {', '.join(NAMES)}")
    sources = plugins.declared(plugins.PROGRAMS)
    if sources:
        # More than one would be a broken installation; the first by name, repeatably.
        source: Callable[[str], Path] = sources[0].load()
        return source(name)
    path = bundled(name)
    if path is None:
        raise BuildError(
            f"this protoduino installation carries no {name}: install a released wheel, or "
            "in a source checkout run ./tools/dev.sh setup (the development tools build it)"
        )
    return path

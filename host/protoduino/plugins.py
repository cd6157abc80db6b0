"""What other installed distributions add to protoduino, found by entry point, never by name.

The runtime imports no development tooling: the development tools (``protoduino-dev``, in
``dev/``) declare entry points in these groups, and the runtime loads whatever is declared.
The dependency flows one way, from the tools down to the runtime; a user's installation,
which has no such distribution, finds nothing and behaves as shipped.

* :data:`PROGRAMS`: one callable ``(name) -> Path`` that builds or finds a program
  (:mod:`protoduino.programs`); the development tools build from the checkout.
* :data:`COMMANDS`: a ``protoduino`` subcommand module (``HELP``, ``register``, ``run``), named
  as the subcommand (:mod:`protoduino.cli.main`).
* :data:`GENERATORS`: ``schema``, the module (``run(args)``) that regenerates protoduino's own
  schema code in a source checkout (``protoduino gen`` without a .proto).
* :data:`SERIAL_URLS`: a module whose import makes a pyserial URL scheme known, named as the
  scheme (``faulty``).
"""

from __future__ import annotations

from importlib import metadata

PROGRAMS = "protoduino.programs"
COMMANDS = "protoduino.commands"
SERIAL_URLS = "protoduino.serial_urls"
GENERATORS = "protoduino.generators"


def declared(group: str) -> list[metadata.EntryPoint]:
    """The entry points of ``group``, in name order (so a choice among them is repeatable)."""
    return sorted(metadata.entry_points(group=group), key=lambda ep: (ep.name, ep.value))


def find(group: str, name: str) -> metadata.EntryPoint | None:
    """The entry point ``name`` of ``group``, or None when no installed distribution has it."""
    for ep in declared(group):
        if ep.name == name:
            return ep
    return None

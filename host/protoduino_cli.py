"""The ``protoduino`` command's entry point, a module outside the package on purpose.

A console script imports its entry point's module before it calls anything, and
importing ``protoduino`` (the board, protobuf's generated code) takes a noticeable
moment: a Ctrl-C then would end in an import traceback, with no ``try`` around it
to catch it. This module imports nothing of protoduino's until :func:`main` runs,
and does it inside a ``try`` that turns an interrupt into exit status 130 silently,
as :func:`protoduino.cli.main.main` does once the command runs (README, "Exit statuses").
"""

from __future__ import annotations


def main() -> int:
    """Run the command line (:func:`protoduino.cli.main.main`); 130 for a Ctrl-C at any point."""
    try:
        from protoduino.cli.main import main as run

        return run()
    except KeyboardInterrupt:
        return 130

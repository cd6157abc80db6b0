"""The code generators' tools (protoc, nanopb's generator) run in a child process: the one
helper that :mod:`protoduino.servicegen` (a user's services) and ``protoduino_dev.codegen``
(the protocol's own files) share, each mapping :class:`ToolError` to its own error.

Standard library only, and nothing imported from the package, on purpose: codegen writes the
files the package imports (``_generated``), so it must run where they are missing or broken;
it loads this file by its path, as it loads ``constants.py``, without importing
``protoduino``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


class ToolError(RuntimeError):
    """A tool exited with an error; the message gives its command line and its output."""


def run(cmd: list[str], cwd: Path) -> None:
    """Run ``cmd`` in ``cwd``; :class:`ToolError` if it fails."""
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise ToolError(f"{' '.join(cmd)} failed:\n{proc.stdout}{proc.stderr}")


def protoc(args: list[str], cwd: Path) -> None:
    """grpc_tools' protoc with ``args``: a module, run in a child so that its argv and any
    ``exit()`` stay out of this process."""
    run([sys.executable, "-m", "grpc_tools.protoc", *args], cwd)

"""Client of a simulated board's input-control socket (``--control PATH``).

Both simulated boards (the native one and the emulated Uno) take one JSON
object per line on a Unix stream socket and apply it to their inputs at once
(``firmware/simcontrol/pd_control.h`` is the protocol)::

    {"pin": 2, "level": 0}                  drive a digital input
    {"pin": 14, "analog": 512}              an analog input, in counts 0..1023 (A0 = 14)
    {"pin": 3, "pulses": 100, "hz": 2000}   pulses for a counter, on the board's clock

Each line gets one answer, ``{"ok": true, "t": T}`` with the board time the
command took effect (the trace's clock) or ``{"ok": false, "error": ...}``,
raised here as :class:`~protoduino.errors.SimControlError`. The board checks
everything (pin numbers, ranges); this client only frames lines, so both
sides cannot disagree about what is valid.
"""

from __future__ import annotations

import json
import socket
import threading
from pathlib import Path
from typing import Any

from .closing import ClosedOnExit
from .errors import SimControlError, TransportError

#: Upper bound on one answer's wait: the board answers between two of its steps.
REPLY_TIMEOUT = 5.0


class SimControl(ClosedOnExit):
    """One connection to a control socket; thread-safe, connects on first use."""

    def __init__(self, path: Path, *, timeout: float = REPLY_TIMEOUT) -> None:
        self.path = path
        self._timeout = timeout
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._buffer = b""

    def level(self, pin: int, level: bool | int) -> float:
        """Drive digital input ``pin`` high (True/1) or low; returns the board time."""
        return self.send({"pin": pin, "level": int(bool(level))})

    def analog(self, pin: int, counts: int) -> float:
        """Set analog input ``pin`` (14..19 on the Uno) to ``counts`` (0..1023)."""
        return self.send({"pin": pin, "analog": counts})

    def pulses(self, pin: int, count: int, hz: int) -> float:
        """Start ``count`` pulses at ``hz`` on ``pin`` from its current level.

        Returns at once with the board time of the first edge's start; the
        train runs on the board's clock (``count / hz`` seconds).
        """
        return self.send({"pin": pin, "pulses": count, "hz": hz})

    def send(self, command: dict[str, Any]) -> float:
        """Send one command object; return its board time or raise SimControlError."""
        line = json.dumps(command).encode() + b"\n"
        with self._lock:
            sock = self._connect()
            try:
                sock.sendall(line)
                answer = self._read_line(sock)
            except OSError as error:
                self._close_locked()
                raise TransportError(f"control socket {self.path}: {error}") from error
        try:
            reply = json.loads(answer)
        except json.JSONDecodeError as error:
            raise TransportError(f"control socket {self.path} answered {answer!r}") from error
        if not reply.get("ok"):
            raise SimControlError(f"{command}: {reply.get('error', 'refused')}")
        return float(reply["t"])

    def _connect(self) -> socket.socket:
        if self._sock is None:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            sock.settimeout(self._timeout)
            try:
                sock.connect(str(self.path))
            except OSError as error:
                sock.close()
                raise TransportError(
                    f"cannot connect to the control socket {self.path}: {error}"
                ) from error
            self._sock = sock
            self._buffer = b""
        return self._sock

    def _read_line(self, sock: socket.socket) -> bytes:
        while b"\n" not in self._buffer:
            chunk = sock.recv(4096)
            if not chunk:
                raise ConnectionResetError("the board closed the control socket")
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        return line

    def _close_locked(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def close(self) -> None:
        with self._lock:
            self._close_locked()

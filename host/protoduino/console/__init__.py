"""The live console: a local web page that shows a board as it is now and drives it (issue 37).

``protoduino console PORT`` (or ``--sim``) runs it; the same as an API::

    from protoduino import Board
    from protoduino.console import ConsoleServer, LiveBoard, EXAMPLE_ROBOT

    with Board.open(port, liveness="heartbeat", failsafe_timeout=2.0) as board:
        live = LiveBoard(board)
        live.configure_all(EXAMPLE_ROBOT)
        with ConsoleServer(live) as server:
            print(server.url)   # open it in a browser; the page's heartbeat keeps the outputs

It needs the ``console`` extra (``pip install 'protoduino[console]'``: aiohttp). Modules:
:mod:`.live` (the board's picture and commands, no web), :mod:`.server` (aiohttp: the page,
its WebSocket, the token, who drives). docs/console.md has the rules.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .live import EXAMPLE_ROBOT, LiveBoard, PinSpec

if TYPE_CHECKING:
    from .server import ConsoleServer

__all__ = ["EXAMPLE_ROBOT", "ConsoleServer", "LiveBoard", "PinSpec"]

#: What a missing extra says.
EXTRA_MISSING = (
    "the console needs aiohttp: pip install 'protoduino[console]' (a checkout's "
    "./tools/dev.sh setup has it)"
)


def __getattr__(name: str) -> Any:
    # The server imports aiohttp: only on use, so that the rest needs nothing more.
    if name == "ConsoleServer":
        try:
            from .server import ConsoleServer
        except ImportError as error:
            if error.name is None or not error.name.startswith("aiohttp"):
                raise
            from ..errors import ProtoduinoError

            raise ProtoduinoError(EXTRA_MISSING) from error
        return ConsoleServer
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

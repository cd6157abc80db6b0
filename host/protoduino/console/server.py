"""The console's web server (aiohttp): the page, its assets and one WebSocket per page.

Why aiohttp: one well-kept asyncio library serves HTTP and WebSockets alike, with no ASGI
server beside it; the board's ``submit_`` futures are awaited with
:func:`asyncio.wrap_future`, so no call blocks the loop (a reconfigured pin's release, the
one blocking call, runs in a worker thread).

The rules (docs/console.md):

* **Where it listens.** 127.0.0.1 unless told otherwise. Anywhere else it needs an access
  token, made at start and printed with the URL (as Jupyter does); every request without it
  is refused (403): the page's URL carries it (``?token=``), which sets a cookie for the
  assets and the WebSocket. A token may be asked for on 127.0.0.1 too.
* **Whose page it is.** A WebSocket whose ``Origin`` is not this server is refused (403),
  token or not: another web site open in the same browser must not drive the robot. Without
  a token, a request whose ``Host`` is not a loopback name or address is refused too (a
  site's name made to resolve to 127.0.0.1, DNS rebinding, would otherwise be this server's
  own origin).
* **Liveness is the page's.** The board runs with ``liveness="heartbeat"``, and only the
  driving page's ``beat`` messages (every ``failsafe_timeout / 4``) send the device's
  heartbeat: a page that goes away (tab closed, laptop asleep, network gone) stops them,
  and the device's failsafe drives every output safe ``failsafe_timeout`` later.
* **One page drives, the others watch.** The first page to connect drives; every other
  page watches (it sees everything; its commands are refused, its beats ignored). When the
  driving page goes, nobody drives until a watching page takes over (``take``). STOP is
  the exception: any page may stop the board.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import ipaddress
import json
import logging
import secrets
import threading
from collections.abc import Awaitable, Callable
from concurrent.futures import Future
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web

from ..errors import ArgumentError, ProtoduinoError
from .live import LiveBoard, spec_from_json

log = logging.getLogger(__name__)

#: The cookie that carries the token for the page's assets and WebSocket.
COOKIE = "protoduino_console_token"
#: Seconds between two pictures sent to every page, and between two readbacks of the outputs.
PUSH_PERIOD = 0.1
READBACK_PERIOD = 0.25
#: Heartbeats a driving page sends per failsafe timeout (as the ROS 2 bridge: one or two lost
#: to a slow moment must not trip it).
BEATS_PER_TIMEOUT = 4


def is_loopback(host: str) -> bool:
    """Whether ``host`` listens on this machine only (127.0.0.0/8, ::1, localhost)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def static_dir() -> Path:
    """The page's own files (index.html, console.js, console.css), in the package."""
    return Path(str(resources.files(__package__) / "static"))


def vendor_dir() -> Path:
    """uPlot's files: the wheel's package data, else a checkout's ``.deps/uplot``
    (tools/fetch_uplot.sh). :class:`ProtoduinoError` when neither has them."""
    candidates = (static_dir() / "vendor", Path(__file__).resolve().parents[3] / ".deps" / "uplot")
    for candidate in candidates:
        if (candidate / "uPlot.iife.min.js").is_file():
            return candidate
    raise ProtoduinoError(
        "the console's plotting library (uPlot) is missing: in a checkout run "
        "./tools/fetch_uplot.sh (./tools/dev.sh setup does); a wheel carries it"
    )


class ConsoleServer:
    """Serve ``live`` on ``host:port`` (0: any free port) from a thread of its own.

    ``token``: the access token; None makes one when ``host`` is not a loopback address
    (and on loopback means none is asked for). :meth:`start` returns the page's URL (with
    the token), :meth:`stop` ends it; the board is its owner's.
    """

    def __init__(
        self,
        live: LiveBoard,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        token: str | None = None,
    ) -> None:
        self.live = live
        self.host = host
        self.port = port
        if token is None and not is_loopback(host):
            token = secrets.token_urlsafe(24)
        self.token = token
        self.url = ""
        self._vendor = vendor_dir()
        self._pages: dict[web.WebSocketResponse, str] = {}
        self._driver: web.WebSocketResponse | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready: Future[str] = Future()
        self._stopping: asyncio.Event | None = None
        self._tasks: set[asyncio.Task[None]] = set()

    # --- lifetime ------------------------------------------------------------------------

    def start(self) -> str:
        """Start serving; returns the page's URL once it listens."""
        self._thread = threading.Thread(target=self._run, name="protoduino-console", daemon=True)
        self._thread.start()
        self.url = self._ready.result(timeout=30)
        return self.url

    def stop(self) -> None:
        """Close every page's WebSocket and stop listening."""
        loop, stopping = self._loop, self._stopping
        if loop is not None and stopping is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop ended on its own
                loop.call_soon_threadsafe(stopping.set)
        if self._thread is not None:
            self._thread.join(10)

    def __enter__(self) -> ConsoleServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as error:  # reported to start(), which raises it
            if not self._ready.done():
                self._ready.set_exception(error)
            else:
                log.exception("the console's server failed")

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stopping = asyncio.Event()
        app = web.Application(middlewares=[self._guard])
        app.router.add_get("/", self._index)
        app.router.add_get("/ws", self._socket)
        app.router.add_static("/static", static_dir())
        app.router.add_static("/vendor", self._vendor)
        runner = web.AppRunner(app, access_log=None)
        await runner.setup()
        site = web.TCPSite(runner, self.host, self.port)
        await site.start()
        port = runner.addresses[0][1]
        host = f"[{self.host}]" if ":" in self.host else self.host
        query = "" if self.token is None else f"?token={self.token}"
        self._ready.set_result(f"http://{host}:{port}/{query}")
        tasks = [asyncio.create_task(self._push()), asyncio.create_task(self._readback())]
        try:
            await self._stopping.wait()
        finally:
            for task in tasks:
                task.cancel()
            for ws in list(self._pages):
                await ws.close()
            await runner.cleanup()

    # --- access --------------------------------------------------------------------------

    def _authorised(self, request: web.Request) -> bool:
        if self.token is None:
            # No token (127.0.0.1): only a request addressed to this machine by name or
            # address, so that a web site whose name was made to resolve to 127.0.0.1 (DNS
            # rebinding) is not let in as if it were the console's own page.
            return is_loopback(urlsplit(f"//{request.host}").hostname or "")
        given = request.query.get("token") or request.cookies.get(COOKIE) or ""
        return hmac.compare_digest(given.encode(), self.token.encode())

    @web.middleware
    async def _guard(
        self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
    ) -> web.StreamResponse:
        if not self._authorised(request):
            log.warning(
                "refused %s %s from %s: no token", request.method, request.path, request.remote
            )
            raise web.HTTPForbidden(
                text="protoduino console: this request needs the access token that the "
                "console printed at its start (open the URL it printed)\n"
            )
        response = await handler(request)
        if self.token is not None and request.query.get("token"):
            response.set_cookie(COOKIE, self.token, httponly=True, samesite="Strict")
        return response

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(static_dir() / "index.html")

    # --- pages ---------------------------------------------------------------------------

    async def _socket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and urlsplit(origin).netloc != request.host:
            log.warning("refused a WebSocket from origin %s (this is %s)", origin, request.host)
            raise web.HTTPForbidden(text="protoduino console: another site's page\n")
        ws = web.WebSocketResponse(heartbeat=None)
        await ws.prepare(request)
        self._pages[ws] = request.remote or "?"
        if self._driver is None:
            self._driver = ws
        await self._send(ws)
        try:
            async for message in ws:
                if message.type != WSMsgType.TEXT:
                    continue
                try:
                    data = json.loads(message.data)
                    future = await self._handle(ws, data)
                except (ProtoduinoError, ValueError, TypeError, KeyError) as error:
                    await self._say(ws, error)
                    continue
                if future is not None:  # its outcome is awaited beside: a STOP never waits
                    task = asyncio.create_task(self._outcome(ws, future, data.get("op")))
                    self._tasks.add(task)
                    task.add_done_callback(self._tasks.discard)
        finally:
            del self._pages[ws]
            if self._driver is ws:
                self._driver = None
                log.info("the driving page went away: the failsafe takes over")
        return ws

    async def _handle(self, ws: web.WebSocketResponse, data: dict[str, Any]) -> Future[Any] | None:
        """Carry out one message of a page: the board's future of what it sent (submitted
        in the order the page's messages came), or None."""
        op = data.get("op")
        live = self.live
        if op == "stop":  # any page may stop the board
            return live.stop()
        if op == "take":
            if self._driver is not None and self._driver is not ws:
                raise ProtoduinoError("another page drives this board: it must close first")
            self._driver = ws
            await self._send(ws)
            return None
        if ws is not self._driver:
            raise ProtoduinoError("this page watches: another page drives the board")
        if op == "beat":
            return live.beat()
        if op == "write":
            unit = str(data.get("unit", ""))
            return live.write(int(data["pin"]), float(data["value"]), unit=unit)
        if op == "configure":
            spec = spec_from_json(data)
            return await asyncio.to_thread(live.configure, spec)
        raise ArgumentError(f"unknown op {op!r}")

    async def _outcome(self, ws: web.WebSocketResponse, future: Future[Any], op: object) -> None:
        """Tell the page when what it asked for failed (a lost heartbeat only goes to the log:
        the failsafe state on the page says what it did)."""
        try:
            await asyncio.wrap_future(future)
        except ProtoduinoError as error:
            if op == "beat":
                log.debug("a heartbeat failed: %s", error)
            else:
                await self._say(ws, error)

    async def _say(self, ws: web.WebSocketResponse, error: Exception) -> None:
        with contextlib.suppress(ConnectionError, RuntimeError):
            await ws.send_json({"type": "error", "text": str(error)})

    def _picture(self, ws: web.WebSocketResponse) -> dict[str, Any]:
        picture = self.live.snapshot()
        picture["type"] = "state"
        picture["role"] = "driver" if ws is self._driver else "watcher"
        picture["driven"] = self._driver is not None
        picture["pages"] = len(self._pages)
        picture["beat_period"] = self.live.board.failsafe_timeout / BEATS_PER_TIMEOUT
        return picture

    async def _send(self, ws: web.WebSocketResponse) -> None:
        with contextlib.suppress(ConnectionError, RuntimeError):
            await ws.send_json(self._picture(ws))

    async def _push(self) -> None:
        while True:
            for ws in list(self._pages):
                await self._send(ws)
            await asyncio.sleep(PUSH_PERIOD)

    async def _readback(self) -> None:
        while True:
            try:
                await asyncio.wrap_future(self.live.refresh_outputs())
            except ProtoduinoError as error:  # the link is down: the page says so
                log.debug("readback: %s", error)
            await asyncio.sleep(READBACK_PERIOD)

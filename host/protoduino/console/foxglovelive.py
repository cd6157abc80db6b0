"""A board's live channels over Foxglove's WebSocket protocol (``foxglove-sdk`` runs the server).

The channels are the MCAP export's (:func:`protoduino.mcapexport.channel_specs`): the same
topics, encodings and schemas, and each message made the same way from the same record
(:func:`protoduino.mcapexport.record_messages`), so one Foxglove layout
(``docs/foxglove-layout.json``) serves a recording and a live robot. The records come as a
capture's do: every frame from a frame monitor (on the board's I/O thread; the encoding and
``Channel.log`` are quick), every event from the event thread, the link counters once a
second from a thread of its own.

A user service's reports (docs/services.md) go on channels of their own, in their own protobuf
schema (``reports={"/robot/presses": (3, presses_pb2.Press)}``: the topic, the report rpc's
number and its message class, as the generated client declares them); the MCAP export, which
knows no user schema, has them inside ``/protoduino/device``'s ``ArduinoOut.user_report``.

The server is read-only (no capability that lets a client publish, call or set anything:
the console's page is the one that drives) and listens on 127.0.0.1 unless told otherwise.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import foxglove
from google.protobuf.message import Message
from mcap_protobuf.schema import build_file_descriptor_set

from ..board import Board
from ..capture import CapturedEvent, CapturedFrame, CapturedStats, Record
from ..events import Event
from ..mcapexport import channel_specs, record_messages
from ..transport import FrameRecord
from ..userreports import RawReport

#: Seconds between two link-counter messages (as a capture writes them).
STATS_EVERY = 1.0


class FoxgloveLive:
    """Serve ``board``'s channels on ``host:port`` (0: any free port) until :meth:`stop`."""

    def __init__(
        self,
        board: Board,
        *,
        host: str = "127.0.0.1",
        port: int = 8765,
        name: str = "protoduino",
        reports: Mapping[str, tuple[int, type[Message]]] | None = None,
    ) -> None:
        self.board = board
        # A FrameRecord's time is time.monotonic(); the channels' is UNIX time, as a capture's.
        self._offset = time.time() - time.monotonic()
        self._stopping = threading.Event()
        self._context = foxglove.Context()
        self._channels: dict[str, Any] = {
            spec.topic: self._channel(
                spec.topic,
                spec.message_encoding,
                spec.schema_name,
                spec.schema_encoding,
                spec.schema_data,
            )
            for spec in channel_specs()
        }
        self._removers: list[Callable[[], None]] = []
        for topic, (method, message) in (reports or {}).items():
            self._channels[topic] = self._channel(
                topic,
                "protobuf",
                message.DESCRIPTOR.full_name,
                "protobuf",
                build_file_descriptor_set(message).SerializeToString(),
            )
            self._removers.append(board.user_reports.on_report(method, self._reporter(topic)))
        self._server = foxglove.start_server(name=name, host=host, port=port, context=self._context)
        self.port: int = self._server.port
        self.url = f"ws://{host}:{self.port}"
        board.add_frame_monitor(self._frame)
        self._unsubscribe = board.on_event(self._event)
        self._stats = threading.Thread(target=self._stats_loop, name="foxglove-stats", daemon=True)
        self._stats.start()

    def _channel(
        self, topic: str, encoding: str, schema_name: str, schema_encoding: str, schema: bytes
    ) -> Any:
        return foxglove.Channel(
            topic,
            message_encoding=encoding,
            schema=foxglove.Schema(name=schema_name, encoding=schema_encoding, data=schema),
            context=self._context,
        )

    def _reporter(self, topic: str) -> Callable[[RawReport], None]:
        def log(raw: RawReport) -> None:  # the event thread; the body is the user's protobuf
            if not self._stopping.is_set():
                t = raw.received + self._offset
                self._channels[topic].log(raw.body, log_time=round(t * 1e9))

        return log

    def _log(self, record: Record) -> None:
        if self._stopping.is_set():
            return
        for topic, t, data in record_messages(record):
            self._channels[topic].log(data, log_time=round(t * 1e9))

    def _frame(self, rec: FrameRecord) -> None:
        self._log(CapturedFrame(rec.t + self._offset, rec.direction, rec.item))

    def _event(self, event: Event) -> None:
        self._log(
            CapturedEvent(event.t + self._offset, event.kind.value, event.text, dict(event.details))
        )

    def _stats_loop(self) -> None:
        while not self._stopping.wait(STATS_EVERY):
            stats = self.board.stats.as_dict()
            stats.pop("last_ping", None)  # a time.monotonic() reading of this process
            self._log(CapturedStats(time.time(), stats))

    def stop(self) -> None:
        """Stop logging and serving (the board is its owner's)."""
        self._stopping.set()
        self._unsubscribe()
        for remove in self._removers:
            remove()
        self._stats.join(5)
        self._server.stop()
        for channel in self._channels.values():
            channel.close()

    def __enter__(self) -> FoxgloveLive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

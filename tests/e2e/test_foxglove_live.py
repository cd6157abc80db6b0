"""Foxglove, live: a board's channels over Foxglove's WebSocket protocol (foxglove-sdk's
server), read by a plain WebSocket client that subscribes and decodes, on both boards; the
channels are the MCAP export's, and the shipped layout's topics are among them.
"""

from __future__ import annotations

import asyncio
import base64
import json
import re
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from protoduino import Board
from protoduino.simboard import SimBoard

pytest.importorskip("foxglove", reason="foxglove-sdk is not installed")
pytest.importorskip("mcap_protobuf", reason="mcap-protobuf-support is not installed")
import aiohttp
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from protoduino.console.foxglovelive import FoxgloveLive
from protoduino.mcapexport import channel_specs
from userbuilds import client as user_client
from userbuilds import need, program

ROOT = Path(__file__).resolve().parents[2]
LAYOUT = ROOT / "docs" / "foxglove-layout.json"
SAFE_90_US = 1472
#: examples/presses.proto's report rpc Changes: the third rpc (UserReport.report numbers the
#: rpcs in declaration order).
CHANGES = 3
#: An upper bound on how long a failing test waits; nothing is judged by it.
WAIT = 30.0


def _decoder(channel: dict[str, Any]) -> Callable[[bytes], Any]:
    """How to read one advertised channel's messages, from what the server advertised."""
    if channel["encoding"] == "json":
        return json.loads
    assert channel["schemaEncoding"] == "protobuf", channel
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for proto in files.file:
        pool.Add(proto)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))
    return cls.FromString


class Client:
    """Subscribes to every advertised channel; keeps each topic's decoded messages."""

    def __init__(self) -> None:
        self.channels: dict[int, dict[str, Any]] = {}
        self.decoders: dict[int, Callable[[bytes], Any]] = {}
        self.received: dict[str, list[Any]] = {}

    async def run(
        self,
        url: str,
        ready: Callable[[Client], bool],
        act: Callable[[], None],
        done: Callable[[Client], bool],
    ) -> None:
        """Subscribe; once ``ready`` holds, run ``act`` (in a thread); read on until ``done``."""
        acting: asyncio.Task[None] | None = None
        async with (
            aiohttp.ClientSession() as session,
            session.ws_connect(url, protocols=("foxglove.sdk.v1",)) as ws,
        ):
            async with asyncio.timeout(WAIT):
                async for message in ws:
                    if message.type == aiohttp.WSMsgType.TEXT:
                        await self._text(ws, json.loads(message.data))
                    elif message.type == aiohttp.WSMsgType.BINARY:
                        self._binary(message.data)
                    if acting is None and ready(self):
                        acting = asyncio.create_task(asyncio.to_thread(act))
                    if acting is not None and acting.done():
                        acting.result()  # the board's calls raised nothing
                        if done(self):
                            return

    async def _text(self, ws: aiohttp.ClientWebSocketResponse, op: dict[str, Any]) -> None:
        if op["op"] != "advertise":
            return
        subscriptions = []
        for channel in op["channels"]:
            self.channels[channel["id"]] = channel
            self.decoders[channel["id"]] = _decoder(channel)
            subscriptions.append({"id": channel["id"], "channelId": channel["id"]})
        await ws.send_json({"op": "subscribe", "subscriptions": subscriptions})

    def _binary(self, data: bytes) -> None:
        if data[0] != 0x01:  # MESSAGE_DATA: subscription id, log time, payload
            return
        subscription, _log_time = struct.unpack_from("<IQ", data, 1)
        topic = self.channels[subscription]["topic"]
        self.received.setdefault(topic, []).append(self.decoders[subscription](data[13:]))


def _servo_us(message: dict[str, Any], pin: int) -> int | None:
    return next((s["us"] for s in message["servos"] if s["pin"] == pin), None)


def seen(c: Client) -> bool:
    """Subscribed: the channels advertised and a first message (the counters) in."""
    return bool(c.channels) and "/protoduino/stats" in c.received


@pytest.fixture(params=["native", "avr"])
def backend(request: pytest.FixtureRequest) -> str:
    name: str = request.param
    return name


def test_live_channels_carry_outputs_inputs_counters_and_events(sim_board: SimBoard) -> None:
    sim = sim_board
    with Board.open(sim.port) as board, FoxgloveLive(board, port=0) as live:
        servo = board.servo(9, safe=90)
        pot = board.analog_input(14)
        client = Client()

        def act() -> None:
            servo.write(30)
            sim.set_analog(14, 700)
            pot.wait_for(lambda v: v == 700)
            board.read_outputs()
            board.stop()

        def done(c: Client) -> bool:
            outputs = c.received.get("/protoduino/outputs", [])
            inputs = c.received.get("/protoduino/inputs", [])
            events = c.received.get("/protoduino/events", [])
            return (
                any(_servo_us(m, 9) == servo.to_us(30) for m in outputs)
                and any(v["pin"] == 14 and v["value"] == 700 for m in inputs for v in m["values"])
                and any(e["event"] == "failsafe" and e.get("cause") == "stop" for e in events)
            )

        # Subscribed first (the channels advertised, a stats message in), then the board acts.
        asyncio.run(client.run(live.url, seen, act, done))

        # The protobuf channels decode with the schema the server advertised.
        commands = client.received["/protoduino/commands"]
        assert any(c.WhichOneof("data") == "servo_control" for c in commands), commands
        device = client.received["/protoduino/device"]
        assert any(d.WhichOneof("data") == "ack" for d in device)
        stats = client.received["/protoduino/stats"][-1]
        assert stats["acks"] > 0 and stats["state"] == "active", stats

        # The same channels as the MCAP export: topic, encoding, schema.
        advertised = {
            (c["topic"], c["encoding"], c["schemaName"]) for c in client.channels.values()
        }
        assert advertised == {(s.topic, s.message_encoding, s.schema_name) for s in channel_specs()}


def test_a_user_services_reports_go_live_in_their_own_schema(
    backend: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """examples/presses' Changes reports on /presses/changes, decoded as presses.Press with the
    schema the server advertised (not the test's own module)."""
    need(backend)
    mod = user_client("presses", monkeypatch)
    sim = SimBoard(backend, trace=tmp_path / "trace.jsonl", firmware=program("presses", backend))
    with sim:
        sim.start()
        with Board.open(sim.port) as board:
            presses = mod.Presses(board)
            reports = {"/presses/changes": (CHANGES, mod.pb.Press)}
            with FoxgloveLive(board, port=0, reports=reports) as live:
                received = Client()

                def act() -> None:
                    presses.watch_button(mod.pb.Watch(pin=2, debounce_ms=5))
                    sim.set_level(2, 0)

                def done(c: Client) -> bool:
                    return any(p.count >= 1 for p in c.received.get("/presses/changes", []))

                asyncio.run(received.run(live.url, seen, act, done))
    channel = next(c for c in received.channels.values() if c["topic"] == "/presses/changes")
    assert channel["schemaName"] == "presses.Press"
    press = received.received["/presses/changes"][-1]
    assert type(press).__module__ != mod.pb.__name__  # decoded from the advertised schema
    assert press.count >= 1 and not press.level


def test_the_shipped_layout_reads_channels_both_the_export_and_the_live_server_have() -> None:
    layout = json.loads(LAYOUT.read_text())
    text = json.dumps(layout["configById"])
    used = set(re.findall(r"(/protoduino/[a-z]+)", text))
    topics = {s.topic for s in channel_specs()}
    assert used and used <= topics, used - topics
    assert {"/protoduino/outputs", "/protoduino/inputs", "/protoduino/stats"} <= used

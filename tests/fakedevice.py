"""A scripted fake device in Python, on a pseudo-terminal, for what the real one won't do.

The host opens ``fake.port``, a symlink to the pty's slave, exactly as it would
open a real board; the fake speaks the wire protocol on the master side from
its own thread. It follows the device side of docs/protocol.md closely enough for
the host (RESET/RESET_ACK, SEQ, NOT_ACTIVE, one Ack per command, the dedupe
window, a pin table so that a reboot forgets the configuration), and every
reply goes through ``handler`` so a test can drop, duplicate, delay or corrupt
any of them. ``unplug()``/``replug()`` make the pty disappear and come back
under the same path, as a USB cable or a killed simulator would.

Pins: every pin mode of the schema is known (PWM and the inputs too), DeviceInfo
states the Uno's capabilities (``features``, ``pwm_pins``, ... are attributes a
test may change before the board opens), and the inputs report like the
firmware: an input's Init is answered by its Ack and then an InputReport with its
value; ``set_level``, ``set_analog`` and ``pulses`` change an input and report it.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from protoduino import __version__
from protoduino._generated import protoduino_pb2 as pb
from protoduino._generated.schema_id import SCHEMA_ID
from protoduino.commands import PIN_MODES, command
from protoduino.constants import (
    MAX_MESSAGE_ID,
    PROTOCOL_VERSION,
    ControlCode,
    EventCode,
    PacketType,
)
from protoduino.framing import StreamDecoder, frame_packet
from protoduino.messages import ArduinoIn, ArduinoOut, Status, serialize_out
from protoduino.packets import Packet, event_payload, parse_control, reset_ack_payload
from protoduino.testing import DedupeWindow

Reply = list[Any]


@dataclass
class Received:
    """One COMMAND the fake received (decoded), with its SEQ and arrival time."""

    seq: int
    msg: Any  # ArduinoIn
    t: float

    @property
    def kind(self) -> str:
        return str(self.msg.WhichOneof("data"))


def mask(pins: list[int] | set[int] | range) -> int:
    """A DeviceInfo/InputReport pin mask."""
    bits = 0
    for pin in pins:
        bits |= 1 << pin
    return bits


#: DeviceInfo.features with every pin mode built in.
ALL_FEATURES = sum(mode.feature_bit for mode in PIN_MODES)


def ack(message_id: int, status: int = Status.STATUS_OK) -> Any:
    out = ArduinoOut()
    out.ack.message_id = message_id
    out.ack.status = status  # type: ignore[assignment]
    return out


class FakeDevice:
    """See the module docstring. Use as a context manager."""

    def __init__(
        self,
        directory: Path,
        *,
        version: int = PROTOCOL_VERSION,
        schema_id: int = SCHEMA_ID,
        answer_reset: bool = True,
    ) -> None:
        self.port = str(directory / "fake-tty")
        self.version = version
        self.schema_id = schema_id
        self.answer_reset = answer_reset
        #: DeviceInfo.rx_buffer (0: not stated, the window alone limits the host).
        self.rx_buffer = 0
        #: DeviceInfo's board name ("uno" makes the host check Timer1's pins).
        self.board_name = "fake"
        #: DeviceInfo's features and pin capabilities (the Uno's by default).
        self.features = ALL_FEATURES
        self.pwm_pins = [3, 9, 10, 11]
        self.analog_pins = list(range(14, 20))
        self.counter_pins = [2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13]
        #: DeviceInfo.user_fingerprint: the user service it claims to carry (0: none).
        self.user_fingerprint = 0
        #: The inputs' state as the device sees it: levels by pin (1 until set:
        #: a pulled-up open switch), analog counts, edges counted.
        self.levels: dict[int, int] = {}
        self.analog: dict[int, int] = {}
        self.counts: dict[int, int] = {}
        #: Device clock for InputReport.time_ms (ms); a test moves it as it likes.
        self.time_ms = 0
        #: InputReport.coalesced of the next report.
        self.coalesced = 0
        #: Replies to a decoded, active COMMAND; replace to script faults.
        self.handler: Callable[[Any], Reply] = self.default_reply
        self.received: list[Received] = []
        self.resets = 0
        self.raw_rx = bytearray()
        self._cond = threading.Condition()
        self._active = False
        self._tx_seq = 0
        self._decoder = StreamDecoder()
        #: The dedupe window and newest id, with the firmware's rules.
        self.dedupe = DedupeWindow()
        #: pin -> "servo" | "digital"; forgotten on reboot, like a real device.
        self.pins: dict[int, str] = {}
        self.values: dict[int, int] = {}
        #: The session that owns the pins (0: none since power-up), and this power-up's id.
        self.session = 0
        self.boot_id = 0
        self._later: list[tuple[float, bytes]] = []
        self._master = -1
        self._slave = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._wlock = threading.Lock()

    # --- life cycle -------------------------------------------------------------

    def __enter__(self) -> FakeDevice:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        self.replug()
        self._thread = threading.Thread(target=self._run, name="fake-device", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.unplug()

    def unplug(self) -> None:
        """The pty disappears: the host's reads fail, the path is gone."""
        with self._wlock:
            for fd in (self._master, self._slave):
                if fd >= 0:
                    os.close(fd)
            self._master = self._slave = -1
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.port)

    def replug(self) -> None:
        """A new pty under the same path; the device boots (configuration forgotten)."""
        master, slave = os.openpty()
        tty.setraw(slave)
        tty.setraw(master)
        os.set_blocking(master, False)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.port)
        os.symlink(os.ttyname(slave), self.port)
        with self._wlock:
            self._master, self._slave = master, slave
        self._power_up()

    def reboot(self) -> None:
        """Restart the device on the same pty: state forgotten, EVENT BOOT sent."""
        self._power_up()

    def _power_up(self) -> None:
        with self._cond:
            self._active = False
            self._tx_seq = 0
            self._decoder.reset()
            self.dedupe = DedupeWindow()
            self.pins.clear()
            self.values.clear()
            self.session = 0
            self.boot_id += 1
        self.send_control(event_payload(EventCode.BOOT))

    # --- sending ------------------------------------------------------------------

    def send_raw(self, data: bytes, delay: float = 0.0) -> None:
        if delay > 0:
            with self._cond:
                self._later.append((time.monotonic() + delay, data))
            return
        with self._wlock:
            if self._master >= 0:
                with contextlib.suppress(OSError):
                    os.write(self._master, data)

    def send_burst(self, msgs: list[Any], timeout: float = 10.0) -> None:
        """Send DATA messages back to back, every byte (send_raw drops what a full pty refuses)."""
        data = b"".join(
            frame_packet(PacketType.DATA, self.next_seq(), serialize_out(m)) for m in msgs
        )
        view = memoryview(data)
        deadline = time.monotonic() + timeout
        with self._wlock:
            while view:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"the host read nothing for {timeout} s")
                select.select([], [self._master], [], 0.1)
                try:
                    view = view[os.write(self._master, view) :]
                except BlockingIOError:
                    continue

    def send_control(self, payload: bytes, *, seq: int | None = None) -> None:
        self.send_raw(frame_packet(PacketType.CONTROL, self.next_seq(seq), payload))

    def send_data(self, msg: Any, *, delay: float = 0.0, seq: int | None = None) -> None:
        payload = serialize_out(msg)  # a plain Ack in its short form, as the device sends it
        self.send_raw(frame_packet(PacketType.DATA, self.next_seq(seq), payload), delay)

    def next_seq(self, seq: int | None = None) -> int:
        """The SEQ for the next packet the fake sends (``seq``, if given, instead)."""
        with self._cond:
            if seq is not None:
                return seq
            seq, self._tx_seq = self._tx_seq, (self._tx_seq + 1) & 0xFF
            return seq

    def skip_seq(self, count: int) -> None:
        """Use up ``count`` SEQ numbers: to the host, that many packets lost on the way."""
        for _ in range(count):
            self.next_seq()

    @property
    def tx_seq(self) -> int:
        """The SEQ the fake's next packet will carry."""
        with self._cond:
            return self._tx_seq

    def forget(self) -> None:
        """Lose every pin, value and remembered id without a BOOT (a reset the host missed)."""
        with self._cond:
            self.pins.clear()
            self.values.clear()
            self.dedupe = DedupeWindow()

    # --- observing ------------------------------------------------------------------

    def commands(self, kind: str | None = None) -> list[Received]:
        with self._cond:
            return [r for r in self.received if kind is None or r.kind == kind]

    def wait_for(self, predicate: Callable[[], bool], timeout: float = 30.0) -> bool:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.05))
            return True

    # --- the device --------------------------------------------------------------------

    def default_reply(self, msg: Any) -> Reply:
        """Ack OK after a minimal execution (pin table, values, ping echo, info)."""
        mid = msg.message_id
        kind = msg.WhichOneof("data")
        declared = command(kind)
        if not 1 <= mid <= MAX_MESSAGE_ID:
            return [ack(mid, Status.STATUS_INVALID_ARGUMENT)]
        seen = self.dedupe.check(mid, lookup=not declared.idempotent)
        if seen is not None:
            return [ack(mid, seen)]
        out = ack(mid)
        if kind == "ping":
            out.ack.ping_echo = msg.ping.payload
        elif kind == "get_info":
            info = out.ack.info
            info.firmware_version = __version__
            info.protocol_version = self.version
            info.schema_id = self.schema_id
            info.board = self.board_name
            info.num_pins = 20
            info.max_servos = 8
            info.reserved_pins.extend([0, 1])
            info.rx_buffer = self.rx_buffer
            info.features = self.features
            info.pwm_pins = mask(self.pwm_pins)
            info.analog_pins = mask(self.analog_pins)
            info.counter_pins = mask(self.counter_pins)
            info.user_fingerprint = self.user_fingerprint
        elif declared.is_init:
            assert declared.pin_mode is not None
            pin = getattr(msg, kind).pin
            self.pins[pin] = declared.pin_mode.name
            if declared.pin_mode.is_input:  # its value follows the Ack, as on the device
                self.dedupe.add(mid, out.ack.status)
                return [out, self.report(**{self._report_kind(pin): [pin]})]
        elif declared.is_control:
            assert declared.pin_mode is not None
            ctl = getattr(msg, kind)
            if self.pins.get(ctl.pin) != declared.pin_mode.name:
                out.ack.status = Status.STATUS_NOT_INITIALISED
            else:
                self._apply(kind, ctl)
        elif kind == "release":
            self.pins.pop(msg.release.pin, None)
            self.values.pop(msg.release.pin, None)
        elif kind == "release_all":
            self.pins.clear()
            self.values.clear()
        elif kind == "pose":  # all or nothing; only the pin-mode check (what the tests need)
            # A PoseItem's oneof member is named after its pin mode ("servo", "digital"); the
            # masks' pins follow the items, upwards (protocol version 6), as on the device.
            items = [
                (i.WhichOneof("output"), getattr(i, i.WhichOneof("output"))) for i in msg.pose.items
            ]
            pose = msg.pose
            items += [
                ("digital", pb.DigitalControl(pin=pin, level=bool(pose.digital_levels >> pin & 1)))
                for pin in range(32)
                if pose.digital_pins >> pin & 1
            ]
            for n, (mode, ctl) in enumerate(items, 1):
                if self.pins.get(ctl.pin) != mode:
                    out.ack.status = Status.STATUS_NOT_INITIALISED
                    out.ack.refused_item = n
                    break
            else:
                for mode, ctl in items:
                    self._apply(f"{mode}_control", ctl)
        if not declared.idempotent:
            self.dedupe.add(mid, out.ack.status)
        return [out]

    # --- inputs ----------------------------------------------------------------------

    def _report_kind(self, pin: int) -> str:
        return {"analog_input": "analog", "counter": "counters"}.get(self.pins[pin], "digital")

    def report(self, *, digital: Any = (), analog: Any = (), counters: Any = ()) -> Any:
        """An InputReport as the firmware builds it: every digital input's level, and
        the analog inputs and counters named (``digital`` only asks for a report)."""
        del digital  # every digital input is in every report
        out = ArduinoOut()
        rep = out.input_report
        rep.time_ms = self.time_ms
        rep.coalesced, self.coalesced = self.coalesced, 0
        inputs = sorted(p for p, m in self.pins.items() if m == "digital_input")
        rep.digital_pins = mask(inputs)
        rep.digital_levels = mask([p for p in inputs if self.levels.get(p, 1)])
        rep.analog_pins = mask(analog)
        rep.analog_values.extend(self.analog.get(p, 0) for p in sorted(analog))
        rep.counter_pins = mask(counters)
        rep.counter_counts.extend(self.counts.get(p, 0) for p in sorted(counters))
        return out

    def set_level(self, pin: int, level: int) -> None:
        """A digital input changes (after its debounce): reported at once."""
        self.levels[pin] = int(level)
        self.send_data(self.report())

    def set_analog(self, pin: int, counts: int) -> None:
        self.analog[pin] = counts
        self.send_data(self.report(analog=[pin]))

    def pulses(self, pin: int, count: int) -> None:
        self.counts[pin] = self.counts.get(pin, 0) + count
        self.send_data(self.report(counters=[pin]))

    def failsafe(self, cause: int, *, active: bool = True, pin: int = 0, epoch: int = 1) -> None:
        """Send a Failsafe message (an interlock: cause FAILSAFE_CAUSE_INTERLOCK, its pin)."""
        out = ArduinoOut()
        out.failsafe.active = active
        out.failsafe.cause = cause  # type: ignore[assignment]
        out.failsafe.pin = pin
        out.failsafe.epoch = epoch
        self.send_data(out)

    def _apply(self, kind: str, ctl: Any) -> None:
        if kind == "digital_control":
            self.values[ctl.pin] = int(ctl.level)
        elif kind == "pwm_control":
            self.values[ctl.pin] = ctl.duty
        else:
            self.values[ctl.pin] = getattr(ctl, str(ctl.WhichOneof("value")))

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._wlock:
                master = self._master
            now = time.monotonic()
            with self._cond:
                due = [d for t, d in self._later if t <= now]
                self._later = [(t, d) for t, d in self._later if t > now]
            for data in due:
                self.send_raw(data)
            if master < 0:
                time.sleep(0.01)
                continue
            try:
                ready, _, _ = select.select([master], [], [], 0.01)
                data = os.read(master, 4096) if ready else b""
            except (OSError, ValueError):
                time.sleep(0.01)  # unplugged under us
                continue
            if data:
                with self._cond:
                    self.raw_rx += data
                for item in self._decoder.feed(data):
                    if isinstance(item, Packet):
                        self._packet(item)

    def _packet(self, packet: Packet) -> None:
        if packet.type is PacketType.CONTROL:
            ctl = parse_control(packet.payload)
            if ctl.code is ControlCode.RESET:
                with self._cond:
                    self.resets += 1
                    self._cond.notify_all()
                if not self.answer_reset:
                    return
                if (
                    self.version < 2
                    or ctl.version != self.version
                    or ctl.session is None
                    or (self.version >= 5 and not 1 <= (ctl.next_id or 0) <= MAX_MESSAGE_ID)
                ):
                    # Version 1, or a RESET of another version: the short answer, IDLE.
                    with self._cond:
                        self._active = self.version < 2 and ctl.version == self.version
                        self._tx_seq = 0
                    self.send_control(reset_ack_payload(self.version, self.schema_id))
                    return
                with self._cond:
                    self._active = True
                    self._tx_seq = 0
                    resumed = ctl.session != 0 and ctl.session == self.session
                    if not resumed:  # a new session: the pin table is freed
                        self.session = ctl.session
                        self.pins.clear()
                        self.values.clear()
                    if ctl.next_id is not None:
                        self.dedupe.sync(ctl.next_id, clear=not resumed)
                self.send_control(
                    reset_ack_payload(self.version, self.schema_id, self.boot_id, resumed)
                )
            return
        if packet.type is not PacketType.COMMAND:
            return
        if not self._active:
            self.send_control(event_payload(EventCode.NOT_ACTIVE))
            return
        msg = ArduinoIn()
        msg.ParseFromString(packet.payload)
        with self._cond:
            self.received.append(Received(packet.seq, msg, time.monotonic()))
            self._cond.notify_all()
        for out in self.handler(msg):
            self.send_data(out)

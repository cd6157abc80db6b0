"""The line-rate agreement's timing and its error, on the link alone with a stepped clock.

A device model answers RESET at the opening rate, switches on BAUD_SET and returns after
BAUD_CONFIRM; the line carries nothing at the faster rates (a bridge that cannot go faster).
Nothing here reads the wall clock: the test moves the clock to each time the link asks for.
"""

from __future__ import annotations

from protoduino._generated.schema_id import SCHEMA_ID
from protoduino.constants import (
    BAUD_CONFIRM,
    FAST_BAUDRATES,
    OPENING_BAUDRATE,
    PROTOCOL_VERSION,
    ControlCode,
    PacketType,
)
from protoduino.errors import ProtoduinoError
from protoduino.events import Event
from protoduino.link import Link, LinkState
from protoduino.messages import ArduinoOut
from protoduino.packets import Packet, baud_payload, parse_control, reset_ack_payload
from protoduino.transport import TransportListener


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class SlowLine:
    """The host's port on a line that carries only the opening rate, with a device behind
    it that answers once ``boot`` (its bootloader's time) has passed."""

    def __init__(self, clock: Clock, boot: float) -> None:
        self.url = self.name = "line://"
        self.connected = True
        self.rx_since_open = 0
        self.rx_head = b""
        self.baudrate = OPENING_BAUDRATE
        self.clock = clock
        self.ready_at = clock.now + boot
        self.answer_resets = True
        self.device_rate = OPENING_BAUDRATE
        self.device_back_at = 0.0  # when an unconfirmed switch reverts
        self.link: Link | None = None
        self.resets_answered = 0

    def start(self, listener: TransportListener) -> None:
        pass

    def close(self) -> None:
        self.connected = False

    def clear_queue(self) -> None:
        pass

    def set_baudrate(self, rate: int) -> None:
        self.baudrate = rate

    def recent_frames(self) -> tuple[str, ...]:
        return ()

    def send(self, ptype: PacketType, payload: bytes, *, reset_seq: bool = False) -> None:
        now = self.clock.now
        if self.device_rate != OPENING_BAUDRATE and now >= self.device_back_at:
            self.device_rate = OPENING_BAUDRATE  # BAUD_CONFIRM ran out
        if now < self.ready_at or self.baudrate != self.device_rate:
            return  # the bootloader, or a rate mismatch: lost
        if self.device_rate != OPENING_BAUDRATE:
            return  # the line carries no faster rate
        ctl = parse_control(payload)
        if ctl.code is ControlCode.RESET and self.answer_resets:
            self.resets_answered += 1
            self._answer(reset_ack_payload(PROTOCOL_VERSION, SCHEMA_ID, 7, False, FAST_BAUDRATES))
        elif ctl.code is ControlCode.BAUD_SET:
            self._answer(baud_payload(ControlCode.BAUD_ACK, ctl.baudrate or 0))
            self.device_rate = ctl.baudrate or OPENING_BAUDRATE
            self.device_back_at = now + BAUD_CONFIRM

    def _answer(self, payload: bytes) -> None:
        assert self.link is not None
        self.link.transport_received([Packet(PacketType.CONTROL, 0, payload)])


class Above:
    """The request layer's part: nothing outstanding."""

    def link_up(self, lost: bool, rebooted: bool) -> None:
        pass

    def link_down(self, reason: str) -> None:
        pass

    def link_message(self, msg: ArduinoOut) -> None:
        pass

    def link_failed(self, error: ProtoduinoError) -> None:
        pass

    def link_tick(self, now: float) -> float:
        return now + 1.0

    def expect_traffic(self) -> bool:
        return False


def _handshake(boot: float, timeout: float = 5.0) -> tuple[Link, SlowLine, Clock]:
    """Run the first handshake to its end (ACTIVE or its timeout), stepping the clock."""
    clock = Clock()
    line = SlowLine(clock, boot)
    events: list[Event] = []
    link = Link(line, Above(), handshake_timeout=timeout, notify=events.append, clock=clock)
    line.link = link
    start = clock.now
    link.transport_opened(False)
    _run(link, clock, until=start + 10.0)
    return link, line, clock


def _run(link: Link, clock: Clock, until: float) -> None:
    """Tick the link at each time it asks for, until it leaves WAIT_ACK (the clock then
    reads when it did) or ``until``."""
    while clock.now < until:
        due = link.transport_tick(clock.now)
        if link.state is not LinkState.WAIT_ACK:
            return
        clock.now = max(clock.now, due)


def test_every_rate_fails_and_the_handshake_fits_its_budget_behind_a_bootloader() -> None:
    # Optiboot after the open's reset: about 1.5 s of the 5 s before the firmware answers.
    link, line, clock = _handshake(boot=1.5)
    assert link.state is LinkState.ACTIVE
    assert line.baudrate == OPENING_BAUDRATE
    assert link.failed_baudrates == set(FAST_BAUDRATES)
    # Each fallback costs the probes and the device's return, not the handshake's grown
    # retry delay (it was 1 s per RESET then: 5 s ran out after two of the three rates).
    assert link._hs_started + 3.0 > clock.now


def test_a_late_device_gets_the_opening_rate_rather_than_no_link() -> None:
    # The firmware answers the RESET 3.5 s into a 4 s budget: no time for an agreement
    # that may fail (three rates failing one after the other took it past 4 s).
    link, line, _ = _handshake(boot=3.2, timeout=4.0)
    assert link.state is LinkState.ACTIVE
    assert line.baudrate == OPENING_BAUDRATE


def test_a_handshake_that_heard_reset_acks_says_so() -> None:
    # The device answers its first RESET and then never again: the agreement's fallback
    # leaves the handshake unfinished. The error says what came back, not "nothing".
    clock = Clock()
    line = SlowLine(clock, boot=0.0)
    link = Link(line, Above(), handshake_timeout=5.0, notify=lambda e: None, clock=clock)
    line.link = link
    link.transport_opened(False)
    line.answer_resets = False
    _run(link, clock, until=clock.now + 10.0)
    assert link.state is LinkState.FAILED
    text = str(link.down_error)
    assert "received nothing" not in text
    assert "answered RESET" in text and "RESET_ACKs" in text
    assert "1000000" in text  # the rate that failed


class Line(SlowLine):
    """A line that carries every rate, and loses what ``lose`` names: the next RESETs that
    reach the device at a rate (``("reset", rate)``: lost on the way in, so a switch stays
    unconfirmed) or their RESET_ACKs (``("ack", rate)``: the device took the RESET)."""

    def __init__(self, clock: Clock) -> None:
        super().__init__(clock, boot=0.0)
        self.lose: dict[tuple[str, int], int] = {}
        self.confirmed = True

    def reset_device(self) -> None:
        """A reset: back at the opening rate, the link state gone."""
        self.device_rate = OPENING_BAUDRATE
        self.confirmed = True

    def _lost(self, what: str) -> bool:
        left = self.lose.get((what, self.device_rate), 0)
        if left:
            self.lose[(what, self.device_rate)] = left - 1
        return left > 0

    def send(self, ptype: PacketType, payload: bytes, *, reset_seq: bool = False) -> None:
        now = self.clock.now
        if not self.confirmed and now >= self.device_back_at:
            self.device_rate, self.confirmed = OPENING_BAUDRATE, True  # BAUD_CONFIRM ran out
        if self.baudrate != self.device_rate or ptype is not PacketType.CONTROL:
            return  # a rate mismatch, or a command the model leaves unanswered
        ctl = parse_control(payload)
        if ctl.code is ControlCode.RESET:
            if self._lost("reset"):
                return
            self.confirmed = True
            if not self._lost("ack"):
                self._answer(
                    reset_ack_payload(PROTOCOL_VERSION, SCHEMA_ID, 7, False, FAST_BAUDRATES)
                )
        elif ctl.code is ControlCode.BAUD_SET:
            self._answer(baud_payload(ControlCode.BAUD_ACK, ctl.baudrate or 0))
            if ctl.baudrate != self.device_rate:
                self.device_rate = ctl.baudrate or OPENING_BAUDRATE
                self.confirmed = False
                self.device_back_at = now + BAUD_CONFIRM


def _recovery(lose: dict[tuple[str, int], int]) -> tuple[float, Line]:
    """How long a link that agreed the fastest rate takes to be ACTIVE again after its
    device reset, with ``lose`` (Line's) lost on the way; and the line."""
    clock = Clock()
    line = Line(clock)
    link = Link(line, Above(), handshake_timeout=5.0, notify=lambda e: None, clock=clock)
    line.link = link
    link.transport_opened(False)
    _run(link, clock, until=clock.now + 5.0)
    assert link.state is LinkState.ACTIVE and line.baudrate == max(FAST_BAUDRATES)
    line.reset_device()
    line.lose = dict(lose)
    start = clock.now
    link.request_handshake()  # as the silence at an agreed rate does
    link.transport_tick(clock.now)
    _run(link, clock, until=start + 10.0)
    assert link.state is LinkState.ACTIVE
    return clock.now - start, line


def test_a_device_that_reset_is_found_at_the_opening_rate_though_a_reset_there_is_lost() -> None:
    took, line = _recovery({("reset", OPENING_BAUDRATE): 1})
    # Retries at 0.1 s (the opening rate: lost), 0.3 (the agreed rate), 0.7 (the opening
    # rate again): found there, where its next turn came at 4.5 s (the soak's calls timed
    # out at 6 s when that one was lost too).
    assert took < 1.0, took
    assert line.baudrate == max(FAST_BAUDRATES)  # and the rate agreed again


def test_a_lost_answer_to_the_reset_confirming_a_rate_is_retried_at_once() -> None:
    # The device confirmed the switch (it took the RESET): it stays at the fast rate.
    took, line = _recovery({("ack", max(FAST_BAUDRATES)): 1})
    # The confirming RESET's retries start from the first delay: its next turn at the
    # fast rate 0.3 s on, where the grown backoff made it 1.2 s (and then 2 s a turn).
    assert took < 1.0, took
    assert line.baudrate == max(FAST_BAUDRATES)


def test_a_lost_reset_confirming_a_rate_finds_the_device_back_at_the_opening_rate() -> None:
    # Unconfirmed, the device returns to the opening rate after BAUD_CONFIRM.
    took, _ = _recovery({("reset", max(FAST_BAUDRATES)): 1})
    assert took < 1.5, took

"""The request layer's call bound, on an injected clock: no thread, no port, no wall clock.

``Rpc`` is driven exactly as the transport's I/O thread drives it: a tick at
``now`` returns when the timers next need to run, and the thread sleeps until
then, or TICK at most. The clock only moves when the test moves it, so every
verdict is exact.
"""

from __future__ import annotations

from typing import Any

import pytest
from protoduino.errors import AckTimeoutError, LinkError, ProtoduinoError
from protoduino.events import Event
from protoduino.messages import ArduinoIn, ArduinoOut
from protoduino.rpc import Call, Rpc
from protoduino.transport import TICK

ACK_TIMEOUT = 0.25
MAX_RETRIES = 3
START = 100.0


class Clock:
    def __init__(self) -> None:
        self.now = START

    def __call__(self) -> float:
        return self.now


class FakeLink:
    """What Rpc uses of a Link: an always-up link that records when each command left."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.active = True
        self.down_error: ProtoduinoError | None = None
        self.reboots = 0
        self.sent: list[float] = []

    def reboot_inferred(self) -> None:
        self.reboots += 1

    def send_command(self, payload: bytes) -> bool:
        if self.active:
            self.sent.append(self.clock.now)
        return self.active

    def recent_frames(self) -> tuple[str, ...]:
        return ()

    def request_handshake(self) -> None:
        pass


def setup() -> tuple[Clock, FakeLink, Rpc]:
    clock = Clock()
    events: list[Event] = []
    rpc = Rpc(
        notify=events.append,
        ack_timeout=ACK_TIMEOUT,
        max_retries=MAX_RETRIES,
        ping=False,
        link_wait=5.0,
        clock=clock,
    )
    link = FakeLink(clock)
    rpc.attach(link)
    return clock, link, rpc


def ping() -> ArduinoIn:
    msg = ArduinoIn()
    msg.ping.SetInParent()
    return msg


def finished_at(clock: Clock, rpc: Rpc, call: Call, wake: Any) -> float:
    """Tick until ``call`` is done, waking when ``wake(now, due)`` says; the time it finished."""
    for _ in range(10_000):
        due = rpc.link_tick(clock.now)
        if call.done.is_set():
            return clock.now
        nxt = wake(clock.now, due)
        assert nxt > clock.now, "a tick that asks to run again at once would spin"
        clock.now = nxt
    raise AssertionError("the call never finished")


def test_a_call_without_ack_fails_exactly_at_the_bound() -> None:
    clock, link, rpc = setup()
    call = rpc.submit(ping())
    # The I/O thread's loop: sleep until the due time, TICK at most.
    end = finished_at(clock, rpc, call, lambda now, due: min(due, now + TICK))
    assert isinstance(call.error, AckTimeoutError)
    assert end - START == ACK_TIMEOUT * (MAX_RETRIES + 1)
    assert link.sent == [START + k * ACK_TIMEOUT for k in range(MAX_RETRIES + 1)]


def test_late_ticks_do_not_add_up() -> None:
    # A thread that only wakes on a coarse grid (every TICK, out of phase with the
    # schedule): each attempt goes out at the first wake-up after it is due, and a
    # late one does not push the next back. Retrying from the previous transmission
    # instead lost up to a TICK per attempt (1.066 s for a 1.0 s bound).
    clock, link, rpc = setup()
    call = rpc.submit(ping())
    grid = [START + 0.013 + k * TICK for k in range(200)]

    def wake(now: float, due: float) -> float:
        return next(t for t in grid if t > now)

    end = finished_at(clock, rpc, call, wake)
    first_after = [next(t for t in grid if t >= START + k * ACK_TIMEOUT) for k in range(1, 5)]
    assert link.sent == [START, *first_after[:3]]
    assert end == first_after[3]
    assert end - START < ACK_TIMEOUT * (MAX_RETRIES + 1) + TICK


def test_an_ack_in_time_completes_without_retry() -> None:
    clock, link, rpc = setup()
    call = rpc.submit(ping())
    clock.now += ACK_TIMEOUT * 0.9
    assert rpc.link_tick(clock.now) == START + ACK_TIMEOUT  # the first retransmission
    out = ArduinoOut()
    out.ack.message_id = call.message_id
    rpc.link_message(out)
    assert call.done.is_set() and call.error is None
    assert call.rtt == pytest.approx(ACK_TIMEOUT * 0.9)
    assert link.sent == [START]


def test_a_link_failed_for_good_fails_every_call_at_once() -> None:
    clock, link, rpc = setup()
    inflight = rpc.submit(ping())
    link.active = False  # the device rebooted: the call waits for the link
    rpc.link_down("device rebooted")
    clock.now += 0.1
    rpc.link_tick(clock.now)
    assert not inflight.done.is_set()
    error = LinkError("another protocol version")
    rpc.link_failed(error)
    assert inflight.done.is_set() and inflight.error is error
    commands = rpc.commands
    with pytest.raises(LinkError, match="another protocol version"):
        rpc.submit(ping())
    assert rpc.commands == commands  # refused before it was queued

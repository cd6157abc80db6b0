"""Late bytes, unseen failsafes (issue 20, items 1, 2 and 4), on both boards, judged at the pin.

The line is ``faulty://`` with ``hold()``: every byte in the held direction is
kept back, then delivered late and in order by ``release()``, as a paused
ser2net or a Wi-Fi outage that TCP survives does. The failsafe epoch
(docs/protocol.md section 7) is what must hold here: a Ping or a Control
written before the failsafe fired never re-arms an output after it, and the
host learns of every failsafe the device entered, even one whose event it
never read.

Servo widths (min 544, max 2400 us): 10 degrees is 647 us, 30 is 853, 90 (the
safe value) 1472, 170 is 2296.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from protoduino import Board, EventKind
from protoduino.errors import ProtoduinoError
from protoduino.events import Event
from protoduino.simboard import SimBoard
from protoduino_dev import faults
from simfixtures import PULSE_TOLERANCE_US, pin_values, wait_for_pin

#: Runs on the emulated Mega too: the failsafe against late bytes (tests/README.md).
pytestmark = pytest.mark.mega

SAFE_US = 1472
BEFORE_US = 647
LATE_US = 2296
AFTER_US = 853


def near(value: int, us: int) -> bool:
    return abs(value - us) <= PULSE_TOLERANCE_US


class Events:
    """Every event of a board, in order, and a way to wait for one."""

    def __init__(self, board: Board) -> None:
        self.events: list[Event] = []
        self._cond = threading.Condition()
        board.on_event(self._add)

    def _add(self, event: Event) -> None:
        with self._cond:
            self.events.append(event)
            self._cond.notify_all()

    def failsafes(self) -> list[dict[str, Any]]:
        with self._cond:
            return [dict(e.details) for e in self.events if e.kind is EventKind.FAILSAFE]

    def wait(self, ok: Any, what: str, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not ok():
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"{what}: events {self.events}")
                self._cond.wait(left)

    def active_then_cleared(self) -> bool:
        seen = [f["active"] for f in self.failsafes()]
        return True in seen and False in seen[seen.index(True) :]


@pytest.fixture
def line_url(sim_board: SimBoard) -> Iterator[tuple[str, str]]:
    name = f"late-{os.getpid()}-{id(sim_board)}"
    yield f"faulty://{sim_board.port}?paused=1&name={name}", name


def _line(name: str) -> faults.FaultyLine:
    line = faults.line(name)
    assert line is not None
    return line


def test_late_pings_and_writes_never_rearm_the_failsafe(
    sim_board: SimBoard, line_url: tuple[str, str]
) -> None:
    """Item 1: both directions held past the failsafe; the held Pings (written before it
    fired) and the held write reach the device after it: the pin stays safe, the write is
    refused, the host reports the failsafe, and only its own re-arm lets a new value run."""
    url, name = line_url
    with Board.open(url, failsafe_timeout=0.5, watchdog_timeout=3.0) as board:
        events = Events(board)
        servo = board.servo(9, safe=90)
        servo.write(10)
        wait_for_pin(sim_board, 9, lambda v: bool(v) and near(v[-1], BEFORE_US))
        line = _line(name)
        line.hold("both")
        # Written before the failsafe fires, delivered after it: a sign of life, then a
        # value (the order a control loop sends them in).
        late_ping = board.submit_ping()
        late = servo.submit(170)
        # The failsafe fires on the device while everything is held.
        values = wait_for_pin(sim_board, 9, lambda v: near(v[-1], SAFE_US))
        fired_at = len(values)
        for call in (late_ping, late):
            with pytest.raises(ProtoduinoError):
                call.result(timeout=10)  # the host gave up on it (AckTimeoutError)
        assert not events.failsafes()  # nothing was heard while held
        line.release()
        events.wait(events.active_then_cleared, "failsafe active, then re-armed by the host")
        first = events.failsafes()[0]
        assert first["active"] and first["cause"] == "ping_timeout" and first["epoch"] == 1
        # At the pin: nothing but the safe width since the failsafe, the late write included.
        after = pin_values(sim_board.trace(), 9)[fired_at - 1 :]
        assert all(near(v, SAFE_US) for v in after), after
        assert servo.value == SAFE_US
        # The host saw it and re-armed: a new value runs.
        servo.write(30)
        wait_for_pin(sim_board, 9, lambda v: near(v[-1], AFTER_US))
        assert not any(near(v, LATE_US) for v in pin_values(sim_board.trace(), 9))


def test_a_failsafe_whose_event_is_lost_is_still_reported(
    sim_board: SimBoard, line_url: tuple[str, str]
) -> None:
    """Item 4: held past the host's watchdog, so the re-handshake runs before the held
    FAILSAFE event is read (and dropped as traffic from before it); the Ack of the next
    Ping tells the host: it reports the failsafe before it re-arms, and ``value`` is safe."""
    url, name = line_url
    with Board.open(url, failsafe_timeout=0.5, watchdog_timeout=1.0) as board:
        events = Events(board)
        servo = board.servo(9, safe=90)
        servo.write(10)
        wait_for_pin(sim_board, 9, lambda v: bool(v) and near(v[-1], BEFORE_US))
        line = _line(name)
        line.hold("both")
        fired_at = len(wait_for_pin(sim_board, 9, lambda v: near(v[-1], SAFE_US)))
        deadline = time.monotonic() + 10
        while board.stats.watchdog_resets < 1:  # the host gave up on the silent link
            assert time.monotonic() < deadline, board.stats
            time.sleep(0.02)
        line.release()
        events.wait(events.active_then_cleared, "failsafe active, then cleared")
        assert servo.value == SAFE_US
        flags = [f["active"] for f in events.failsafes()]
        assert flags[0] is True  # never a "cleared" without its "active" first
        after = pin_values(sim_board.trace(), 9)[fired_at - 1 :]
        assert all(near(v, SAFE_US) for v in after), after


def test_restore_last_never_undoes_a_failsafe_it_did_not_hear_of(
    sim_board: SimBoard, line_url: tuple[str, str]
) -> None:
    """Item 2: the device-to-host direction cut (its FAILSAFE event is lost for good), the
    other held; the failsafe fires, the device reboots, then the line heals: the host never
    heard of the failsafe, so restore="last" must bring the servo up at its safe width
    only, never the value from before the failsafe (the host infers it: no liveness
    message was acknowledged within the timeout before the outputs were lost)."""
    url, name = line_url
    url = url.replace("?", "?dir=rx&drop=1&", 1)
    with Board.open(url, failsafe_timeout=0.5, watchdog_timeout=3.0, restore="last") as board:
        events = Events(board)
        servo = board.servo(9, safe=90)
        servo.write(30)
        wait_for_pin(sim_board, 9, lambda v: bool(v) and near(v[-1], AFTER_US))
        line = _line(name)
        line.resume()  # every byte from the device is lost from now on
        line.hold("tx")
        values = wait_for_pin(sim_board, 9, lambda v: near(v[-1], SAFE_US))
        sim_board.reboot()
        # The reboot releases the servo: its pulses stop (the trace shows 0).
        values = wait_for_pin(sim_board, 9, lambda v: len(v) > len(values) and v[-1] == 0)
        mark = len(values)
        line.heal()
        line.release()
        events.wait(lambda: any(e.kind is EventKind.RESTORED for e in events.events), "the restore")
        restored = [e for e in events.events if e.kind is EventKind.RESTORED][-1]
        wait_for_pin(sim_board, 9, lambda v: len(v) > mark and near(v[-1], SAFE_US))
        after = pin_values(sim_board.trace(), 9)[mark:]
        assert all(near(v, SAFE_US) for v in after), after
        assert servo.value == SAFE_US
        assert restored.details["replayed"] == 2  # ConfigureFailsafe and the Init, no value
        assert not any(f["active"] for f in events.failsafes())  # its event never came

"""The failsafe in every path (issue 10), on every board (the Mega too), judged at the pins on
the board's clock.

Each test configures a short failsafe timeout T, so that the suite stays fast
(the 10 s default is covered by the slow tests in test_sim_e2e and
test_board_sim). Its verdict is the trace's: the last sign of life is
bracketed on the board's own clock by two edges of a marker pin (13) sent
right before and right after it, and the failsafe must put pin 12 (a digital
output commanded on, safe off) and pin 9 (a servo commanded to 10 degrees,
safe 90) at their safe values no earlier than T after the first edge and no
later than T (plus one servo frame for the servo) after the second.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from typing import Any

import protoduino
import pytest
import serial
from protoduino import Board, DigitalOutput, EventKind, Servo
from protoduino.constants import ControlCode, PacketType
from protoduino.framing import StreamDecoder, frame_packet
from protoduino.messages import ArduinoIn, Status, parse_out
from protoduino.packets import Packet, parse_control, reset_payload
from protoduino.simboard import SimBoard
from protoduino_dev import faults
from simfixtures import PULSE_TOLERANCE_US, pin_values

#: The safety tests run on the emulated Mega too (tests/README.md).
pytestmark = pytest.mark.mega

SAFE_90_US = 1472
#: The device checks its timer every millisecond; the trace dates edges to the microsecond.
POLL = 0.003
#: A servo shows a new width at its next frame: the failsafe starts one at once, and the
#: emulated Uno's channel may come up to 2.6 ms into it.
FRAME = 0.020 + 0.003


@pytest.fixture
def sim(sim_board: SimBoard) -> SimBoard:
    return sim_board


def _lines(sim: SimBoard, pin: int) -> list[dict[str, Any]]:
    return [c for c in sim.trace() if c["pin"] == pin]


def _wait_trace(sim: SimBoard, ok: Any, timeout: float, what: str) -> Any:
    """Poll the trace until ``ok(trace)`` returns something; the timeout only bounds a failure."""
    deadline = time.monotonic() + timeout
    while True:
        found = ok(sim.trace())
        if found is not None:
            return found
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: the trace shows {sim.trace()}")
        time.sleep(0.02)


class Rig:
    """Pin 9 a servo at 10 degrees (safe 90), pin 12 on (safe off), pin 13 the marker."""

    def __init__(self, board: Board, sim: SimBoard) -> None:
        self.board, self.sim = board, sim
        self.servo: Servo = board.servo(9, safe=90)
        self.out: DigitalOutput = board.digital_output(12, safe=False)
        board.digital_output(13, safe=False)  # the marker
        self.marks = 0

    def command(self) -> None:
        self.servo.write(10)
        self.out.on()

    def bracket(self, alive: Any) -> tuple[float, float]:
        """Run ``alive()`` (the last sign of life) between two marker edges; their times.

        The edges are Inits (safe level high, then low): they drive the pin and,
        unlike a Control, run even while the failsafe timer has run out.
        """
        self.board.digital_output(13, safe=True)
        alive()
        self.board.digital_output(13, safe=False)
        self.marks += 1
        n = self.marks

        def edges(trace: list[dict[str, Any]]) -> tuple[float, float] | None:
            lines = [c for c in trace if c["pin"] == 13]
            ons = [i for i, c in enumerate(lines) if c["value"] == 1]
            if len(ons) < n or ons[n - 1] + 1 >= len(lines):
                return None
            return lines[ons[n - 1]]["t"], lines[ons[n - 1] + 1]["t"]

        result: tuple[float, float] = _wait_trace(self.sim, edges, 5.0, "marker edges")
        return result


#: With this set to a file name, every measurement is appended to it as one JSON line
#: (the figures in docs/reliability.md, "The failsafe in every path").
FIGURES = os.environ.get("PROTODUINO_FAILSAFE_FIGURES")


def _record(
    sim: SimBoard, timeout: float, alive: tuple[float, float], digital: float, servo: float
) -> None:
    if not FIGURES:
        return
    test = os.environ.get("PYTEST_CURRENT_TEST", "?").split("::")[-1].split(" ")[0]
    line = {
        "test": test,
        "backend": sim.backend,
        "board": sim.board,
        "timeout": timeout,
        "window": alive[1] - alive[0],
        # the failsafe at the pin, from the earliest and the latest the last sign of life was
        "digital": [digital - alive[1], digital - alive[0]],
        "servo": [servo - alive[1], servo - alive[0]],
    }
    with open(FIGURES, "a") as out:
        out.write(json.dumps(line) + "\n")


def assert_failsafe_on_time(
    sim: SimBoard, alive: tuple[float, float], timeout: float, *, commanded_after: float = 0.0
) -> None:
    """Pins 12 and 9 went safe T after the bracketed sign of life, not before, not later.

    ``commanded_after``: trace lines up to then are ignored, so that a return to safe
    from an earlier failsafe (a servo's is dated to its first pulse, a frame before it is
    written) is never taken for this one.
    """
    first, last = alive

    def safe_line(pin: int, value: int) -> Any:
        def find(trace: list[dict[str, Any]]) -> dict[str, Any] | None:
            # The first return to the safe value from a commanded one, after `first` (the
            # emulated Uno dates a servo's Init only once it measured two frames of it).
            commanded = False
            for c in trace:
                if c["pin"] != pin or c["t"] <= commanded_after:
                    continue
                if abs(c["value"] - value) > tol:
                    commanded = True
                elif commanded and c["t"] > first:
                    return c
            return None

        tol = PULSE_TOLERANCE_US if pin == 9 else 0
        line: dict[str, Any] = _wait_trace(sim, find, timeout + 5.0, f"pin {pin} safe")
        return line["t"]

    digital = safe_line(12, 0)
    servo = safe_line(9, SAFE_90_US)
    _record(sim, timeout, alive, digital, servo)
    assert first + timeout - POLL <= digital <= last + timeout + POLL, (alive, digital)
    assert first + timeout - POLL <= servo <= last + timeout + POLL + FRAME, (alive, servo)


def test_after_stop_a_later_command_is_still_protected(sim: SimBoard) -> None:
    """Defect 1: servo(9, safe=90), stop(), write(10), host gone: 10 degrees must not stay."""
    t = 1.0  # room for the commands that follow the sign of life on a busy machine
    with Board.open(sim.port, ping=False, failsafe_timeout=t) as board:
        rig = Rig(board, sim)
        alive = rig.bracket(board.ping)
        board.stop()
        rig.command()  # after the Stop
    assert_failsafe_on_time(sim, alive, t)


def test_after_a_failsafe_controls_wait_for_life_and_are_protected_again(sim: SimBoard) -> None:
    """Defect 1: once the timer ran out nothing is commanded until a sign of life."""
    t = 1.0  # room for the commands that follow the sign of life on a busy machine
    with Board.open(sim.port, ping=False, failsafe_timeout=t) as board:
        events: list[protoduino.Event] = []
        board.on_event(events.append)
        rig = Rig(board, sim)
        rig.command()
        alive = rig.bracket(board.ping)
        assert_failsafe_on_time(sim, alive, t)
        with pytest.raises(protoduino.CommandRejectedError) as info:
            rig.servo.write(45)
        assert info.value.status == Status.STATUS_FAILSAFE_EXPIRED
        assert abs(pin_values(sim.trace(), 9)[-1] - SAFE_90_US) <= PULSE_TOLERANCE_US
        alive = rig.bracket(board.ping)  # a sign of life: commands run again ...
        rig.command()
        # ... protected again: judged from the command after the sign of life
        assert_failsafe_on_time(sim, alive, t, commanded_after=alive[1])
    assert [e.details["active"] for e in events if e.kind is EventKind.FAILSAFE][:2] == [
        True,
        False,
    ]


def test_a_board_the_host_stalls_keeps_its_failsafe_on_its_own_clock(sim: SimBoard) -> None:
    """The board's process stopped (SIGSTOP) past its failsafe deadline, as a loaded
    host can keep it waiting: once it runs again, the failsafe is still dated T after the
    last sign of life on the board's clock. The native board's clock counts a gap between
    two of its readings as 1.5 ms at most (pd_sim.c, SIM_MAX_STEP); on the wall clock it
    fired at the resume, the whole stop late. The emulated Uno's time is emulated cycles."""
    t = 1.0  # room for the commands that follow the sign of life on a busy machine
    with Board.open(sim.port, ping=False, failsafe_timeout=t) as board:
        rig = Rig(board, sim)
        rig.command()
        alive = rig.bracket(board.ping)
        os.kill(sim.pid, signal.SIGSTOP)
        try:
            time.sleep(t + 0.5)  # the stop outlasts the deadline; its length is not judged
        finally:
            os.kill(sim.pid, signal.SIGCONT)
        assert_failsafe_on_time(sim, alive, t)


def test_ping_false_explicit_ping_is_the_only_life(sim: SimBoard) -> None:
    t = 1.0  # room for the commands that follow the sign of life on a busy machine
    with Board.open(sim.port, ping=False, failsafe_timeout=t) as board:
        rig = Rig(board, sim)
        rig.command()
        alive = rig.bracket(board.ping)
        assert_failsafe_on_time(sim, alive, t)


def test_application_heartbeat_that_stops_trips_the_failsafe(sim: SimBoard) -> None:
    """liveness="heartbeat": the automatic Ping keeps the link up, not the outputs."""
    t = 1.0
    with Board.open(sim.port, failsafe_timeout=t, liveness="heartbeat") as board:
        rig = Rig(board, sim)
        rig.command()
        for _ in range(5):  # a control loop that beats well within T keeps them
            board.heartbeat()
            time.sleep(t / 5)
        assert pin_values(sim.trace(), 12)[-1] == 1
        alive = rig.bracket(board.heartbeat)  # the loop's last beat: it hangs
        assert_failsafe_on_time(sim, alive, t)
        assert board.pinging and board.stats.ping_failures == 0  # the link was fine


def test_a_ping_is_no_heartbeat(sim: SimBoard) -> None:
    t = 1.0  # room for the commands that follow the sign of life on a busy machine
    with Board.open(sim.port, ping=False, failsafe_timeout=t, liveness="heartbeat") as board:
        rig = Rig(board, sim)
        rig.command()

        alive = rig.bracket(board.heartbeat)
        for _ in range(3):
            board.ping()  # answered, but not liveness here
        assert_failsafe_on_time(sim, alive, t)


@pytest.fixture
def deaf_line(sim: SimBoard) -> Iterator[str]:
    name = f"deaf-{os.getpid()}-{id(sim)}"
    yield f"faulty://{sim.port}?dir=rx&drop=1&paused=1&name={name}"


def test_a_host_that_cannot_hear_the_device_does_not_keep_outputs_alive(
    sim: SimBoard, deaf_line: str
) -> None:
    """Defect 2: device-to-host cut; the host's watchdog re-handshakes (every RESET used to
    restart the timer). Only the liveness message feeds it: the failsafe fires."""
    t = 2.0  # longer than the RESET backoff (<= 1 s), which the old firmware let feed it
    # watchdog 1 s: the re-handshakes start sooner, the test is shorter.
    with Board.open(deaf_line, failsafe_timeout=t, watchdog_timeout=1.0) as board:
        rig = Rig(board, sim)
        rig.command()
        name = deaf_line.rsplit("name=", 1)[1]
        line = faults.line(name)
        assert line is not None

        def deafen() -> None:
            line.resume()  # from now on every byte from the device is lost

        start, _ = rig.bracket(lambda: None)
        deafen()
        # The host still pings until its watchdog gives up on the silent link, then sends
        # RESET after RESET: none of them may keep the outputs alive.
        assert_failsafe_on_time(sim, (start, start + 1.0 + 2 * t / 4 + 0.3), t)
        assert board.stats.watchdog_resets >= 1
        line.heal()


CHILD = textwrap.dedent(
    """
    import sys
    import protoduino
    board = protoduino.Board.open(sys.argv[1], failsafe_timeout=float(sys.argv[2]))
    board.servo(9, safe=90).write(10)
    board.digital_output(12, safe=False).on()
    marker = board.digital_output(13, safe=False)
    print(board.session, flush=True)
    for _ in sys.stdin:  # each line: an on and off edge of pin 13, a mark on the board's clock
        marker.on()
        marker.off()
        print("marked", flush=True)
    """
)


def _mark_time(trace: list[dict[str, Any]], n: int) -> float | None:
    """The board's time of the child's ``n``-th mark (the off edge after pin 13's ``n``-th on
    edge), or None before it shows in the trace."""
    lines = [c for c in trace if c["pin"] == 13]
    ons = [i for i, c in enumerate(lines) if c["value"] == 1]
    if len(ons) < n or ons[n - 1] + 1 >= len(lines):
        return None
    return float(lines[ons[n - 1] + 1]["t"])


def _raw_marker(port: str, session: int) -> None:
    """Re-handshake ``session`` and set pin 13: a mark on the board's clock that is no sign
    of life (a RESET of the same session and a Control never feed the timer)."""
    ser = serial.Serial(port, baudrate=115200, timeout=0.05)
    try:
        decoder = StreamDecoder()
        ser.write(
            b"\0"
            + frame_packet(
                PacketType.CONTROL, 0, reset_payload(protoduino.PROTOCOL_VERSION, session, 1)
            )
        )
        msg = ArduinoIn(message_id=1)  # NEXT_ID 1: new to the device whatever its window holds
        msg.digital_control.pin, msg.digital_control.level = 13, True
        sent = False
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            for item in decoder.feed(ser.read(256)):
                if not isinstance(item, Packet):
                    continue
                if item.type is PacketType.CONTROL and not sent:
                    ctl = parse_control(item.payload)
                    if ctl.code is ControlCode.RESET_ACK:
                        assert ctl.resumed, "the session should still own the outputs"
                        ser.write(frame_packet(PacketType.COMMAND, 1, msg.SerializeToString()))
                        sent = True
                elif item.type is PacketType.DATA and parse_out(item.payload).ack.message_id:
                    assert parse_out(item.payload).ack.status == Status.STATUS_OK
                    return
        raise AssertionError("no answer to the marker")
    finally:
        ser.close()


def test_host_process_killed(sim: SimBoard) -> None:
    """The host dies with its automatic Pings running (every T/4)."""
    t = 1.0
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, sim.port, str(t)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout is not None
        assert child.stdin is not None
        session = int(child.stdout.readline())
        on = _wait_trace(
            sim,
            lambda tr: next((c["t"] for c in tr if c["pin"] == 12 and c["value"] == 1), None),
            5.0,
            "pin 12 on",
        )
        # The child pings: alive for 2T on the board's clock, and nothing goes safe. The child's
        # marks on pin 13 date that span; the wall clock only paces them.
        marks, mark = 0, on
        while mark < on + 2 * t:
            child.stdin.write("mark\n")
            child.stdin.flush()
            assert child.stdout.readline() == "marked\n"
            marks += 1
            mark = _wait_trace(sim, lambda tr, n=marks: _mark_time(tr, n), 5.0, f"mark {marks}")
            time.sleep(0.1)
        assert [c for c in _lines(sim, 12) if on < c["t"] <= mark] == []
        assert pin_values(sim.trace(), 12)[-1] == 1
        killed = time.monotonic()
        os.kill(child.pid, signal.SIGKILL)
        child.wait(5)
        _raw_marker(sim.port, session)
        late = time.monotonic() - killed  # how long after the kill the marker was set, at most
        last_mark = mark
        mark = _wait_trace(
            sim,
            lambda tr: next(
                (c["t"] for c in tr if c["pin"] == 13 and c["value"] == 1 and c["t"] > last_mark),
                None,
            ),
            5,
            "mark",
        )
        # The last Ping came at most T/4 before the kill, the kill at most `late` before the
        # mark: the failsafe fires T after that Ping, i.e. in this window around the mark.
        assert_failsafe_on_time(sim, (mark - late - t / 4, mark), t)
    finally:
        if child.poll() is None:
            child.kill()
        child.wait(5)
        for stream in (child.stdin, child.stdout):
            if stream is not None:
                stream.close()

"""``protoduino demo``: the whole stack against a simulated board, in about 15 seconds.

Starts the simulated board (or, with ``--backend avr``, the emulated Uno; with ``--board
mega`` too, the emulated Mega 2560), sweeps a servo, blinks a pin, then stops pinging
and waits for the device's failsafe to put both outputs back to their safe
values, and finally reads the board's own trace to show what the pins did.

Ctrl-C ends it cleanly: the simulated board is owned by this process and runs
in its own process group (:mod:`protoduino.simboard`), so the terminal's SIGINT
reaches only the demo, which closes its Board, then stops the board, and exits
with status 130. (Were the board interrupted too, its port would vanish under
the open Board: a "device disconnected" warning that says nothing true.)
"""

from __future__ import annotations

import argparse
import queue
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..board import Board
from ..constants import FAILSAFE_TIMEOUT
from ..errors import ProtoduinoError
from ..events import Event, EventKind
from ..simboard import AVR_BOARDS, BACKENDS
from .options import add_capture, capture_max_bytes, capture_verdict, error

if TYPE_CHECKING:
    from ..simboard import SimBoard

HELP = "run the demo on the simulated board: sweep a servo, blink a pin, watch the failsafe"

SERVO_PIN = 9
LED_PIN = 13
SAFE_DEGREES = 90
#: The servo's safe width, as the trace states it.
SAFE_US = 544 + SAFE_DEGREES * (2400 - 544) // 180
#: Seconds the demo waits, once the failsafe's event came, for the trace to show it: an
#: emulated board writes a servo's new width after measuring it over two 20 ms frames, and
#: the event can come first. A bound only: it reads on as soon as the trace shows it.
TRACE_WAIT = 2.0


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--backend",
        choices=sorted(BACKENDS),
        default="native",
        help="simulated board: native (default) or avr (the emulated Uno)",
    )
    parser.add_argument(
        "--board",
        choices=sorted(AVR_BOARDS),
        default="uno",
        help="the board the avr backend emulates: uno (default) or mega (the Mega 2560)",
    )
    parser.add_argument("--trace", type=Path, help="keep the board's pin trace in this file")
    add_capture(parser)


class _Clock:
    def __init__(self) -> None:
        self.t0 = time.monotonic()

    def say(self, text: str) -> None:
        print(f"[{time.monotonic() - self.t0:6.2f} s] {text}", flush=True)


def run(args: argparse.Namespace) -> int:
    from ..simboard import SimBoard  # imported here: only the demo starts a board

    clock = _Clock()
    with tempfile.TemporaryDirectory(prefix="protoduino-demo-") as tmp:
        trace_path = args.trace or Path(tmp) / "trace.jsonl"
        clock.say(f"starting the simulated board ({args.backend}, {args.board}) ...")
        try:
            with SimBoard(args.backend, board=args.board, trace=trace_path) as sim:
                port = sim.start()
                clock.say(f"simulated board on {port} (pid {sim.pid})")
                ok = _demo(port, clock, args)
                trace = _trace_with_failsafe(sim)
        except ProtoduinoError as exc:
            return error("demo", exc)
        except KeyboardInterrupt:
            clock.say("interrupted: the Board is closed and the simulated board stopped")
            return 130
        return 0 if _report(trace, clock) and ok else 1


def _demo(port: str, clock: _Clock, args: argparse.Namespace) -> bool:
    events: queue.Queue[Event] = queue.Queue()
    board = Board.open(port, capture=args.capture, capture_max_bytes=capture_max_bytes(args))
    with board:
        info = board.info
        clock.say(
            f"connected: {info.board} firmware {info.firmware_version}, protocol "
            f"{info.protocol_version}, {info.num_pins} pins, {info.max_servos} servos, "
            f"ping {board.ping() * 1000:.2f} ms"
        )
        board.on_event(events.put)

        servo = board.servo(SERVO_PIN, safe=SAFE_DEGREES)
        clock.say(f"servo on pin {SERVO_PIN}, safe at {SAFE_DEGREES} degrees; sweeping 0..180..0")
        for degrees in [*range(0, 181, 10), *range(170, -1, -10)]:
            servo.write(degrees)
            time.sleep(0.02)

        led = board.digital_output(LED_PIN, safe=False)
        clock.say(f"digital output on pin {LED_PIN}, safe level off; blinking 5 times")
        for _ in range(5):
            led.on()
            time.sleep(0.1)
            led.off()
            time.sleep(0.1)

        servo.write(150)
        led.on()
        clock.say("servo at 150 degrees, LED on")
        board.pinging = False
        last_ping = board.stats.last_ping or time.monotonic()
        clock.say(
            f"pings stopped; the device's failsafe is due {FAILSAFE_TIMEOUT:g} s after the last"
        )
        failsafe = _wait_for(events, EventKind.FAILSAFE, FAILSAFE_TIMEOUT + 5.0, clock)
        if failsafe is None:
            clock.say("no failsafe event arrived: something is wrong")
            return False
        since = time.monotonic() - last_ping
        clock.say(f"{failsafe.text} ({since:.1f} s after the last Ping)")
        board.pinging = True
        cleared = _wait_for(events, EventKind.FAILSAFE, 3.0, clock)
        if cleared is not None:
            clock.say(f"pings resumed: {cleared.text}")
        stats = board.stats
        clock.say(
            f"link: {stats.commands} commands, {stats.acks} acks, {stats.retransmits} "
            f"retransmits, {stats.timeouts} timeouts, {stats.pings} pings"
        )
    return capture_verdict("demo", board, 0) == 0


def _wait_for(
    events: queue.Queue[Event], kind: EventKind, timeout: float, clock: _Clock
) -> Event | None:
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        try:
            event = events.get(timeout=left)
        except queue.Empty:
            return None
        if event.kind is kind:
            return event
        clock.say(f"event: {event}")
    return None


def _pin_changes(trace: list[dict[str, Any]], pin: int) -> list[dict[str, Any]]:
    return [e for e in trace if e.get("pin") == pin]


def _shows_failsafe(trace: list[dict[str, Any]]) -> bool:
    """The failsafe is the last change of each pin: back to the safe values."""
    servo, led = _pin_changes(trace, SERVO_PIN), _pin_changes(trace, LED_PIN)
    return bool(servo and led and servo[-1]["value"] == SAFE_US and led[-1]["value"] == 0)


def _trace_with_failsafe(sim: SimBoard) -> list[dict[str, Any]]:
    """The board's trace once it shows the failsafe, or as it is after ``TRACE_WAIT``."""
    deadline = time.monotonic() + TRACE_WAIT
    while not _shows_failsafe(trace := sim.trace()) and time.monotonic() < deadline:
        time.sleep(0.02)
    return trace


def _report(trace: list[dict[str, Any]], clock: _Clock) -> bool:
    """What the board's own trace says the pins did; True if the failsafe shows in it."""
    servo, led = _pin_changes(trace, SERVO_PIN), _pin_changes(trace, LED_PIN)
    clock.say(f"the board's trace: {len(trace)} output changes")
    if servo:
        values = [e["value"] for e in servo]
        clock.say(
            f"  pin {SERVO_PIN} (servo): {len(servo)} changes, {min(values)}..{max(values)} us"
        )
    if led:
        ons = sum(1 for e in led if e["value"] == 1)
        clock.say(f"  pin {LED_PIN} (digital): {len(led)} changes, {ons} times on")
    if not servo or not led:
        clock.say("  the trace lacks the demo's pins")
        return False
    # The failsafe: back to the safe values, about FAILSAFE_TIMEOUT after the last command
    # (the LED going on).
    last_servo, last_led = servo[-1], led[-1]
    gap = last_servo["t"] - led[-2]["t"] if len(led) >= 2 else float("nan")
    shown = _shows_failsafe(trace)
    clock.say(
        f"  failsafe in the trace: pin {SERVO_PIN} -> {last_servo['value']} us (safe "
        f"{SAFE_US}), pin {LED_PIN} -> {last_led['value']} at t={last_servo['t']:.3f} s, "
        f"{gap:.2f} s after the last command (the Ping before it counts)"
    )
    clock.say("demo done" if shown else "the trace does not show the failsafe")
    return shown

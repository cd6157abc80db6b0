"""The console's picture of one board, and what a page may ask of it (no web here).

:class:`LiveBoard` owns the pins a console session uses on a :class:`~protoduino.Board`
opened with ``liveness="heartbeat"``: it configures them (:class:`PinSpec`), writes them,
stops the board, feeds its heartbeat, keeps each input's history over the last
``window`` seconds (from the inputs' ``on_change`` callbacks), the latest readback of
the outputs (:meth:`Board.read_outputs`), the failsafe state and the recent events, and
makes one JSON-able :meth:`snapshot` of all of it for the page. Every call that goes to
the device returns the board's future (the ``submit_`` forms), so the server awaits it
without a thread of its own; the checks are the board's (a refused value raises its
:class:`~protoduino.errors.ArgumentError` at once).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Literal, cast

from ..board import AnalogInput, Board, Counter, DigitalInput, DigitalOutput, PwmOutput, Servo
from ..errors import ArgumentError
from ..events import Event, EventKind
from ..inputs import Reading
from ..readback import OutputState

Mode = Literal["servo", "digital", "pwm", "input", "analog", "counter"]
#: The output modes and the input modes, as a page names them.
OUTPUT_MODES: tuple[Mode, ...] = ("servo", "digital", "pwm")
INPUT_MODES: tuple[Mode, ...] = ("input", "analog", "counter")
#: Each mode's firmware feature (DeviceInfo.features), so the page offers only what is built in.
FEATURES: Mapping[Mode, str] = {
    "servo": "servo",
    "digital": "digital_output",
    "pwm": "pwm",
    "input": "digital_input",
    "analog": "analog_input",
    "counter": "counter",
}
#: Samples one input keeps at most, whatever the window (bounded memory).
HISTORY_LIMIT = 2000
#: Events kept for the page.
EVENT_LIMIT = 50


@dataclass(frozen=True)
class PinSpec:
    """One pin as the console configures it.

    ``safe``: a servo's safe angle in degrees (None: detached when safe), a digital output's
    safe level (0 or 1), a PWM output's safe duty; ignored for inputs. ``pull_up`` for a
    digital input or a counter; ``name`` is the page's label (default: the mode and pin).
    """

    pin: int
    mode: Mode
    safe: int | None = None
    pull_up: bool = False
    name: str = ""

    def label(self) -> str:
        return self.name or f"{self.mode} {self.pin}"


#: The example robot of ``protoduino console --sim`` (docs/console.md): every output kind
#: and every input kind, on pins an Uno holds at once (the servos on Timer1's 9 and 10,
#: PWM on Timer2's 3 and 11; Timer0 runs the device's clock).
EXAMPLE_ROBOT: tuple[PinSpec, ...] = (
    PinSpec(9, "servo", safe=90, name="pan"),
    PinSpec(10, "servo", safe=45, name="tilt"),
    PinSpec(13, "digital", safe=0, name="led"),
    PinSpec(3, "pwm", safe=0, name="left motor"),
    PinSpec(11, "pwm", safe=0, name="right motor"),
    PinSpec(7, "input", pull_up=True, name="bumper"),
    PinSpec(14, "analog", name="battery (A0)"),
    PinSpec(2, "counter", name="encoder"),
)

Output = Servo | DigitalOutput | PwmOutput
Input = DigitalInput | AnalogInput | Counter


@dataclass
class _Pin:
    spec: PinSpec
    handle: Output | Input
    history: deque[tuple[float, int]]
    #: Removes an input's on_change callback (outputs: nothing to remove).
    unsubscribe: Callable[[], None] = lambda: None


class LiveBoard:
    """See the module docstring. ``window``: seconds of input history the page plots."""

    def __init__(
        self, board: Board, *, window: float = 30.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.board = board
        self.window = window
        self.clock = clock
        self._lock = threading.Lock()
        self._pins: dict[int, _Pin] = {}
        self._readback: dict[int, OutputState] = {}
        self._readback_t: float | None = None
        self._events: deque[dict[str, Any]] = deque(maxlen=EVENT_LIMIT)
        self._failsafe: dict[str, Any] = {"active": False, "cause": "none", "t": None}
        #: The safe state the outputs hold since the device entered it (its cause and time):
        #: the device latches it past the flag's clearing, until an output is commanded.
        self._latched: dict[str, Any] | None = None
        self._unsubscribe = board.on_event(self._on_event)

    # --- configuring -------------------------------------------------------------------

    def configure(self, spec: PinSpec) -> Future[Any]:
        """Configure one pin (a pin the console already uses is released first: the
        device refuses a second mode on a pin). The future resolves with the Ack."""
        board = self.board
        if spec.mode not in FEATURES:
            raise ArgumentError(f"mode must be one of {', '.join(FEATURES)}, not {spec.mode!r}")
        if spec.pin in self._pins:
            self.board.release(spec.pin)
            with self._lock:
                old = self._pins.pop(spec.pin, None)
            if old is not None:
                old.unsubscribe()
        future: Future[Any]
        if spec.mode == "servo":
            future = board.submit_servo(spec.pin, spec.safe if spec.safe is not None else "detach")
        elif spec.mode == "digital":
            future = board.submit_digital_output(spec.pin, safe=bool(spec.safe))
        elif spec.mode == "pwm":
            future = board.submit_pwm_output(spec.pin, safe=spec.safe or 0)
        elif spec.mode == "input":
            future = board.submit_digital_input(spec.pin, pull_up=spec.pull_up)
        elif spec.mode == "analog":
            future = board.submit_analog_input(spec.pin, rate_hz=20.0, threshold=0)
        else:
            future = board.submit_counter(spec.pin, pull_up=spec.pull_up)
        future.add_done_callback(lambda done: self._configured(spec, done))
        return future

    def configure_all(self, specs: Iterable[PinSpec]) -> None:
        """Configure several pins in order, waiting for each (what a command line starts with)."""
        for spec in specs:
            self.configure(spec).result()

    def _configured(self, spec: PinSpec, done: Future[Any]) -> None:
        if done.cancelled() or done.exception() is not None:
            return
        handle = done.result()
        pin = _Pin(spec, handle, deque(maxlen=HISTORY_LIMIT))
        with self._lock:
            self._pins[spec.pin] = pin
        if spec.mode in INPUT_MODES:
            pin.unsubscribe = handle.on_change(lambda reading: self._on_reading(pin, reading))
            reading = handle.reading()
            if reading is not None:
                self._on_reading(pin, reading)

    def _on_reading(self, pin: _Pin, reading: Reading) -> None:
        with self._lock:
            pin.history.append((reading.received, int(reading.value)))

    # --- driving -----------------------------------------------------------------------

    def write(self, pin: int, value: float, *, unit: str = "") -> Future[None]:
        """Write an output: a servo's degrees (``unit="us"``: its pulse width), a digital
        level (0 or 1) or a PWM duty. ArgumentError for a pin the console has no output on."""
        handle = self._output(pin)
        future: Future[None]
        if isinstance(handle, Servo):
            future = handle.submit_us(value) if unit == "us" else handle.submit(value)
        elif isinstance(handle, DigitalOutput):
            future = handle.submit(bool(value))
        else:
            future = handle.submit(value)
        future.add_done_callback(self._commanded)
        return future

    def _commanded(self, done: Future[None]) -> None:
        if not done.cancelled() and done.exception() is None:
            with self._lock:
                self._latched = None

    def _output(self, pin: int) -> Output:
        with self._lock:
            found = self._pins.get(pin)
        if found is None or found.spec.mode not in OUTPUT_MODES:
            raise ArgumentError(f"pin {pin} is no output of this console")
        return found.handle  # type: ignore[return-value]

    def stop(self) -> Future[None]:
        """The board's Stop: every output to its safe value, on the device."""
        return self.board.submit_stop()

    def beat(self) -> Future[None]:
        """The page's sign of life: the device's heartbeat (liveness="heartbeat")."""
        return self.board.submit_heartbeat()

    def refresh_outputs(self) -> Future[dict[int, OutputState]]:
        """Read back what the device drives; :meth:`snapshot` shows it when it comes."""
        future = self.board.submit_read_outputs()
        future.add_done_callback(self._read_back)
        return future

    def _read_back(self, done: Future[dict[int, OutputState]]) -> None:
        if done.cancelled() or done.exception() is not None:
            return
        with self._lock:
            self._readback = done.result()
            self._readback_t = self.clock()

    # --- events ------------------------------------------------------------------------

    def _on_event(self, event: Event) -> None:
        with self._lock:
            self._events.append({"t": event.t, "kind": event.kind.value, "text": event.text})
            if event.kind is EventKind.FAILSAFE:
                active = bool(event.details.get("active"))
                cause = str(event.details.get("cause", "none"))
                self._failsafe = {"active": active, "cause": cause, "t": event.t}
                if active:
                    self._latched = {"cause": cause, "t": event.t}

    def close(self) -> None:
        """Stop listening to the board's events (the board is its owner's to close)."""
        self._unsubscribe()

    # --- the page's picture ------------------------------------------------------------

    def snapshot(self) -> dict[str, Any]:
        """Everything the page shows, as JSON-able values; times are seconds before now."""
        now = self.clock()
        stats = self.board.stats
        info = self.board.info
        with self._lock:
            pins = sorted(self._pins.values(), key=lambda p: p.spec.pin)
            readback = dict(self._readback)
            readback_age = None if self._readback_t is None else now - self._readback_t
            events = [dict(e, age=now - e["t"]) for e in self._events]
            failsafe = dict(self._failsafe)
            latched = None if self._latched is None else dict(self._latched)
            outputs, inputs = [], []
            for pin in pins:
                spec = pin.spec
                if spec.mode in OUTPUT_MODES:
                    state = readback.get(spec.pin)
                    outputs.append(
                        {
                            "pin": spec.pin,
                            "mode": spec.mode,
                            "name": spec.label(),
                            "safe": spec.safe,
                            "value": None if state is None else state.value,
                            "target": None if state is None else state.target,
                            "commanded": pin.handle.value,  # type: ignore[union-attr]
                        }
                    )
                else:
                    while pin.history and now - pin.history[0][0] > self.window:
                        pin.history.popleft()
                    latest = pin.handle.reading()  # type: ignore[union-attr]
                    inputs.append(
                        {
                            "pin": spec.pin,
                            "mode": spec.mode,
                            "name": spec.label(),
                            "value": None if latest is None else int(latest.value),
                            "age": None if latest is None else now - latest.received,
                            "history": [[t - now, v] for t, v in pin.history],
                        }
                    )
        failsafe["age"] = None if failsafe["t"] is None else now - failsafe["t"]
        failsafe["latched"] = None if latched is None else latched["cause"]
        failsafe["latched_age"] = None if latched is None else now - latched["t"]
        return {
            "board": {
                "url": self.board.url,
                "name": info.board,
                "firmware": info.firmware_version,
                "num_pins": info.num_pins,
                "reserved": list(info.reserved_pins),
                "pwm_pins": list(info.pwm_pins),
                "analog_pins": list(info.analog_pins),
                "counter_pins": list(info.counter_pins),
                "modes": [m for m, f in FEATURES.items() if f in info.features],
            },
            "window": self.window,
            "failsafe_timeout": self.board.failsafe_timeout,
            "link": {
                "state": stats.state,
                "rtt": stats.rtt,
                "commands": stats.commands,
                "acks": stats.acks,
                "retransmits": stats.retransmits,
                "timeouts": stats.timeouts,
                "rejected": stats.rejected,
                "dropped": sum(stats.dropped.values()),
                "reconnects": stats.reconnects,
                "reboots": stats.reboots,
                "input_reports": stats.input_reports,
            },
            "failsafe": failsafe,
            "events": events,
            "outputs": outputs,
            "readback_age": readback_age,
            "inputs": inputs,
        }


def spec_from_json(data: Mapping[str, Any]) -> PinSpec:
    """A page's ``configure`` request as a :class:`PinSpec`; ArgumentError for a bad one."""
    try:
        pin = int(data["pin"])
        mode = str(data["mode"])
        if mode not in FEATURES:
            raise ArgumentError(f"mode must be one of {', '.join(FEATURES)}, not {mode!r}")
        safe = data.get("safe")
        spec = PinSpec(
            pin=pin,
            mode=cast(Mode, mode),
            safe=None if safe is None or safe == "" else int(safe),
            pull_up=bool(data.get("pull_up", False)),
            name=str(data.get("name", "")),
        )
    except (KeyError, TypeError, ValueError) as error:
        raise ArgumentError(f"a pin to configure needs pin, mode and safe: {error}") from None
    return spec


__all__ = ["EXAMPLE_ROBOT", "FEATURES", "LiveBoard", "PinSpec", "spec_from_json"]

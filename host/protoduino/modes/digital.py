"""The digital output mode: :class:`DigitalOutput`, its DigitalInit (the safe level) and its
checks."""

from __future__ import annotations

from concurrent.futures import Future
from typing import Any

from ..arguments import Pin, check_level
from ..commands import DIGITAL
from ..messages import ArduinoIn
from .base import Built, ModeBoard, OutputBoard, PinRecord


def init(board: ModeBoard, pin: Pin, safe: bool) -> Built[DigitalOutput]:
    """Check a digital output's configuration; its DigitalInit, what to record at the Ack,
    its object."""
    pin = board._check_pin(pin, DIGITAL)
    safe = check_level("safe", safe)  # bool("no") and bool(2) are True: no guessing
    with board._lock:
        board._check_free(pin, DIGITAL)
    msg = ArduinoIn()
    msg.digital_init.pin = pin
    msg.digital_init.safe_level = safe
    state = PinRecord(DIGITAL, msg.SerializeToString(), int(safe))
    return msg, lambda: board._set_output(pin, state), DigitalOutput(board, pin)


class DigitalOutput:
    """A digital output pin; get one from :meth:`Board.digital_output`."""

    def __init__(self, board: OutputBoard, pin: int) -> None:
        self.board = board
        self.pin = pin
        #: Each level's Control, serialized (without a message id), once it was used.
        self._controls: dict[int, bytes] = {}

    @property
    def value(self) -> bool | None:
        """The level the device last acknowledged (the safe level after Init, Stop, failsafe)."""
        value = self.board._value(self.pin, DIGITAL)
        return None if value is None else bool(value)

    def _pose_item(self, item: Any, value: object) -> tuple[bytes, int]:
        """As :meth:`Servo._pose_item` (a pin the Pose's pin sets cannot hold, 72 or above)."""
        control, level = self._pose_level(value)
        item.digital.pin = self.pin
        item.digital.level = bool(level)
        return control, level

    def _pose_level(self, value: object) -> tuple[bytes, int]:
        """The level ``value`` sets in a pose's pin sets, and this output's own Control for it.
        A level has two values: each one's Control is built once (a pose of digital outputs
        is the robot's hot call)."""
        level = int(check_level("level", value))
        control = self._controls.get(level)
        if control is None:
            control = self._controls[level] = self._level(bool(level))[0].SerializeToString()
        return control, level

    def write(self, level: bool) -> None:
        """Drive the pin high (True or 1) or low (False or 0); any other value is refused."""
        self.board._control(self.pin, *self._level(level))

    def on(self) -> None:
        self.write(True)

    def off(self) -> None:
        self.write(False)

    def submit(self, level: bool) -> Future[None]:
        """:meth:`write` without waiting: a future resolved by the Ack."""
        return self.board._control_future(self.pin, *self._level(level))

    def _level(self, level: bool) -> tuple[ArduinoIn, int]:
        value = check_level("level", level)
        msg = ArduinoIn()
        msg.digital_control.pin = self.pin
        msg.digital_control.level = value
        return msg, int(value)

    def release(self) -> None:
        """Release the pin: it becomes an input, as at power-up, free for any mode."""
        self.board.release(self.pin)

    def submit_release(self) -> Future[None]:
        """:meth:`release` without waiting: a future resolved by the Ack."""
        return self.board.submit_release(self.pin)

    def __repr__(self) -> str:
        return f"DigitalOutput(pin={self.pin})"

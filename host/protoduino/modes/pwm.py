"""The PWM output mode: :class:`PwmOutput`, its PwmInit (the safe duty) and its checks.

A PWM pin needs its timer (``info.timer``): one that runs the device's clock is refused
here; the servos' timer while a servo runs, by :func:`~protoduino.board.conflict`, which
spans the modes.
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import Any

from ..arguments import Pin, RealNumber, refused, whole_number
from ..commands import PWM
from ..constants import PWM_MAX_DUTY
from ..messages import ArduinoIn, Status
from .base import Built, ModeBoard, OutputBoard, PinRecord


def init(board: ModeBoard, pin: Pin, safe: object) -> Built[PwmOutput]:
    """Check a PWM output's configuration; its PwmInit, what to record at the Ack, its object."""
    # The device's order (docs/protocol.md section 7, rule 13).
    pin = board._check_pin(pin, PWM)
    info = board.info
    timer = info.timer(pin)
    use = "free" if timer is None else info.timer_use(timer)
    if use not in ("free", "servos"):  # the servos' timer: conflict(), by what runs
        held = "runs the device's millisecond clock" if use == "clock" else f"is the {use}'"
        raise refused(
            Status.STATUS_TIMER_IN_USE,
            f"pin {pin}'s PWM needs Timer{timer}, which {held} "
            f"(PWM pins: {', '.join(map(str, info.pwm_pins))})",
        )
    board._check_capable(pin, PWM)
    duty = whole_number("safe", safe)
    with board._lock:
        board._check_free(pin, PWM)
    if not 0 <= duty <= PWM_MAX_DUTY:
        raise refused(Status.STATUS_OUT_OF_RANGE, f"safe duty {duty} is outside 0..{PWM_MAX_DUTY}")
    msg = ArduinoIn()
    msg.pwm_init.pin = pin
    msg.pwm_init.safe_duty = duty
    state = PinRecord(PWM, msg.SerializeToString(), duty)
    return msg, lambda: board._set_output(pin, state), PwmOutput(board, pin, duty)


class PwmOutput:
    """A PWM output, duty 0..255 as Arduino's analogWrite; get one from :meth:`Board.pwm_output`."""

    def __init__(self, board: OutputBoard, pin: int, safe: int) -> None:
        self.board = board
        self.pin = pin
        #: The duty the failsafe, a Stop and an interlock drive (0: off).
        self.safe = safe

    @property
    def value(self) -> int | None:
        """The duty the device last acknowledged (the safe duty after Init, Stop, failsafe)."""
        return self.board._value(self.pin, PWM)

    def _pose_item(self, item: Any, value: object) -> tuple[bytes, int]:
        """As :meth:`Servo._pose_item`."""
        msg, duty = self._duty(value)
        item.pwm.CopyFrom(msg.pwm_control)
        return msg.SerializeToString(), duty

    def write(self, duty: RealNumber) -> None:
        """Set the duty, 0 (always low) .. 255 (always high); a real number is rounded
        to the nearest whole duty (halves to even)."""
        self.board._control(self.pin, *self._duty(duty))

    def submit(self, duty: RealNumber) -> Future[None]:
        """:meth:`write` without waiting: a future resolved by the Ack."""
        return self.board._control_future(self.pin, *self._duty(duty))

    def _duty(self, duty: object) -> tuple[ArduinoIn, int]:
        value = whole_number("duty", duty)
        if not 0 <= value <= PWM_MAX_DUTY:
            shown = f"{duty} (rounded: {value})" if value != duty else str(value)
            raise refused(Status.STATUS_OUT_OF_RANGE, f"duty {shown} is outside 0..{PWM_MAX_DUTY}")
        msg = ArduinoIn()
        msg.pwm_control.pin = self.pin
        msg.pwm_control.duty = value
        return msg, value

    def release(self) -> None:
        """Release the pin: its PWM stops, it becomes an input, free for any mode."""
        self.board.release(self.pin)

    def __repr__(self) -> str:
        return f"PwmOutput(pin={self.pin}, safe={self.safe})"

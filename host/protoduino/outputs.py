"""The board's outputs: :class:`Servo`, :class:`DigitalOutput`, :class:`PwmOutput`.

Each is a handle on one configured pin: it checks its values (the pin's limits, the argument
checks of :mod:`protoduino.arguments`) and asks its board to send them. The board is what
:class:`OutputBoard` names, so this module does not depend on the board's module.
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import Any, Protocol, SupportsFloat

from .arguments import RealNumber, check_level, refused, whole_number
from .commands import DIGITAL, PWM, SERVO, PinMode
from .constants import PWM_MAX_DUTY, SERVO_MAX_DEGREES
from .messages import ArduinoIn, Status


class OutputBoard(Protocol):
    """What an output needs of its board (:class:`protoduino.Board`)."""

    def _value(self, pin: int, mode: PinMode) -> int | None: ...

    def _control(self, pin: int, msg: ArduinoIn, value: int) -> None: ...

    def _control_future(self, pin: int, msg: ArduinoIn, value: int) -> Future[None]: ...

    def release(self, pin: int) -> None: ...

    def submit_release(self, pin: int) -> Future[None]: ...


class Servo:
    """A servo output; get one from :meth:`Board.servo`."""

    def __init__(
        self, board: OutputBoard, pin: int, min_us: int, max_us: int, max_speed_us: int = 0
    ) -> None:
        self.board = board
        self.pin = pin
        self.min_us = min_us
        self.max_us = max_us
        #: The speed limit the device keeps (us per second; 0: none, values jump).
        self.max_speed_us = max_speed_us

    @property
    def value(self) -> int | None:
        """The pulse width (us) the device last acknowledged for this servo.

        Its safe width after the Init, a Stop or a failsafe (0 for ``safe="detach"``:
        no pulses); None once the pin was released or configured anew as
        something else (or for a servo object that stands for a configuration
        since replaced).
        """
        return self.board._value(self.pin, SERVO)

    def _pose_item(self, item: Any, value: object) -> tuple[bytes, int]:
        """Fill a pose's item with ``value``; return this output's own Control (as bytes,
        for a restore) and the value it sets."""
        msg, us = self._degrees(value)
        item.servo.CopyFrom(msg.servo_control)
        return msg.SerializeToString(), us

    def to_us(self, degrees: int) -> int:
        """The pulse width the device makes for ``degrees`` (its own integer formula)."""
        return self.min_us + degrees * (self.max_us - self.min_us) // SERVO_MAX_DEGREES

    def write(self, degrees: SupportsFloat) -> None:
        """Move to ``degrees`` (0..180, mapped linearly onto [min_us, max_us]).

        Any real number: it is rounded to the nearest whole degree first, a half to
        the even one (``round()``), which must then be within 0..180.
        """
        self.board._control(self.pin, *self._degrees(degrees))

    def write_us(self, us: SupportsFloat) -> None:
        """Set the pulse width in microseconds (within [min_us, max_us]).

        Any real number, rounded to the nearest whole microsecond as :meth:`write` rounds.
        """
        self.board._control(self.pin, *self._us(us))

    def submit(self, degrees: SupportsFloat) -> Future[None]:
        """:meth:`write` without waiting: a future resolved by the Ack."""
        return self.board._control_future(self.pin, *self._degrees(degrees))

    def submit_us(self, us: SupportsFloat) -> Future[None]:
        """:meth:`write_us` without waiting: a future resolved by the Ack."""
        return self.board._control_future(self.pin, *self._us(us))

    def _degrees(self, value: object) -> tuple[ArduinoIn, int]:
        degrees = whole_number("degrees", value)
        if not 0 <= degrees <= SERVO_MAX_DEGREES:
            raise refused(Status.STATUS_OUT_OF_RANGE, f"{degrees} degrees is outside 0..180")
        msg = ArduinoIn()
        msg.servo_control.pin = self.pin
        msg.servo_control.degrees = degrees
        return msg, self.to_us(degrees)

    def _us(self, value: object) -> tuple[ArduinoIn, int]:
        us = whole_number("us", value)
        if not self.min_us <= us <= self.max_us:
            raise refused(
                Status.STATUS_OUT_OF_RANGE,
                f"{us} us is outside this servo's [{self.min_us}, {self.max_us}]",
            )
        msg = ArduinoIn()
        msg.servo_control.pin = self.pin
        msg.servo_control.us = us
        return msg, us

    def release(self) -> None:
        """Release the servo: its pulses stop (limp) and the pin is free for any mode."""
        self.board.release(self.pin)

    def submit_release(self) -> Future[None]:
        """:meth:`release` without waiting: a future resolved by the Ack."""
        return self.board.submit_release(self.pin)

    def __repr__(self) -> str:
        return f"Servo(pin={self.pin}, min_us={self.min_us}, max_us={self.max_us})"


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
        """As :meth:`Servo._pose_item` (a pin the Pose's masks cannot hold, 32 or above)."""
        control, level = self._pose_level(value)
        item.digital.pin = self.pin
        item.digital.level = bool(level)
        return control, level

    def _pose_level(self, value: object) -> tuple[bytes, int]:
        """The level ``value`` sets in a pose's masks, and this output's own Control for it.
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

"""What the device reports about itself and its outputs, decoded: :class:`DeviceInfo` (GetInfo,
read once at open) and :class:`OutputState` (``Board.read_outputs``, ReadOutputs).

:func:`failsafe_cause` names a Failsafe's cause from the schema's own enum. Pure decoding,
no I/O: the board, the asyncio board and the MCAP export (each readback as
plottable numbers) share it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from ._generated import protoduino_pb2 as pb
from .commands import ANALOG_INPUT, COUNTER, PIN_MODES, PWM, PinMode
from .errors import ProtocolError
from .messages import pin_mask, pins_in


@dataclass(frozen=True, slots=True)
class OutputState:
    """One configured output as the device drives it now (:meth:`Board.read_outputs`)."""

    pin: int
    mode: str  # "servo", "digital" or "pwm"
    #: A servo's pulse width now (us), a digital level (0, 1) or a PWM duty (0..255).
    value: int
    #: Where a servo is going (differs from ``value`` while a speed limit moves it).
    target: int


def decode_output_states(states: Any) -> dict[int, OutputState]:
    """Decode an ``OutputStates`` readback by pin (docs/protocol.md: 5 bytes per servo,
    the digital pin sets, then the PWM pins' set and their duties in pin order);
    :class:`ProtocolError` for fields that do not agree."""
    blob = bytes(states.servos)
    if len(blob) % 5:
        raise ProtocolError(f"OutputStates.servos of {len(blob)} bytes is not 5 per servo")
    found: dict[int, OutputState] = {}
    for pin, us, target in struct.iter_unpack("<BHH", blob):
        found[pin] = OutputState(pin, "servo", us, target)
    levels = pin_mask(states.digital_levels)
    for pin in pins_in(states.digital_pins):
        level = levels >> pin & 1
        found[pin] = OutputState(pin, "digital", level, level)
    pwm_pins = pins_in(states.pwm_pins)
    if len(pwm_pins) != len(states.pwm_duties):
        raise ProtocolError(
            f"OutputStates: {len(pwm_pins)} PWM pins but {len(states.pwm_duties)} duties"
        )
    for pin, duty in zip(pwm_pins, states.pwm_duties, strict=True):
        found[pin] = OutputState(pin, "pwm", duty, duty)
    return dict(sorted(found.items()))


#: DeviceInfo.pins: a pin's byte holds its PinBit flags below this bit, and 1 + the number
#: of the timer it needs that the device holds from it up (docs/protocol.md section 7).
_TIMER_SHIFT = 5


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What the device says about itself (GetInfo), read once at open.

    Its pin table (:attr:`pins`, :attr:`timers`) is the one place the host learns what a
    pin can do: :meth:`can`, :meth:`pins_for`, :meth:`timer` and :meth:`timer_use` answer
    from it, for any board, with no table of the host's own."""

    firmware_version: str
    protocol_version: int
    schema_id: int
    board: str
    num_pins: int
    max_servos: int
    reserved_pins: tuple[int, ...]
    #: Bytes of received frames the device buffers while it works (0: not stated); the
    #: board keeps the command bytes in flight within it.
    rx_buffer: int = 0
    #: The pin modes built into the firmware, by feature name ("servo", "pwm", ...).
    features: frozenset[str] = frozenset()
    #: The user service built in: its schema's fingerprint (docs/services.md); 0: none.
    user_fingerprint: int = 0
    #: DeviceInfo.pins: byte P is pin P's PinBit flags and (bits 5-7) 1 + the number of
    #: the timer its PWM needs that the device holds (0: none it holds).
    pins: bytes = b""
    #: DeviceInfo.timers: byte T is what the device holds Timer T for (a TimerUse).
    timers: bytes = b""

    def can(self, pin: int, mode: PinMode) -> bool:
        """Pin ``pin`` can do ``mode`` on this board (its flag in the pin table); whether
        the firmware has the mode is :attr:`features`."""
        flag = pb.PinBit.Value(mode.pins or "PIN_DIGITAL")
        return 0 <= pin < len(self.pins) and bool(self.pins[pin] & flag)

    def pins_for(self, mode: PinMode) -> tuple[int, ...]:
        """The pins that can do ``mode``, lowest first; none if the firmware lacks it."""
        if mode.feature not in self.features:
            return ()
        return tuple(pin for pin in range(len(self.pins)) if self.can(pin, mode))

    @property
    def pwm_pins(self) -> tuple[int, ...]:
        """The pins that can do PWM."""
        return self.pins_for(PWM)

    @property
    def analog_pins(self) -> tuple[int, ...]:
        """The analog inputs, A0 first."""
        return self.pins_for(ANALOG_INPUT)

    @property
    def counter_pins(self) -> tuple[int, ...]:
        """The pins that can count pulses."""
        return self.pins_for(COUNTER)

    def timer(self, pin: int) -> int | None:
        """The number of the timer ``pin``'s PWM needs that the device holds for something
        else (:meth:`timer_use`), or None."""
        if not 0 <= pin < len(self.pins):
            return None
        timer = self.pins[pin] >> _TIMER_SHIFT
        return timer - 1 if timer else None

    def timer_use(self, timer: int) -> str:
        """What the device holds Timer ``timer`` for: "clock" (always), "servos" (while a
        servo runs) or "free"."""
        use = self.timers[timer] if 0 <= timer < len(self.timers) else pb.TIMER_FREE
        try:
            return pb.TimerUse.Name(use).removeprefix("TIMER_").lower()  # type: ignore[arg-type]
        except ValueError:  # a use this host does not know: it holds the timer all the same
            return f"use {use}"

    def timer_pins(self, use: str) -> tuple[int, ...]:
        """The pins whose PWM needs a timer the device holds for ``use`` ("servos", ...)."""
        return tuple(
            pin
            for pin in range(len(self.pins))
            if (timer := self.timer(pin)) is not None and self.timer_use(timer) == use
        )


def decode_device_info(info: Any) -> DeviceInfo:
    """A GetInfo answer (``DeviceInfo`` message) as :class:`DeviceInfo`."""
    return DeviceInfo(
        firmware_version=info.firmware_version,
        protocol_version=info.protocol_version,
        schema_id=info.schema_id,
        board=info.board,
        num_pins=info.num_pins,
        max_servos=info.max_servos,
        reserved_pins=tuple(info.reserved_pins),
        rx_buffer=info.rx_buffer,
        features=frozenset(mode.feature for mode in PIN_MODES if info.features & mode.feature_bit),
        user_fingerprint=info.user_fingerprint,
        pins=bytes(info.pins),
        timers=bytes(info.timers),
    )


#: The schema's enum prefix of every failsafe cause (FAILSAFE_CAUSE_PING_TIMEOUT, ...).
_CAUSE_PREFIX = "FAILSAFE_CAUSE_"


def failsafe_cause(value: int) -> str:
    """A Failsafe's cause by its name in the schema (``FailsafeCause``), in lower case:
    "ping_timeout", "stop", "interlock", "none"; a cause this host does not know is "none"."""
    try:
        name = pb.FailsafeCause.Name(value)  # type: ignore[arg-type]
    except ValueError:
        return "none"
    return name.removeprefix(_CAUSE_PREFIX).lower()

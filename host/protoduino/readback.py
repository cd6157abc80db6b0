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
from .commands import PIN_MODES
from .errors import ProtocolError


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
    the digital masks, then the PWM pins' mask and their duties in pin order);
    :class:`ProtocolError` for fields that do not agree."""
    blob = bytes(states.servos)
    if len(blob) % 5:
        raise ProtocolError(f"OutputStates.servos of {len(blob)} bytes is not 5 per servo")
    found: dict[int, OutputState] = {}
    for pin, us, target in struct.iter_unpack("<BHH", blob):
        found[pin] = OutputState(pin, "servo", us, target)
    for pin in range(32):
        if states.digital_pins >> pin & 1:
            level = states.digital_levels >> pin & 1
            found[pin] = OutputState(pin, "digital", level, level)
    pwm_pins = [pin for pin in range(32) if states.pwm_pins >> pin & 1]
    if len(pwm_pins) != len(states.pwm_duties):
        raise ProtocolError(
            f"OutputStates: {len(pwm_pins)} PWM pins but {len(states.pwm_duties)} duties"
        )
    for pin, duty in zip(pwm_pins, states.pwm_duties, strict=True):
        found[pin] = OutputState(pin, "pwm", duty, duty)
    return dict(sorted(found.items()))


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What the device says about itself (GetInfo), read once at open."""

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
    #: The pins that can do PWM, that are analog inputs, that can count pulses.
    pwm_pins: tuple[int, ...] = ()
    analog_pins: tuple[int, ...] = ()
    counter_pins: tuple[int, ...] = ()
    #: The user service built in: its schema's fingerprint (docs/services.md); 0: none.
    user_fingerprint: int = 0


def _mask_pins(mask: int) -> tuple[int, ...]:
    return tuple(pin for pin in range(32) if mask >> pin & 1)


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
        pwm_pins=_mask_pins(info.pwm_pins),
        analog_pins=_mask_pins(info.analog_pins),
        counter_pins=_mask_pins(info.counter_pins),
        user_fingerprint=info.user_fingerprint,
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

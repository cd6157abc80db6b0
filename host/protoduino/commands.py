"""One declaration per command and per pin mode: the host's side of the firmware's tables.

The firmware has a command table (``PD_COMMANDS`` in firmware/core/pd_dispatch.c:
handler, idempotent or not, what its Ack returns) and a pin-mode table
(``PD_MODES`` in firmware/core/pd_outputs.c). Everything the host's layers need
to know about a command (the request layer: may its duplicate run twice? does
a session restore have to send an Init before it?) is read from here instead of
lists of names kept in step across modules. tests/contract/test_commands.py checks that
every ArduinoIn member is declared and that the firmware's table agrees.

How to add a command: one :class:`Command` in ``_BOARD_COMMANDS`` (or, for the
Init and Control of a pin mode, one :class:`PinMode` in ``PIN_MODES``, which
declares both), then its method on :class:`~protoduino.board.Board`.
"""

from __future__ import annotations

from dataclasses import dataclass

from ._generated import protoduino_pb2 as pb


@dataclass(frozen=True, slots=True)
class PinMode:
    """A way of using a pin; its Init claims the pin, its Control (if any) sets a value.

    Both messages carry the pin in a field named ``pin``.
    """

    name: str  # as in the firmware's PD_MODE_<NAME>
    init: str  # ArduinoIn member that configures a pin for this mode
    control: str | None = None  # ArduinoIn member that sets its value (None: an input)
    #: The build-time feature that carries it: Feature ``FEATURE_<FEATURE>`` in the
    #: schema, a bit of DeviceInfo.features. A firmware built without it refuses the
    #: mode (STATUS_NOT_SUPPORTED), and so does the host, before sending.
    feature: str = ""
    #: The DeviceInfo mask of the pins that can do this mode ("pwm_pins", ...); empty:
    #: any pin that is not reserved.
    pins: str = ""

    @property
    def feature_bit(self) -> int:
        """This mode's bit in DeviceInfo.features."""
        return 1 << pb.Feature.Value(f"FEATURE_{self.feature.upper()}")

    @property
    def is_input(self) -> bool:
        """An input: configured once, its values come in InputReports."""
        return self.control is None


@dataclass(frozen=True, slots=True)
class Command:
    """One ArduinoIn member as the host handles it."""

    kind: str  # the ArduinoIn.data member
    #: Running it twice changes nothing (the firmware's PD_CMD_IDEMPOTENT): the
    #: device does not keep it in its dedupe window, so the request layer does
    #: not guard its retransmissions.
    idempotent: bool = False
    #: The Ack.result member its Ack carries, if any.
    result: str | None = None
    #: The pin mode whose Init or Control it is, if any.
    pin_mode: PinMode | None = None

    @property
    def is_init(self) -> bool:
        """It configures a pin (its pin mode's Init)."""
        return self.pin_mode is not None and self.pin_mode.init == self.kind

    @property
    def is_control(self) -> bool:
        """It sets a configured pin's value (its pin mode's Control)."""
        return self.pin_mode is not None and self.pin_mode.control == self.kind

    @property
    def needs_init(self) -> str | None:
        """For a Control: the Init a restore must send before it (its pin's mode's Init)."""
        if not self.is_control:
            return None
        assert self.pin_mode is not None
        return self.pin_mode.init


DIGITAL = PinMode(
    "digital", init="digital_init", control="digital_control", feature="digital_output"
)
SERVO = PinMode("servo", init="servo_init", control="servo_control", feature="servo")
PWM = PinMode("pwm", init="pwm_init", control="pwm_control", feature="pwm", pins="pwm_pins")
DIGITAL_INPUT = PinMode("digital_input", init="digital_input_init", feature="digital_input")
ANALOG_INPUT = PinMode(
    "analog_input", init="analog_input_init", feature="analog_input", pins="analog_pins"
)
COUNTER = PinMode("counter", init="counter_init", feature="counter", pins="counter_pins")

#: Every pin mode, in the firmware's PD_MODE_* order.
PIN_MODES: tuple[PinMode, ...] = (DIGITAL, SERVO, PWM, DIGITAL_INPUT, ANALOG_INPUT, COUNTER)

_BOARD_COMMANDS: tuple[Command, ...] = (
    Command("ping", idempotent=True, result="ping_echo"),
    Command("get_info", idempotent=True, result="info"),
    Command("stop"),
    Command("pose"),  # several pin-mode Controls at once (PoseItem: servo, digital, pwm)
    Command("read_outputs", idempotent=True, result="outputs"),
    Command("configure_failsafe"),
    Command("heartbeat", idempotent=True),
    Command("release"),
    Command("release_all"),
    # Not idempotent: a late duplicate must never clear an interlock that tripped
    # again after the first one ran; the dedupe window answers it instead.
    Command("clear_interlock"),
    # A user service's method (docs/services.md). The device takes each method's
    # flags from the user's service table; the host guards every one as a
    # command that changes outputs (the safe side for a retransmission).
    Command("user_call", result="user_reply"),
)


def _pin_mode_commands(modes: tuple[PinMode, ...]) -> tuple[Command, ...]:
    commands = []
    for mode in modes:
        commands.append(Command(mode.init, pin_mode=mode))
        if mode.control is not None:
            commands.append(Command(mode.control, pin_mode=mode))
    return tuple(commands)


#: ArduinoIn member -> its declaration.
COMMANDS: dict[str, Command] = {c.kind: c for c in _BOARD_COMMANDS + _pin_mode_commands(PIN_MODES)}


def feature_hint(feature: str) -> str:
    """Why a mode is refused on a firmware without ``feature``, and how to get it."""
    name = feature.upper()
    every = " ".join(m.feature for m in sorted(PIN_MODES, key=lambda m: m.feature_bit))
    return (
        f"the firmware on this device was built without the {feature} feature "
        f"(FEATURE_{name}). The default firmware has every feature (protoduino flash PORT); "
        f'a make build must list it: make -C firmware avr FEATURES="{every}"; the Arduino '
        f"library must not #define PD_FEATURE_{name} 0 in its src/pd_config.h"
    )


def command(kind: str) -> Command:
    """The declaration of ``kind``; an undeclared one is treated as not idempotent."""
    found = COMMANDS.get(kind)
    return found if found is not None else Command(kind)


def arduino_in_kinds() -> tuple[str, ...]:
    """Every member of ArduinoIn.data in the schema (what must be declared here)."""
    oneof = pb.ArduinoIn.DESCRIPTOR.oneofs_by_name["data"]
    return tuple(field.name for field in oneof.fields)

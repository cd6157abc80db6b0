"""The built-in commands and pin modes as the host handles them, from their one declaration.

Each command's handling (idempotent, the Ack result, the feature it needs, whether
it sets an output) and each pin mode (its Init and Control, its feature, the pins
that can do it) are declared once, as options in proto/protoduino.proto
(proto/protoduino_options.proto says what each means). ``protoduino gen`` writes
from them the firmware's tables (firmware/generated/pd_tables.h) and the rows this
module builds its typed declarations from (``_generated/tables.py``). Everything the
host's layers need to know about a command (the request layer: may its duplicate
run twice? does a session restore have to send an Init before it?) is read from
here instead of lists of names kept in step across modules.

How to add a command (2 files by hand, counted with a throwaway one; before the tables
were generated, 3): its message and ``ArduinoIn.data`` member in proto/protoduino.proto,
with a ``(command)`` option if it is idempotent, carries an Ack result, needs a feature
or sets outputs, then ``protoduino gen``; its handler ``cmd_<name>`` in
firmware/core/pd_dispatch.c (the recipe there). Nothing here: its :class:`Command`
comes from the table. Then its wire text in docs/protocol.md and its method on
:class:`~protoduino.board.Board` (and ``protoduino.aio``).

How to add a pin mode (4 files by hand, and the 2 tests that list the default
firmware's features; before, 8 and the same 2): its Init and Control and a
``Feature`` value with a ``(pin_mode)`` option in the schema, then the firmware's
functions (firmware/core/pd_outputs.h has the exact recipe). Here, only a named
constant (``SERVO`` and the others below) if the host's code refers to the mode; the
host's code for the mode is its module ``protoduino.modes.<name>``, which ``Board``
composes. docs/architecture.md lists the counts, file by file.
"""

from __future__ import annotations

from dataclasses import dataclass

from ._generated import protoduino_pb2 as pb
from ._generated import tables


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
    #: The PinBit flag of the pins that can do this mode in the device's pin table
    #: ("PIN_PWM", ...: DeviceInfo.can); empty: PIN_DIGITAL.
    pins: str = ""

    @property
    def feature_bit(self) -> int:
        """This mode's bit in DeviceInfo.features."""
        return 1 << pb.Feature.Value(f"FEATURE_{self.feature.upper()}")

    @property
    def words(self) -> str:
        """Its name as messages write it: "analog input"."""
        return self.name.replace("_", " ")

    @property
    def a_pin(self) -> str:
        """ "a servo pin", "an analog input pin": the phrase the refusals name it by."""
        article = "an" if self.name[0] in "aeiou" else "a"
        return f"{article} {self.words} pin"

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
    #: The build-time feature it needs (a pin mode's, or its own), if any.
    feature: str | None = None
    #: It sets outputs to commanded values (the firmware's PD_CMD_SETS_OUTPUT): the
    #: device refuses it once the failsafe has run out or an interlock is latched.
    sets_output: bool = False

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


#: Every pin mode, in the firmware's PD_MODE_* order (their Features' order).
PIN_MODES: tuple[PinMode, ...] = tuple(
    PinMode(row.name, row.init, row.control, row.feature, row.pins) for row in tables.PIN_MODES
)
_MODES = {mode.name: mode for mode in PIN_MODES}

#: The pin modes the host's code names.
DIGITAL = _MODES["digital"]
SERVO = _MODES["servo"]
PWM = _MODES["pwm"]
DIGITAL_INPUT = _MODES["digital_input"]
ANALOG_INPUT = _MODES["analog_input"]
COUNTER = _MODES["counter"]

#: ArduinoIn member -> its declaration, for every member of the schema.
COMMANDS: dict[str, Command] = {
    row.kind: Command(
        row.kind,
        idempotent=row.idempotent,
        result=row.result,
        pin_mode=_MODES[row.pin_mode] if row.pin_mode is not None else None,
        feature=row.feature,
        sets_output=row.sets_output,
    )
    for row in tables.COMMANDS
}


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
    """Every member of ArduinoIn.data in the schema (each has a declaration here)."""
    oneof = pb.ArduinoIn.DESCRIPTOR.oneofs_by_name["data"]
    return tuple(field.name for field in oneof.fields)

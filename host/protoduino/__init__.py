"""protoduino: drive an Arduino's servos and pins over a reliable, failsafe serial link.

The layers, each a module, data flowing one way::

    bytes -> framing (COBS) -> packets (TYPE/LEN/SEQ/CRC) -> link -> rpc (+ session) -> board

``protoduino.testing`` is a Board on an in-process device, for testing code without hardware.

See README.md for the API and docs/protocol.md for the wire protocol.
"""

from __future__ import annotations

from ._generated.schema_id import SCHEMA_ID
from ._version import __version__
from .board import Board, effective_speed
from .boardoptions import BoardOptions
from .constants import PROTOCOL_VERSION
from .errors import (
    AckTimeoutError,
    ArgumentError,
    ArgumentTypeError,
    BadCommandError,
    BoardClosedError,
    BuildError,
    CaptureError,
    CommandRejectedError,
    ConfigError,
    DeviceRebootedError,
    ExtraMissingError,
    FeatureMissingError,
    FlashError,
    HandshakeError,
    InputTimeoutError,
    InterlockActiveError,
    LinkError,
    NotSupportedError,
    PayloadTooLargeError,
    PortInUseError,
    ProtocolError,
    ProtoduinoError,
    RebootLoopError,
    ReentrantCallError,
    SchemaMismatchError,
    ServiceGenError,
    SimControlError,
    StaleCommandError,
    TimerInUseError,
    TransportError,
    UserError,
    UserReplyLostError,
    UserSchemaError,
    VersionMismatchError,
)
from .events import Event, EventKind, Stats
from .inputs import Reading
from .modes.analog_input import AnalogInput
from .modes.counter import Counter
from .modes.digital_input import DigitalInput
from .outputs import DigitalOutput, PwmOutput, Servo
from .readback import DeviceInfo, OutputState

__all__ = [
    "PROTOCOL_VERSION",
    "SCHEMA_ID",
    "AckTimeoutError",
    "AnalogInput",
    "ArgumentError",
    "ArgumentTypeError",
    "BadCommandError",
    "Board",
    "BoardClosedError",
    "BoardOptions",
    "BuildError",
    "CaptureError",
    "CommandRejectedError",
    "ConfigError",
    "Counter",
    "DeviceInfo",
    "DeviceRebootedError",
    "DigitalInput",
    "DigitalOutput",
    "Event",
    "EventKind",
    "ExtraMissingError",
    "FeatureMissingError",
    "FlashError",
    "HandshakeError",
    "InputTimeoutError",
    "InterlockActiveError",
    "LinkError",
    "NotSupportedError",
    "OutputState",
    "PayloadTooLargeError",
    "PortInUseError",
    "ProtocolError",
    "ProtoduinoError",
    "PwmOutput",
    "Reading",
    "RebootLoopError",
    "ReentrantCallError",
    "SchemaMismatchError",
    "ServiceGenError",
    "Servo",
    "SimControlError",
    "StaleCommandError",
    "Stats",
    "TimerInUseError",
    "TransportError",
    "UserError",
    "UserReplyLostError",
    "UserSchemaError",
    "VersionMismatchError",
    "__version__",
    "effective_speed",
]

"""Every error protoduino raises, as one tree::

    ProtoduinoError
     +-- ProtocolError            bytes that break the wire protocol (bad control payload, ...)
     |    +-- PayloadTooLargeError  a message over MAX_PAYLOAD, refused at the sender
     +-- TransportError           the port could not be opened, or was lost
     |    +-- PortInUseError        another program holds the port
     +-- LinkError                the link could not be (re)established
     |    +-- HandshakeError        the device did not answer RESET in time
     |    +-- VersionMismatchError  device and host speak different protocol versions
     |    +-- SchemaMismatchError   firmware generated from another .proto schema
     +-- UserSchemaError          a user service client that does not match the firmware's service
     +-- CommandRejectedError     the device (or the host, checking first) refused a command
     |    +-- InterlockActiveError  an interlock input tripped: outputs latched safe
     |    +-- TimerInUseError       the pin's hardware timer is taken by another mode
     |    +-- NotSupportedError     the pin cannot do the mode, or the firmware lacks it
     |         +-- FeatureMissingError  the firmware was built without the mode (host check)
     |    +-- UserError             a user service's handler refused the call with its own code
     |    +-- UserReplyLostError    a user call ran once, but its reply was lost (a repeat's Ack)
     +-- AckTimeoutError          no Ack after every retry; also a builtin TimeoutError
     +-- BoardClosedError         the board was closed while, or before, the call ran
     +-- ReentrantCallError       a blocking board call from the I/O thread (a frame monitor)
     +-- DeviceRebootedError      the device lost its outputs (rebooted, taken over) mid-call
     |    +-- RebootLoopError       it did so too often: the board stopped restoring
     +-- BuildError               a build step (make, avr-objcopy) failed, or a program it runs
     |                            lacks a shared library here (named, with its Debian package)
     +-- FlashError               avrdude could not upload the firmware
     +-- SimControlError          a simulated board refused an input command (also a ValueError)
     +-- CaptureError             a capture file cannot be written or read
     +-- ArgumentError            a value refused before anything ran; also a builtin ValueError
     +-- ArgumentTypeError        an argument of the wrong type; also a builtin TypeError
     +-- InputTimeoutError        an input's wait_for saw no matching value in time (TimeoutError)
     +-- ServiceGenError          a user's .proto cannot become a service (protoduino gen)
     +-- ConfigError              the ROS 2 bridge's robot.yaml is invalid; also a ValueError
     +-- ExtraMissingError        a package of the ``ros2`` extra is missing; also an ImportError
     +-- BadCommandError          the ROS 2 bridge refuses a message (a Twist, a servo command);
                                  also a ValueError
          +-- StaleCommandError     a Twist older than the drive's timeout on arrival

A refusal the device would give too (a pin that does not exist, an angle outside
0..180) is a :class:`CommandRejectedError` with ``sent=False``; ArgumentError and
ArgumentTypeError are for the rest: options of ``Board.open`` (``session=1.5``),
a value of the wrong type (``servo.write("45")``), an unknown name. Being
ValueError and TypeError too, they are caught by code written for the builtins.

Third-party exceptions (pyserial, protobuf) are wrapped at the boundary with
``raise ... from error`` so callers need to catch only ``ProtoduinoError``.
"""

from __future__ import annotations

from ._generated import protoduino_pb2 as pb


class ProtoduinoError(Exception):
    """Base class of every error raised by protoduino."""


class ProtocolError(ProtoduinoError):
    """Bytes that violate the wire protocol."""


class PayloadTooLargeError(ProtocolError):
    """A payload longer than MAX_PAYLOAD; version 1 has no fragmentation."""


class TransportError(ProtoduinoError):
    """The serial port could not be opened, or failed while in use."""


class PortInUseError(TransportError):
    """Another program (another Board, ``protoduino monitor``...) holds the port."""


class LinkError(ProtoduinoError):
    """The link to the device could not be established."""


class HandshakeError(LinkError):
    """The device did not answer RESET within the handshake timeout."""


class VersionMismatchError(LinkError):
    """Device and host speak different protocol versions."""

    def __init__(self, host_version: int, device_version: int) -> None:
        super().__init__(
            f"protocol version mismatch: host speaks {host_version}, device speaks "
            f"{device_version}; update the host library or flash matching firmware "
            "(protoduino flash PORT)"
        )
        self.host_version = host_version
        self.device_version = device_version


class SchemaMismatchError(LinkError):
    """Firmware and host were generated from different .proto schemas."""

    def __init__(self, host_schema_id: int, device_schema_id: int) -> None:
        super().__init__(
            f"schema mismatch: host SCHEMA_ID 0x{host_schema_id:08X}, device SCHEMA_ID "
            f"0x{device_schema_id:08X}; rebuild and flash the firmware from this checkout "
            "(protoduino flash PORT)"
        )
        self.host_schema_id = host_schema_id
        self.device_schema_id = device_schema_id


class CommandRejectedError(ProtoduinoError):
    """The command was refused; ``status`` says why (a ``Status`` enum value).

    ``sent`` is False when the host refused it before sending, with the same
    status the device would have given. ``output`` is the output object a
    refused pose names (None for other commands).
    """

    def __init__(
        self, status: int, message: str, *, sent: bool = True, output: object = None
    ) -> None:
        super().__init__(message)
        self.status = status
        self.sent = sent
        self.output = output


class InterlockActiveError(CommandRejectedError):
    """STATUS_INTERLOCK_ACTIVE: an interlock input tripped and the outputs are latched safe.

    New values are refused until the input is back at its normal level and
    ``board.clear_interlock()`` succeeded (which is itself refused with this
    error while the input is still at its trip level).
    """


class TimerInUseError(CommandRejectedError):
    """STATUS_TIMER_IN_USE: the pin's hardware timer is taken by another mode.

    On the Uno, Timer1 drives the servos, so pins 9 and 10 cannot do PWM
    while a servo runs (and no servo starts while they do).
    """


class NotSupportedError(CommandRejectedError):
    """STATUS_NOT_SUPPORTED: this pin cannot do this mode on this board (no PWM, ADC or
    interrupt there), or the firmware was built without the mode."""


class FeatureMissingError(NotSupportedError):
    """The firmware on the device was built without the mode's feature; nothing was sent.

    ``feature`` is the feature's name ("pwm", "counter", ...); the message says
    how to get a firmware that has it.
    """

    def __init__(self, feature: str, message: str) -> None:
        super().__init__(pb.STATUS_NOT_SUPPORTED, message, sent=False)
        self.feature = feature


class UserError(CommandRejectedError):
    """STATUS_USER_ERROR: a user service's handler refused the call; nothing was done.

    ``code`` is the handler's code, a value of the user's error enum; a generated
    client raises the subclass it declares for that value (docs/services.md).
    """

    def __init__(self, code: int, message: str) -> None:
        super().__init__(pb.STATUS_USER_ERROR, message)
        self.code = code


class UserReplyLostError(CommandRejectedError):
    """A user call ran exactly once, but the Ack that carried its reply was lost: the
    retransmission was answered from the device's dedupe window, which keeps statuses,
    not replies. Declare a method that only reads ``NO_SIDE_EFFECTS`` and its repeat is
    answered in full (docs/services.md)."""

    def __init__(self, message: str) -> None:
        super().__init__(pb.STATUS_OK, message)


class UserSchemaError(ProtoduinoError):
    """A user service client was attached to a board whose firmware carries another
    service (or none): the message names the .proto and both fingerprints."""

    def __init__(self, proto: str, client_fingerprint: int, device_fingerprint: int) -> None:
        device = (
            f"0x{device_fingerprint:08X}"
            if device_fingerprint
            else "none (the firmware has no user service)"
        )
        super().__init__(
            f"user service mismatch for {proto}: client fingerprint 0x{client_fingerprint:08X}, "
            f"device {device}; build and flash the firmware from the same {proto} "
            "(docs/services.md), or regenerate the client (protoduino gen)"
        )
        self.proto = proto
        self.client_fingerprint = client_fingerprint
        self.device_fingerprint = device_fingerprint


#: The statuses that have a named error.
_REFUSALS: dict[int, type[CommandRejectedError]] = {
    pb.STATUS_INTERLOCK_ACTIVE: InterlockActiveError,
    pb.STATUS_TIMER_IN_USE: TimerInUseError,
    pb.STATUS_NOT_SUPPORTED: NotSupportedError,
}


def rejection(
    status: int, message: str, *, sent: bool = True, output: object = None
) -> CommandRejectedError:
    """The error for a refusal with ``status``: its named subclass where it has one."""
    cls = _REFUSALS.get(status, CommandRejectedError)
    return cls(status, message, sent=sent, output=output)


class AckTimeoutError(ProtoduinoError, TimeoutError):
    """No Ack arrived after ACK_TIMEOUT x (MAX_RETRIES + 1).

    ``recent_frames`` holds the last frames sent and received (readable lines,
    oldest first), also added to the traceback as a note, for diagnosis.
    """

    def __init__(self, message: str = "", *, recent_frames: tuple[str, ...] = ()) -> None:
        super().__init__(message)
        self.recent_frames = recent_frames
        if recent_frames:
            self.add_note("recent frames:\n  " + "\n  ".join(recent_frames))


class BoardClosedError(ProtoduinoError):
    """The board is closed."""


class DeviceRebootedError(ProtoduinoError):
    """The device lost this session's outputs while the call was outstanding.

    It rebooted (a new boot id) or another host session took it over. The call
    may or may not have run before that; it is not sent again. The board has
    re-initialised every output at its safe value (see ``Board.open``'s
    ``restore``); the application decides what to command next.
    """


class RebootLoopError(DeviceRebootedError):
    """The device rebooted too often (a brown-out loop?): the board stopped restoring.

    Every later call raises this; close the board, fix the cause (a servo's
    inrush current on the Uno's 5 V rail is the classic one), and open it again.
    """


class ReentrantCallError(ProtoduinoError, RuntimeError):
    """A blocking board call made on the board's own I/O thread (from a frame monitor).

    The call would wait for its Ack, which only that thread can read: the link
    would stall until the call's deadline. It is refused at once instead.
    """


class BuildError(ProtoduinoError):
    """A build step (make, avr-objcopy) failed; the message carries its output. Also: a
    program protoduino runs cannot run here (a simulated board's program lacks a shared
    library: the message names it and its Debian package)."""


class FlashError(ProtoduinoError):
    """Uploading firmware failed: wrong port, no bootloader answering, or avrdude's error."""


class SimControlError(ProtoduinoError, ValueError):
    """A simulated board's control socket refused an input command; the message says why."""


class CaptureError(ProtoduinoError):
    """A capture file cannot be written, or what was read is not a capture."""


class ArgumentError(ProtoduinoError, ValueError):
    """A value protoduino refuses (out of range, an unknown name), before anything is sent."""


class ArgumentTypeError(ProtoduinoError, TypeError):
    """An argument of a type protoduino does not take (``session=True``, ``degrees="45"``)."""


class InputTimeoutError(ProtoduinoError, TimeoutError):
    """An input's ``wait_for`` saw no value that matched before its timeout."""


class ServiceGenError(ProtoduinoError):
    """The user's .proto cannot become a service (the message says what to change),
    or a generator tool failed or is missing (:mod:`protoduino.servicegen`)."""


class ConfigError(ProtoduinoError, ValueError):
    """The ROS 2 bridge's configuration is invalid (the message names the key)."""


class ExtraMissingError(ProtoduinoError, ImportError):
    """A package of the ``ros2`` extra (cyclonedds, PyYAML) is not installed."""


class BadCommandError(ProtoduinoError, ValueError):
    """A message the ROS 2 bridge refuses, a Twist (:mod:`protoduino.ros2.drive`) or a servo
    command (:mod:`protoduino.ros2.servos`): logged, counted on /diagnostics, nothing moves."""


class StaleCommandError(BadCommandError):
    """A Twist older than the ROS 2 bridge drive's timeout on arrival
    (:meth:`protoduino.ros2.drive.DiffDrive.check_fresh`): refused like a bad one, counted
    apart (``stale``)."""

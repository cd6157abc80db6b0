"""Protocol constants (docs/protocol.md section 8) and the wire's enumerations.

The one source of them for both sides: ``protoduino gen`` writes the ones the
firmware uses (:data:`FIRMWARE_CONSTANTS`, :data:`FIRMWARE_ENUMS`) to
``firmware/generated/pd_protocol.h``, and tests/contract/test_codegen.py fails when the
committed header is stale or carries a constant the firmware does not use.
"""

from __future__ import annotations

from enum import IntEnum

PROTOCOL_VERSION = 8
MAX_PAYLOAD = 255
#: COBS-encoded packet of MAX_PAYLOAD bytes, without the 0x00 delimiter.
MAX_ENCODED_FRAME = 262
#: TYPE + LEN + SEQ in front of the payload, CRC16 behind it.
HEADER_SIZE = 3
CRC_SIZE = 2
MIN_PACKET = HEADER_SIZE + CRC_SIZE

HANDSHAKE_TIMEOUT = 5.0
WATCHDOG_TIMEOUT = 5.0
PING_INTERVAL = 1.0
FAILSAFE_TIMEOUT = 10.0
#: The range a session may configure its failsafe timeout in (seconds).
FAILSAFE_MIN = 0.1
FAILSAFE_MAX = 60.0
ACK_TIMEOUT = 0.25
MAX_RETRIES = 3
SEQ_TOLERANCE = 5
SEQ_DESYNC_THRESHOLD = 50
DEDUPE_WINDOW = 16
#: Message ids are per session and sequential, 1..MAX_MESSAGE_ID (one varint byte), wrapping
#: to 1 (docs/protocol.md section 7, *Message ids*).
MAX_MESSAGE_ID = 127
#: An id at most this many ahead of the newest one is newer; further "ahead" is behind. The
#: host never transmits an id further than this ahead of the device's newest (it
#: re-handshakes first), so both ends always tell newer from older alike.
ID_AHEAD_MAX = 63

#: Servo pulse defaults when a ServoInit leaves min_us/max_us at 0.
SERVO_DEFAULT_MIN_US = 544
SERVO_DEFAULT_MAX_US = 2400
#: Pulse limits any ServoInit must stay within.
SERVO_LIMIT_MIN_US = 400
SERVO_LIMIT_MAX_US = 2600
SERVO_MAX_DEGREES = 180
#: Speed limits (ServoInit.max_speed, us per second) step once per servo frame.
SERVO_FRAME = 0.020
#: The fastest limit: 255 us per frame.
SERVO_MAX_SPEED = 12750

#: PWM duty, as Arduino's analogWrite: 0 (always low) .. 255 (always high).
PWM_MAX_DUTY = 255
#: A digital input's debounce (ms): a level must hold this long to count.
DEBOUNCE_MAX_MS = 255
#: Analog inputs are 10-bit: counts 0..1023.
ANALOG_MAX = 1023
#: The longest sampling, report or heartbeat interval of an input (ms).
INPUT_INTERVAL_MAX_MS = 60000


class PacketType(IntEnum):
    """Packet TYPE (docs/protocol.md section 4)."""

    CONTROL = 0x00
    DATA = 0x01  # device to host: one ArduinoOut
    COMMAND = 0x02  # host to device: one ArduinoIn


class ControlCode(IntEnum):
    """CONTROL payload CODE (docs/protocol.md section 5)."""

    RESET = 0x00
    RESET_ACK = 0x01
    # 0x02 was HEARTBEAT until version 3 (sent by nobody, ignored by the firmware): unassigned.
    EVENT = 0x03
    #: Line rate agreement (docs/protocol.md section 5, *Line rate*): new codes, not
    #: HEARTBEAT's old 0x02 (a version 3 device may still see one).
    BAUD_SET = 0x04
    BAUD_ACK = 0x05


#: CONTROL payload sizes (section 5). RESET: CODE VERSION SESSION(4) NEXT_ID.
#: RESET_ACK: CODE VERSION SCHEMA_ID(4) BOOT_ID(4) FLAGS; its first 6 bytes
#: (version 1's whole RESET_ACK) are all a RESET of another version gets.
RESET_SIZE = 7
RESET_ACK_V1_SIZE = 6
RESET_ACK_SIZE = 11
#: RESET_ACK FLAGS: the session was resumed (the device kept its outputs).
RESET_ACK_RESUMED = 0x01
#: RESET_ACK FLAGS: the line rates above the opening one the device can switch to
#: (docs/protocol.md section 5, *Line rate*): the Uno's clock divides them exactly.
RESET_ACK_BAUD_250K = 0x02
RESET_ACK_BAUD_500K = 0x04
RESET_ACK_BAUD_1M = 0x08
#: The rates those flags name, slowest first (bit 1, 2, 3).
FAST_BAUDRATES = (250_000, 500_000, 1_000_000)
#: The firmware's default opening rate (a build option: ``make -C firmware avr BAUD=...``).
OPENING_BAUDRATE = 115_200
#: BAUD_SET / BAUD_ACK: CODE RATE (4 B big-endian).
BAUD_SIZE = 5
#: After it switched, the device goes back to the opening rate unless a frame other
#: than a BAUD_SET arrives at the new rate within this (seconds).
BAUD_CONFIRM = 0.25
#: The host's probe at the new rate: this many tries, each waiting this long.
BAUD_PROBE_TRIES = 3
BAUD_PROBE_WAIT = 0.05


class EventCode(IntEnum):
    """EVENT codes (docs/protocol.md section 5)."""

    BOOT = 0x01
    NOT_ACTIVE = 0x02
    DESYNC = 0x03
    RX_OVERFLOW = 0x04


#: What the firmware needs of this module, written by ``protoduino gen`` to
#: firmware/generated/pd_protocol.h as ``PD_<NAME>`` (a duration in seconds as
#: ``PD_<NAME>_MS``: the device's clock counts milliseconds). The handshake,
#: watchdog, ping and Ack timings, the retries and SEQ_TOLERANCE are the host's alone.
FIRMWARE_CONSTANTS = (
    "PROTOCOL_VERSION",
    "MAX_PAYLOAD",
    "MAX_ENCODED_FRAME",
    "HEADER_SIZE",
    "MIN_PACKET",
    "FAILSAFE_TIMEOUT",
    "FAILSAFE_MIN",
    "FAILSAFE_MAX",
    "RESET_SIZE",
    "RESET_ACK_V1_SIZE",
    "RESET_ACK_SIZE",
    "RESET_ACK_RESUMED",
    "RESET_ACK_BAUD_250K",
    "RESET_ACK_BAUD_500K",
    "RESET_ACK_BAUD_1M",
    "OPENING_BAUDRATE",
    "BAUD_SIZE",
    "BAUD_CONFIRM",
    "SEQ_DESYNC_THRESHOLD",
    "DEDUPE_WINDOW",
    "MAX_MESSAGE_ID",
    "ID_AHEAD_MAX",
    "SERVO_DEFAULT_MIN_US",
    "SERVO_DEFAULT_MAX_US",
    "SERVO_LIMIT_MIN_US",
    "SERVO_LIMIT_MAX_US",
    "SERVO_MAX_DEGREES",
    "SERVO_FRAME",
    "SERVO_MAX_SPEED",
)
#: The enumerations the firmware needs, by their C prefix: ``PD_<PREFIX>_<MEMBER>``.
FIRMWARE_ENUMS: dict[str, type[IntEnum]] = {
    "PACKET": PacketType,
    "CONTROL": ControlCode,
    "EVENT": EventCode,
}

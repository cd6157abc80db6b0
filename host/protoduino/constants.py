"""Protocol constants (docs/protocol.md section 8) and the wire's enumerations.

The firmware mirrors these in ``firmware/core/pd_protocol.h``; a test compares
the two so they cannot drift.
"""

from __future__ import annotations

from enum import IntEnum

PROTOCOL_VERSION = 1
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
ACK_TIMEOUT = 0.25
MAX_RETRIES = 3
SEQ_TOLERANCE = 5
SEQ_DESYNC_THRESHOLD = 50
DEDUPE_WINDOW = 16

#: Servo pulse defaults when a ServoInit leaves min_us/max_us at 0.
SERVO_DEFAULT_MIN_US = 544
SERVO_DEFAULT_MAX_US = 2400
#: Pulse limits any ServoInit must stay within.
SERVO_LIMIT_MIN_US = 400
SERVO_LIMIT_MAX_US = 2600
SERVO_MAX_DEGREES = 180


class PacketType(IntEnum):
    CONTROL = 0x00
    DATA = 0x01  # device to host: one ArduinoOut
    COMMAND = 0x02  # host to device: one ArduinoIn


class ControlCode(IntEnum):
    RESET = 0x00
    RESET_ACK = 0x01
    HEARTBEAT = 0x02
    EVENT = 0x03


class EventCode(IntEnum):
    BOOT = 0x01
    NOT_ACTIVE = 0x02
    DESYNC = 0x03
    RX_OVERFLOW = 0x04

"""MAVLink 2 with pymavlink: COMMAND_LONG parsing (part 1) and DO_SET_SERVO bytes (part 4)."""

from __future__ import annotations

import io
import random
from typing import Any

from ..core import MissingDependencyError, require
from . import RxCase, WireSample, chunked

#: Who talks: a ground station (system 255, component 190 = MAV_COMP_ID_MISSIONPLANNER) commands
#: an autopilot (system 1, component 1).
GCS = (255, 190)
VEHICLE = (1, 1)

#: 90 degrees on a servo with the Arduino Servo library's default 544..2400 us range, the same
#: mapping protoduino's ServoInit uses; MAV_CMD_DO_SET_SERVO takes a pulse width, not an angle.
SERVO_9_AT_90_US = 544 + 90 * (2400 - 544) // 180


def _dialect() -> Any:
    return require("pymavlink.dialects.v20.common", "pymavlink")


def parser_kind() -> str:
    """How this installation of pymavlink parses: it ships no C parser (``use_native`` is
    accepted and ignored), so only the CRC can be native, through ``fastcrc``."""
    _dialect()
    try:
        require("fastcrc", "fastcrc")
    except MissingDependencyError:
        return "pure Python, CRC pure Python too (fastcrc missing)"
    return "pure Python (pymavlink ships no C parser); CRC-16/MCRF4XX from `fastcrc` (Rust)"


def command_long_stream(frames: int, seed: int) -> bytes:
    """``frames`` COMMAND_LONG DO_SET_SERVO messages a ground station would send."""
    mav = _dialect()
    rng = random.Random(seed)
    sender = mav.MAVLink(io.BytesIO(), srcSystem=GCS[0], srcComponent=GCS[1])
    out: list[bytes] = []
    for _ in range(frames):
        msg = sender.command_long_encode(
            VEHICLE[0],
            VEHICLE[1],
            mav.MAV_CMD_DO_SET_SERVO,
            0,
            float(rng.randrange(1, 17)),
            float(rng.randrange(1000, 2001)),
            0,
            0,
            0,
            0,
            0,
        )
        out.append(bytes(msg.pack(sender)))
    return b"".join(out)


def rx_case(frames: int, chunk: int, seed: int) -> RxCase:
    mav = _dialect()
    stream = command_long_stream(frames, seed)
    chunks = chunked(stream, chunk)
    command_long_id = mav.MAVLINK_MSG_ID_COMMAND_LONG

    def run() -> int:
        parser = mav.MAVLink(None)
        handled = 0
        # The application's table: message id -> handler, then command -> what to do.
        servo_outputs: dict[int, float] = {}
        commands = {mav.MAV_CMD_DO_SET_SERVO: servo_outputs}
        for data in chunks:
            messages = parser.parse_buffer(data)
            if not messages:
                continue
            for msg in messages:
                if msg.get_msgId() == command_long_id:
                    table = commands.get(msg.command)
                    if table is not None:
                        table[int(msg.param1)] = msg.param2
                        handled += 1
        return handled

    return RxCase(
        name="pymavlink (MAVLink 2 COMMAND_LONG)",
        package="pymavlink",
        parser=parser_kind(),
        stages="MAVLink.parse_buffer -> COMMAND_LONG objects -> dispatch on msgid and command",
        stream=stream,
        frames=frames,
        run=run,
    )


def wire_sample() -> WireSample:
    mav = _dialect()
    gcs = mav.MAVLink(io.BytesIO(), srcSystem=GCS[0], srcComponent=GCS[1])
    vehicle = mav.MAVLink(io.BytesIO(), srcSystem=VEHICLE[0], srcComponent=VEHICLE[1])
    command = gcs.command_long_encode(
        VEHICLE[0],
        VEHICLE[1],
        mav.MAV_CMD_DO_SET_SERVO,
        0,
        9.0,
        float(SERVO_9_AT_90_US),
        0,
        0,
        0,
        0,
        0,
    )
    # An autopilot addresses the Ack to the requester (ArduPilot does), so the target fields
    # are set and MAVLink 2's trailing-zero truncation cannot shorten it to one byte.
    ack = vehicle.command_ack_encode(
        mav.MAV_CMD_DO_SET_SERVO, mav.MAV_RESULT_ACCEPTED, 0, 0, GCS[0], GCS[1]
    )
    return WireSample(
        library="MAVLink 2",
        package="pymavlink",
        encoder="pymavlink MAVLink.command_long_encode / command_ack_encode + pack (unsigned)",
        setup=None,
        setup_what="none: the autopilot's parameters define its servo outputs",
        command=bytes(command.pack(gcs)),
        command_what=f"COMMAND_LONG MAV_CMD_DO_SET_SERVO(servo 9, {SERVO_9_AT_90_US} us)",
        ack=bytes(ack.pack(vehicle)),
        ack_what="COMMAND_ACK MAV_RESULT_ACCEPTED, addressed to the sender",
        check="CRC-16/MCRF4XX (+ CRC_EXTRA)",
        notes="DO_SET_SERVO takes a pulse width: 90 deg is "
        f"{SERVO_9_AT_90_US} us on a 544..2400 us servo; payloads truncated by MAVLink 2",
    )

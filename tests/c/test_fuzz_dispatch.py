"""A bounded run of the structure-aware fuzz target (tests/c/fuzz_dispatch.c).

The harness frames every packet itself, so the fuzzer's mutations reach the
nanopb decoder, the dispatcher, the dedupe window, the outputs and the
failsafe rather than dying at the CRC check. ``make -C firmware
fuzz-dispatch-long`` runs it for 10 million executions; docs/reliability.md
records the long runs.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from fuzzing import require_fuzz_tools, run_bounded

ROOT = Path(__file__).resolve().parents[2]
FUZZ_BIN = ROOT / "build" / "fuzz" / "pd_fuzz_dispatch"
FUZZ_USER_BIN = ROOT / "build" / "fuzz" / "pd_fuzz_dispatch_user"
FUZZ_SECONDS = 10


@pytest.mark.slow
def test_fuzz_dispatch_bounded(tmp_path: Path) -> None:
    require_fuzz_tools()
    build = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), "fuzz-dispatch"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    seeds = tmp_path / "seeds"
    seeds.mkdir()
    for i, script in enumerate(_host_seeds()):
        (seeds / f"host-{i}").write_bytes(script)
    run_bounded(FUZZ_BIN, FUZZ_SECONDS, tmp_path, [seeds], min_runs=5_000)


@pytest.mark.slow
def test_fuzz_dispatch_with_a_user_service_bounded(tmp_path: Path) -> None:
    """The same with the probe user service built in (``make -C firmware fuzz-dispatch-user``)."""
    require_fuzz_tools()
    build = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), "fuzz-dispatch-user"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    seeds = tmp_path / "seeds"
    seeds.mkdir()
    for i, script in enumerate(_user_seeds()):
        (seeds / f"user-{i}").write_bytes(script)
    run_bounded(FUZZ_USER_BIN, FUZZ_SECONDS, tmp_path, [seeds], min_runs=5_000)


def _host_seeds() -> list[bytes]:
    """Scripts of commands as the host library writes them (op 0: a COMMAND with its payload),
    the shape the device's short decode takes (pd_dispatch_decode_short: the id, then one
    command), so that mutations start there and the harness compares it with the full
    decode on payloads near and at that shape."""
    from protoduino._generated import protoduino_pb2 as pb

    def command(msg: pb.ArduinoIn) -> bytes:
        payload = msg.SerializeToString()
        return bytes([0, len(payload)]) + payload

    def make(mid: int, member: str, **fields: object) -> pb.ArduinoIn:
        msg = pb.ArduinoIn(message_id=mid)
        getattr(msg, member).SetInParent()
        for name, value in fields.items():
            setattr(getattr(msg, member), name, value)
        return msg

    pose = pb.ArduinoIn(message_id=9)
    pose.pose.items.add().servo.degrees = 90
    pose.pose.items[0].servo.pin = 9
    pose.pose.items.add().digital.pin = 13
    pose.pose.items[1].digital.level = True
    pose.pose.items.add().pwm.pin = 3
    pose.pose.items[2].pwm.duty = 200
    return [
        command(make(1, "digital_init", pin=13))
        + command(make(2, "digital_control", pin=13, level=True))
        + command(make(3, "digital_control", pin=13)),
        command(make(1, "servo_init", pin=9, min_us=1000, max_us=2000))
        + command(make(2, "servo_control", pin=9, degrees=45))
        + command(make(3, "servo_control", pin=9, us=1500)),
        command(make(1, "pwm_init", pin=3, safe_duty=0))
        + command(make(2, "pwm_control", pin=3, duty=128))
        + command(make(3, "ping", payload=b"\x01\x02", failsafe_epoch=0)),
        command(make(1, "servo_init", pin=9))
        + command(make(2, "digital_init", pin=13))
        + command(make(3, "pwm_init", pin=3))
        + command(pose)
        + command(make(10, "heartbeat", failsafe_epoch=0)),
    ]


def _user_seeds() -> list[bytes]:
    """Scripts of UserCalls to the probe service (fuzz_dispatch.c: op 0, a COMMAND with its
    payload; op 6, time passes and a poll sends reports), so that mutations start from calls
    that reach the handlers: Echo (refused, replied, publishing a report), Peek, Claim, the
    report method, an unknown one."""
    from protoduino._generated import protoduino_pb2 as pb

    def command(mid: int, method: int, request: bytes) -> bytes:
        msg = pb.ArduinoIn(message_id=mid)
        msg.user_call.method = method
        msg.user_call.request = request
        payload = msg.SerializeToString()
        return bytes([0, len(payload)]) + payload

    poll = bytes([6, 1])
    return [
        command(1, 1, b"\x08\x05\x12\x03abc") + command(1, 1, b"\x08\x05") + poll,
        command(2, 1, b"") + command(3, 1, b"\x08\x04") + poll + command(4, 2, b""),
        command(5, 3, b"\x08\x05") + command(6, 3, b"\x08\x05") + poll + command(7, 4, b""),
        command(8, 9, b"\x08\x01") + command(9, 1, b"\x08\x02") + poll + poll,
    ]

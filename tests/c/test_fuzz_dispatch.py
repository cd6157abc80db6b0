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
    run_bounded(FUZZ_BIN, FUZZ_SECONDS, tmp_path, [], min_runs=5_000)


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

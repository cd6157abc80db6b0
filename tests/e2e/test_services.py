"""User services end to end (docs/services.md, issue 22): the examples built with
``make -C firmware sim avr USER_PROTO=... USER_SRC=...`` and run on both boards.

The blinker drives an output (judged at the pin in the board's trace; the failsafe
and Stop make it safe); the button counter reads an input driven through the
control socket and streams reports. Each is called through its generated client.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import protoduino
import pytest
from protoduino import aio
from protoduino._generated import protoduino_pb2 as pb
from protoduino.events import Event, EventKind
from protoduino.simboard import SimBoard
from simfixtures import pin_values, wait_for_pin, wait_until
from userbuilds import client, need, program

BACKENDS = ["native", "avr"]


@pytest.fixture(params=BACKENDS)
def backend(request: pytest.FixtureRequest) -> str:
    name: str = request.param
    need(name)
    return name


def start(name: str, backend: str, tmp_path: Path) -> SimBoard:
    sim = SimBoard(backend, trace=tmp_path / "trace.jsonl", firmware=program(name, backend))
    sim.start()
    return sim


@pytest.fixture
def blinker_sim(backend: str, tmp_path: Path) -> Iterator[SimBoard]:
    sim = start("blinker", backend, tmp_path)
    try:
        yield sim
    finally:
        sim.stop()


@pytest.fixture
def presses_sim(backend: str, tmp_path: Path) -> Iterator[SimBoard]:
    sim = start("presses", backend, tmp_path)
    try:
        yield sim
    finally:
        sim.stop()


def test_blinker_drives_its_pin_and_the_failsafe_makes_it_safe(
    blinker_sim: SimBoard, monkeypatch: pytest.MonkeyPatch
) -> None:
    mod = client("blinker", monkeypatch)
    pbu = mod.pb
    events: list[Event] = []
    with protoduino.Board.open(blinker_sim.port, failsafe_timeout=0.5) as board:
        board.on_event(events.append)
        assert board.info.user_fingerprint == mod.FINGERPRINT
        assert "servo" in board.info.features  # the built-ins are all there
        blinker = mod.Blinker(board)

        # Refusals of the handler's own: named errors, nothing done.
        with pytest.raises(mod.BadPeriodError) as bad:
            blinker.start_blink(pbu.Blink(pin=13, period_ms=5))
        assert bad.value.code == pbu.BLINKER_ERROR_BAD_PERIOD
        assert isinstance(bad.value, protoduino.UserError)
        assert blinker.count(pbu.Empty()).count == 0

        # One pin table: a built-in's pin is refused to the handler, and the reverse.
        board.digital_output(12, safe=False)
        with pytest.raises(mod.PinUnavailableError):
            blinker.start_blink(pbu.Blink(pin=12, period_ms=40))
        reply = blinker.start_blink(pbu.Blink(pin=13, period_ms=40))
        assert (reply.pin, reply.half_ms) == (13, 20)
        with pytest.raises(protoduino.CommandRejectedError) as taken:
            board.digital_output(13)
        assert taken.value.status == pb.STATUS_PIN_IN_USE

        # The device toggles the pin on its own (the poll hook), every 20 ms of its clock.
        values = wait_for_pin(blinker_sim, 13, lambda v: len(v) >= 6)
        assert values[:6] == [1, 0, 1, 0, 1, 0]
        times = [e["t"] for e in blinker_sim.trace() if e["pin"] == 13][:6]
        gaps = [b - a for a, b in itertools.pairwise(times)]
        if blinker_sim.backend == "avr":  # the emulated clock: exact to its millisecond tick
            assert all(abs(g - 0.020) <= 0.0015 for g in gaps), gaps
        else:  # the native board's clock is this machine's: never early on average
            assert sum(gaps) / len(gaps) >= 0.019, gaps

        # Stop: the service's safe state (low), and it stays there.
        board.stop()
        wait_for_pin(blinker_sim, 13, lambda v: v[-1] == 0)
        after = blinker.count(pbu.Empty())
        assert not after.on
        assert blinker.count(pbu.Empty()).count == after.count

        # The failsafe: no sign of life for 0.5 s and the pin goes low, by itself.
        board.heartbeat()  # a Control after a Stop is protected like any other
        blinker.start_blink(pbu.Blink(pin=13, period_ms=40))
        wait_for_pin(blinker_sim, 13, lambda v: len(v) > len(values) + 2)
        board.pinging = False
        wait_for_event(events, "ping_timeout")
        assert pin_values(blinker_sim.trace(), 13)[-1] == 0
        assert not blinker.count(pbu.Empty()).on  # NO_SIDE_EFFECTS: answered while expired
        with pytest.raises(protoduino.CommandRejectedError) as expired:
            blinker.start_blink(pbu.Blink(pin=13, period_ms=40))
        assert expired.value.status == pb.STATUS_FAILSAFE_EXPIRED
        board.pinging = True


def test_a_reboot_empties_the_service(
    blinker_sim: SimBoard, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reboot clears the service's state on both boards (docs/services.md, *A reboot*):
    the emulated Uno's C runtime does at reset; the simulated board restores the user's
    static data as the program started with it."""
    mod = client("blinker", monkeypatch)
    pbu = mod.pb
    with protoduino.Board.open(blinker_sim.port) as board:
        blinker = mod.Blinker(board)
        blinker.start_blink(pbu.Blink(pin=13, period_ms=40))
        wait_for_pin(blinker_sim, 13, lambda v: len(v) >= 3)
        before = blinker.count(pbu.Empty())
        assert before.on and before.count >= 3
        blinker_sim.reboot()
        assert wait_until(lambda: board.stats.reboots == 1), "no reboot noticed"
        after = blinker.count(pbu.Empty())
        assert (after.count, after.on) == (0, False)


def test_a_call_that_ran_is_answered_as_run_even_past_its_reply_bounds(
    backend: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The probe's Overfill handler fills its reply's strings to their last byte, and a
    count and a size past their arrays: the call ran, so it is answered as run, its reply
    within the bounds nanopb encodes (docs/services.md, *What a user call guarantees*)."""
    mod = client("probe", monkeypatch)
    pbu = mod.pb
    with start("probe", backend, tmp_path) as sim, protoduino.Board.open(sim.port) as board:
        probe = mod.Probe(board)
        label = probe.overfill(pbu.Empty())
        assert label.text == "x" * 7  # the string's last byte is its terminator's
        assert list(label.values) == [1, 2, 3]
        assert (label.tag.text, label.tag.blob) == ("yyy", b"zzzz")


def wait_for_event(events: list[Event], cause: str, timeout: float = 30.0) -> None:
    """Wait for the board's FAILSAFE event of ``cause`` (the device's verdict: ``timeout``
    only bounds how long a failing test waits)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for event in list(events):
            data = event.details
            if (
                event.kind is EventKind.FAILSAFE
                and data.get("active")
                and data.get("cause") == cause
            ):
                return
        time.sleep(0.02)
    raise AssertionError(f"no failsafe event of cause {cause}: {events}")


def test_presses_reads_its_button_and_reports_every_change(
    presses_sim: SimBoard, monkeypatch: pytest.MonkeyPatch
) -> None:
    mod = client("presses", monkeypatch)
    pbu = mod.pb
    seen: list[Any] = []
    cond = threading.Condition()

    def on_change(report: Any) -> None:
        with cond:
            seen.append(report.value)
            cond.notify_all()

    def wait(test: Any) -> Any:
        with cond:
            assert cond.wait_for(lambda: any(test(v) for v in seen), timeout=30.0), seen
            return next(v for v in seen if test(v))

    with protoduino.Board.open(presses_sim.port) as board:
        presses = mod.Presses(board)
        with pytest.raises(mod.BadDebounceError):
            presses.watch_button(pbu.Watch(pin=2, debounce_ms=300))
        presses.on_changes(on_change)
        first = presses.watch_button(pbu.Watch(pin=2, debounce_ms=5))
        assert first.level and first.count == 0  # the pull-up: high while not pressed
        with pytest.raises(protoduino.CommandRejectedError) as taken:
            board.digital_input(2)
        assert taken.value.status == pb.STATUS_PIN_IN_USE

        presses_sim.set_level(2, 0)
        wait(lambda v: v.count == 1 and not v.level)
        presses_sim.set_level(2, 1)
        wait(lambda v: v.count == 1 and v.level)
        presses_sim.set_level(2, 0)
        pressed = wait(lambda v: v.count == 2 and not v.level)
        assert presses.total(pbu.Empty()).count == 2
        latest = presses.changes()
        assert latest is not None and latest.value.count == 2
        assert pressed.time_ms >= first.time_ms


def test_reports_as_an_async_iterator(
    presses_sim: SimBoard, monkeypatch: pytest.MonkeyPatch
) -> None:
    mod = client("presses", monkeypatch)
    pbu = mod.pb

    async def main() -> list[tuple[int, bool]]:
        async with await aio.open(presses_sim.port) as board:
            presses = mod.AsyncPresses(board)
            await presses.watch_button(pbu.Watch(pin=3, debounce_ms=0))
            got: list[tuple[int, bool]] = []
            async with presses.changes_reports() as stream:
                await asyncio.to_thread(presses_sim.set_level, 3, 0)
                async for report in stream:
                    got.append((report.value.count, report.value.level))
                    if report.value.count == 1 and not report.value.level:
                        break
            total = await presses.total(pbu.Empty())
            assert total.count == 1
            return got

    got = asyncio.run(main())
    assert got[-1] == (1, False)


def test_a_client_of_another_service_is_refused_by_name(
    presses_sim: SimBoard, monkeypatch: pytest.MonkeyPatch
) -> None:
    blinker = client("blinker", monkeypatch)
    presses = client("presses", monkeypatch)
    with protoduino.Board.open(presses_sim.port) as board:
        with pytest.raises(protoduino.UserSchemaError) as error:
            blinker.Blinker(board)
        text = str(error.value)
        assert "blinker.proto" in text
        assert f"0x{blinker.FINGERPRINT:08X}" in text and f"0x{presses.FINGERPRINT:08X}" in text
        board.ping()  # a host without the client still has the built-ins


def test_the_default_firmware_has_no_service(
    sim_board: SimBoard, monkeypatch: pytest.MonkeyPatch
) -> None:
    blinker = client("blinker", monkeypatch)
    with protoduino.Board.open(sim_board.port) as board:
        assert board.info.user_fingerprint == 0
        with pytest.raises(protoduino.UserSchemaError, match="no user service"):
            blinker.Blinker(board)
        with pytest.raises(protoduino.NotSupportedError):
            board.call_user(1, b"")


def test_the_command_line_runs_a_user_build(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`protoduino sim --firmware` runs the user's board; `protoduino info` shows its service."""
    need("native")
    mod = client("blinker", monkeypatch)
    cli = [sys.executable, "-m", "protoduino.cli.main"]
    pid_file = tmp_path / "sim.pid"
    started = subprocess.run(
        [
            *cli,
            "sim",
            "--firmware",
            str(program("blinker", "native")),
            "--detach",
            "--pid-file",
            str(pid_file),
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
    )
    assert started.returncode == 0, started.stderr
    try:
        info = subprocess.run(
            [*cli, "info", started.stdout.strip(), "--json", "--new-session"],
            capture_output=True,
            text=True,
            check=False,
            timeout=60,
        )
        assert info.returncode == 0, info.stderr
        assert json.loads(info.stdout)["info"]["user_fingerprint"] == f"0x{mod.FINGERPRINT:08X}"
    finally:
        subprocess.run([*cli, "sim", "--stop", str(pid_file)], check=False, timeout=60)

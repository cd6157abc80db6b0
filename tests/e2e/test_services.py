"""User services end to end (docs/services.md, issue 22): the examples built with
``make -C firmware sim avr USER_PROTO=... USER_SRC=...`` and run on both boards.

The blinker drives an output (judged at the pin in the board's trace; the failsafe
and Stop make it safe); the button counter reads an input driven through the
control socket and streams reports. Each is called through its generated client.
"""

from __future__ import annotations

import asyncio
import itertools
import re
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import protoduino
import pytest
from boardprocess import detached_sim_info
from protoduino import aio
from protoduino._generated import protoduino_pb2 as pb
from protoduino.events import Event, EventKind
from protoduino.simboard import SimBoard
from simfixtures import pin_values, wait_for_pin, wait_until
from userbuilds import ROOT, client, need, program

BACKENDS = ["native", "avr"]
#: How late the emulated Uno's main loop may run a poll hook after its clock's tick: one
#: pass that handles a command (about 8,000 cycles, 0.5 ms at 16 MHz), doubled.
MAIN_LOOP_SLACK = 0.001


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
    stopped: list[Any] = []  # the safe hook's reports (its ctx lets it publish)
    with protoduino.Board.open(blinker_sim.port, failsafe_timeout=0.5) as board:
        board.on_event(events.append)
        assert board.info.user_fingerprint == mod.FINGERPRINT
        assert "servo" in board.info.features  # the built-ins are all there
        blinker = mod.Blinker(board)
        blinker.on_stopped(lambda report: stopped.append(report.value))

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
        if blinker_sim.backend == "avr":
            # The emulated clock: 20 ms of millis() is 19 or 20 of Timer0's 1,024 us
            # overflows (one step of 2 every 41 or 42), so a toggle after the first comes
            # 19.456 or 20.48 ms after the last, give or take the loop pass it waits for
            # (MAIN_LOOP_SLACK). The first starts from start_blink's read of the clock,
            # anywhere within an overflow: at most one overflow sooner than that.
            overflow = 0.001024
            assert 19 * overflow - overflow <= gaps[0] <= 20 * overflow + MAIN_LOOP_SLACK, gaps
            assert all(
                19 * overflow - MAIN_LOOP_SLACK <= g <= 20 * overflow + MAIN_LOOP_SLACK
                for g in gaps[1:]
            ), gaps
        else:  # the native board's clock is this machine's: never early on average
            assert sum(gaps) / len(gaps) >= 0.019, gaps

        # Stop: the service's safe state (low), and it stays there; its safe hook says so.
        assert stopped == []
        board.stop()
        wait_for_pin(blinker_sim, 13, lambda v: v[-1] == 0)
        after = blinker.count(pbu.Empty())
        assert not after.on
        assert wait_until(lambda: len(stopped) == 1)
        assert stopped[0].count == after.count and not stopped[0].on
        assert blinker.count(pbu.Empty()).count == after.count

        # The failsafe: no sign of life for 0.5 s and the pin goes low, by itself.
        board.heartbeat()  # a Control after a Stop is protected like any other
        blinker.start_blink(pbu.Blink(pin=13, period_ms=40))
        wait_for_pin(blinker_sim, 13, lambda v: len(v) > len(values) + 2)
        board.pinging = False
        wait_for_event(events, "ping_timeout")
        assert pin_values(blinker_sim.trace(), 13)[-1] == 0
        assert wait_until(lambda: len(stopped) == 2)
        assert not blinker.count(pbu.Empty()).on  # NO_SIDE_EFFECTS: answered while expired
        with pytest.raises(protoduino.CommandRejectedError) as expired:
            blinker.start_blink(pbu.Blink(pin=13, period_ms=40))
        assert expired.value.status == pb.STATUS_FAILSAFE_EXPIRED
        # The refusal names the rpc and what lifts it, for the asyncio form as well.
        text = str(expired.value)
        assert text.startswith("StartBlink refused by the device: STATUS_FAILSAFE_EXPIRED: ")
        assert "board.ping() re-arms it, then call StartBlink again" in text
        with pytest.raises(protoduino.CommandRejectedError) as submitted:
            blinker.submit_start_blink(pbu.Blink(pin=13, period_ms=40)).result(timeout=30)
        assert str(submitted.value) == text
        board.ping()  # the remedy it names
        assert blinker.start_blink(pbu.Blink(pin=13, period_ms=40)).half_ms == 20
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

        # The handler releases the pin it claimed (pd_user_release): free for any mode.
        assert presses.unwatch(pbu.Empty()).count == 2
        button = board.digital_input(2, pull_up=True)
        presses_sim.set_level(2, 1)
        assert wait_until(lambda: button.read() is True)
        with pytest.raises(mod.PinUnavailableError):  # the handler's claim is refused now
            presses.watch_button(pbu.Watch(pin=2, debounce_ms=5))


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
    stated = detached_sim_info(
        tmp_path / "sim.pid", "--firmware", str(program("blinker", "native"))
    )
    assert stated["user_fingerprint"] == f"0x{mod.FINGERPRINT:08X}"


def _make(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )


def test_a_relative_user_path_is_explained(tmp_path: Path) -> None:
    """make -C runs in firmware/: a path relative to the caller's folder names the rule."""
    need("native")
    (tmp_path / "t").mkdir()
    for suffix in (".proto", ".c"):
        (tmp_path / "t" / f"blinker{suffix}").write_bytes(
            (ROOT / "examples" / "blinker" / f"blinker{suffix}").read_bytes()
        )
    built = _make(
        tmp_path,
        "sim",
        f"BUILD={tmp_path / 'build'}",
        "USER_PROTO=t/blinker.proto",
        "USER_SRC=t/blinker.c",
    )
    assert built.returncode != 0
    assert "USER_PROTO=t/blinker.proto: no such file" in built.stderr, built.stderr
    assert 'give an absolute one, e.g. USER_PROTO="$PWD/t/blinker.proto"' in built.stderr
    built = _make(
        tmp_path,
        "sim",
        f"BUILD={tmp_path / 'build'}",
        f"USER_PROTO={tmp_path / 't' / 'blinker.proto'}",
        "USER_SRC=t/blinker.c",
    )
    assert "USER_SRC=t/blinker.c: no such file" in built.stderr, built.stderr


#: A service whose handler reads a table of TABLE bytes kept in the Uno's flash.
BIG_PROTO = """syntax = "proto3";
package big;
message Index { uint32 at = 1; }
message Value { uint32 value = 1; }
service Big { rpc Look(Index) returns (Value); }
"""
BIG_C = """#include "big_service.h"
#ifdef __AVR__
#include <avr/pgmspace.h>
static const uint8_t table[TABLE] PROGMEM = {1, 2, 3};
#define READ(p) pgm_read_byte(p)
#else
static const uint8_t table[TABLE] = {1, 2, 3};
#define READ(p) (*(p))
#endif

uint8_t big_look(pd_user_ctx_t *ctx, const big_Index *request, big_Value *reply)
{
    (void)ctx;
    reply->value = READ(&table[request->at % sizeof table]);
    return 0;
}

void big_safe(pd_user_ctx_t *ctx, uint8_t pin) { (void)ctx; (void)pin; }
void big_release(pd_user_ctx_t *ctx, uint8_t pin) { (void)ctx; (void)pin; }
void big_poll(pd_user_ctx_t *ctx, uint32_t now_ms) { (void)ctx; (void)now_ms; }
"""


def _build_big(tmp_path: Path, table: int) -> tuple[subprocess.CompletedProcess[str], Path]:
    folder = tmp_path / str(table)
    folder.mkdir()
    (folder / "big.proto").write_text(BIG_PROTO)
    (folder / "big.c").write_text(BIG_C.replace("TABLE", str(table)))
    built = _make(
        folder,
        "avr",
        f"BUILD={folder / 'build'}",
        f"USER_PROTO={folder / 'big.proto'}",
        f"USER_SRC={folder / 'big.c'}",
    )
    return built, folder / "build" / "user" / "big" / "avr" / "protoduino.hex"


def test_a_build_over_the_flash_says_what_to_do(tmp_path: Path) -> None:
    """Over the default firmware's budget: built, with what it means and which FEATURES
    shrink it. Over the flash Optiboot leaves (32,256 B of the Uno's 32,768), or over the
    chip's: refused with the same advice, and no hex."""
    need("avr")
    hint = "For room, build only the pin modes it uses: FEATURES lists them (this build: FEATURES="
    built, hex_file = _build_big(tmp_path, 1000)
    assert built.returncode == 0, built.stderr
    assert "over the default firmware's 26624 B budget but fits the Uno (32256 B" in built.stdout
    assert hint in built.stdout
    assert hex_file.is_file()
    flash = int(re.findall(r"flash (\d+) B", built.stdout)[0])

    # 200 B past what Optiboot leaves: linked, but no hex.
    built, hex_file = _build_big(tmp_path, 1000 + 32256 - flash + 200)
    assert built.returncode != 0, built.stdout
    assert re.search(
        r"flash 32[45]\d\d B does not fit the Uno: 32256 B \(32768 less Optiboot's "
        r"512\); no hex written",
        built.stderr,
    ), built.stderr
    assert hint in built.stderr
    assert not hex_file.exists()

    # Past the chip's 32 KB: the linker refuses, and the build says the same.
    built, hex_file = _build_big(tmp_path, 7000)
    assert built.returncode != 0, built.stdout
    assert "region `text' overflowed" in built.stderr
    assert "does not fit the Uno: larger than its 32768 B of flash" in built.stderr
    assert hint in built.stderr
    assert not hex_file.exists()

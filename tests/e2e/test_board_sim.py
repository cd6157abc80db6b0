"""The Board API against the real simulated board (firmware core on a pty), checked in its trace."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import protoduino
import pytest
import serial
from protoduino import Board, Event, EventKind
from protoduino.commands import SERVO
from protoduino.messages import ArduinoIn, Status
from protoduino.simboard import SimBoard
from protoduino.transport import FrameRecord
from simfixtures import PULSE_TOLERANCE_US, SIM_BACKENDS, pin_values, pins_for, wait_until

SAFE_90_US = 544 + 90 * (2400 - 544) // 180  # 1472


def us(degrees: int, lo: int = 544, hi: int = 2400) -> int:
    return lo + degrees * (hi - lo) // 180


@pytest.fixture
def sim(sim_board: SimBoard) -> SimBoard:
    """The shared fixture (one per backend), started, tracing."""
    return sim_board


@pytest.fixture
def board(sim: SimBoard) -> Iterator[Board]:
    with Board.open(sim.port) as b:
        yield b


BOARD_NAME = {"native": "sim", "avr": "uno"}


def fits(actual: list[int], expected: list[int], tol: int, exact: bool) -> bool:
    """Exactly ``expected`` (native), or an in-order subsequence of it ending like it."""
    if exact:
        return actual == expected
    if not actual or abs(actual[-1] - expected[-1]) > tol:
        return False
    i = 0
    for value in actual:
        while i < len(expected) and abs(value - expected[i]) > tol:
            i += 1
        if i == len(expected):
            return False
    return True


def expect_pin(
    sim: SimBoard,
    pin: int,
    expected: list[int],
    *,
    since: int = 0,
    digital: bool = False,
    timeout: float = 30.0,
) -> None:
    """Wait until the trace (from line ``since``) shows ``expected`` for ``pin``: a digital
    pin's every level on both boards (the emulated Uno's trace shows every edge of one)."""
    exact = sim.backend == "native" or digital
    tol = 0 if exact else PULSE_TOLERANCE_US

    def values() -> list[int]:
        return pin_values(sim.trace()[since:], pin)

    def ok() -> bool:
        return fits(values(), expected, tol, exact)

    if not wait_until(ok, timeout):
        raise AssertionError(f"pin {pin}: trace shows {values()}, expected {expected}")


class Recorder:
    def __init__(self, board: Board) -> None:
        self.events: list[Event] = []
        board.on_event(self.events.append)

    def wait(self, kind: EventKind, timeout: float = 30.0, count: int = 1) -> list[Event]:
        ok = wait_until(lambda: len(self.of(kind)) >= count, timeout)
        assert ok, f"no {kind} event in {timeout} s; got {self.events}"
        return self.of(kind)

    def of(self, kind: EventKind) -> list[Event]:
        return [e for e in list(self.events) if e.kind is kind]


def test_every_api_call(board: Board, sim: SimBoard) -> None:
    assert board.info.board == BOARD_NAME[sim.backend]
    assert board.info.firmware_version == protoduino.__version__
    assert board.info.protocol_version == protoduino.PROTOCOL_VERSION
    assert board.info.schema_id == protoduino.SCHEMA_ID
    assert (board.info.num_pins, board.info.max_servos) == (20, 8)
    assert board.info.reserved_pins == (0, 1)
    servo = board.servo(9, safe=90)
    servo.write(45)
    servo.write_us(1500)
    narrow = board.servo(10, safe_us=1200, min_us=1000, max_us=2000)
    narrow.write(180)
    led = board.digital_output(13, safe=False)
    led.write(True)
    assert board.ping(b"payload") > 0
    board.stop()
    expect_pin(sim, 9, [SAFE_90_US, us(45), 1500, SAFE_90_US])
    expect_pin(sim, 10, [1200, 2000, 1200])
    expect_pin(sim, 13, [0, 1, 0], digital=True)  # init (safe), on, stop (safe)
    assert board.stats.timeouts == 0 and board.stats.rejected == 0


@pytest.mark.mega
def test_stop_latches_until_commanded(board: Board, sim: SimBoard) -> None:
    servo = board.servo(9)
    led = board.digital_output(13)
    servo.write(0)
    led.on()
    rec = Recorder(board)
    board.stop()
    event = rec.wait(EventKind.FAILSAFE)[0]
    assert event.details == {"active": True, "cause": "stop", "epoch": 1}
    servo.write(180)  # a control moves it normally again
    expect_pin(sim, 9, [SAFE_90_US, us(0), SAFE_90_US, us(180)])
    expect_pin(sim, 13, [0, 1, 0], digital=True)  # the LED stays safe until commanded


def raw(build: Callable[[Any], None]) -> Any:
    msg = ArduinoIn()
    build(msg)
    return msg


# (name, the API call, the same command sent raw past the host's checks)
CASES: list[tuple[str, Callable[[Board], object], Callable[[Any], None]]] = [
    ("pin 20", lambda b: b.servo(20), lambda m: m.servo_init.MergeFrom(_si(20))),
    ("reserved 0", lambda b: b.digital_output(0), lambda m: setattr(m.digital_init, "pin", 0)),
    ("reserved 1", lambda b: b.servo(1), lambda m: m.servo_init.MergeFrom(_si(1))),
    (
        "min_us 399",
        lambda b: b.servo(9, min_us=399),
        lambda m: m.servo_init.MergeFrom(_si(9, min_us=399)),
    ),
    (
        "max_us 2601",
        lambda b: b.servo(9, max_us=2601),
        lambda m: m.servo_init.MergeFrom(_si(9, max_us=2601)),
    ),
    (
        "min >= max",
        lambda b: b.servo(9, min_us=2000, max_us=1000),
        lambda m: m.servo_init.MergeFrom(_si(9, min_us=2000, max_us=1000)),
    ),
    ("safe 181", lambda b: b.servo(9, safe=181), lambda m: m.servo_init.MergeFrom(_si(9, 181))),
    (
        "safe_us 2401",
        lambda b: b.servo(9, safe_us=2401),
        lambda m: m.servo_init.MergeFrom(_si(9, safe_us=2401)),
    ),
    ("ping 65 bytes", lambda b: b.ping(bytes(65)), lambda m: setattr(m.ping, "payload", bytes(65))),
]


def _si(pin: int, safe: int = 90, *, safe_us: int = 0, min_us: int = 0, max_us: int = 0) -> Any:
    init = ArduinoIn().servo_init
    init.pin, init.min_us, init.max_us = pin, min_us, max_us
    if safe_us:
        init.safe_us = safe_us
    else:
        init.safe_degrees = safe
    return init


@pytest.mark.parametrize(("name", "api", "build"), CASES, ids=[c[0] for c in CASES])
def test_host_checks_match_the_device(
    board: Board, name: str, api: Callable[[Board], object], build: Callable[[Any], None]
) -> None:
    with pytest.raises(protoduino.CommandRejectedError) as host:
        api(board)
    assert host.value.sent is False
    with pytest.raises(protoduino.CommandRejectedError) as device:
        board.request(raw(build))  # the same command, past the host's checks
    assert device.value.sent is True
    assert host.value.status == device.value.status


@pytest.mark.mega
def test_state_dependent_checks_match_the_device(board: Board) -> None:
    board.digital_output(13)
    with pytest.raises(protoduino.CommandRejectedError) as host:
        board.servo(13)
    with pytest.raises(protoduino.CommandRejectedError) as device:
        board.request(raw(lambda m: m.servo_init.MergeFrom(_si(13))))
    assert host.value.status == device.value.status == Status.STATUS_PIN_IN_USE
    servo = board.servo(9, min_us=1000, max_us=2000)
    with pytest.raises(protoduino.CommandRejectedError) as host:
        servo.write_us(2001)
    with pytest.raises(protoduino.CommandRejectedError) as device:
        board.request(raw(lambda m: m.servo_control.MergeFrom(_sc(9, us_=2001))))
    assert host.value.status == device.value.status == Status.STATUS_OUT_OF_RANGE
    for pin in pins_for(board, SERVO, board.info.max_servos - 1, avoid=(9, 10, 13)):
        board.servo(pin)  # every servo slot the device states (the Uno's 8, the Mega's 24)
    with pytest.raises(protoduino.CommandRejectedError) as host:
        board.servo(10)
    with pytest.raises(protoduino.CommandRejectedError) as device:
        board.request(raw(lambda m: m.servo_init.MergeFrom(_si(10))))
    assert host.value.status == device.value.status == Status.STATUS_NO_FREE_RESOURCE


def _sc(pin: int, *, us_: int) -> Any:
    ctl = ArduinoIn().servo_control
    ctl.pin, ctl.us = pin, us_
    return ctl


@pytest.mark.mega
def test_device_only_rejections(board: Board) -> None:
    cases: list[tuple[Callable[[Any], None], int]] = [
        (lambda m: m.servo_control.MergeFrom(_sc(12, us_=1500)), Status.STATUS_NOT_INITIALISED),
        (lambda m: setattr(m.digital_control, "pin", 12), Status.STATUS_NOT_INITIALISED),
        (lambda m: setattr(m.servo_init, "pin", 9), Status.STATUS_INVALID_ARGUMENT),  # no safe
        (lambda m: None, Status.STATUS_UNKNOWN_COMMAND),
    ]
    for build, status in cases:
        with pytest.raises(protoduino.CommandRejectedError) as info:
            board.request(raw(build))
        assert info.value.status == status and info.value.sent


@pytest.mark.mega
def test_restore_after_reboot_brings_outputs_up_safe(board: Board, sim: SimBoard) -> None:
    """Defect 3: after a reboot an output comes back at its safe value, not at a stale pose."""
    rec = Recorder(board)
    board.servo(9).write(30)
    board.digital_output(13).on()
    expect_pin(sim, 9, [SAFE_90_US, us(30)])
    before = len(sim.trace())
    sim.reboot()
    restored = rec.wait(EventKind.RESTORED)[0]
    assert restored.details["values"] is False
    assert rec.of(EventKind.REBOOTED)
    board.ping()  # the restore is acknowledged: anything it moved is at the pins
    # the reboot drops every output (value 0), the restore brings each back safe, and stays
    expect_pin(sim, 9, [0, SAFE_90_US], since=before)
    expect_pin(sim, 13, [0, 0], since=before, digital=True)  # released, init (safe)
    assert board.stats.reboots == 1


@pytest.mark.mega
def test_restore_last_values_when_opted_in(sim: SimBoard) -> None:
    with Board.open(sim.port, restore="last") as board:
        rec = Recorder(board)
        board.servo(9).write(30)
        board.digital_output(13).on()
        expect_pin(sim, 9, [SAFE_90_US, us(30)])
        before = len(sim.trace())
        sim.reboot()
        assert rec.wait(EventKind.RESTORED)[0].details["values"] is True
        expect_pin(sim, 9, [0, SAFE_90_US, us(30)], since=before)
        expect_pin(sim, 13, [0, 0, 1], since=before, digital=True)


@pytest.mark.mega
def test_a_reboot_loop_stops_restoring(sim: SimBoard) -> None:
    with Board.open(sim.port, ping=False, reboot_limit=3, reboot_window=60.0) as board:
        rec = Recorder(board)
        servo = board.servo(9)
        for n in (1, 2):
            sim.reboot()
            rec.wait(EventKind.RESTORED, count=n)
            board.ping()
        before = len(sim.trace())
        sim.reboot()
        assert "reboot loop" in rec.wait(EventKind.ERROR)[0].text
        with pytest.raises(protoduino.RebootLoopError):
            servo.write(10)
        # The decision was taken with the handshake, before the event: no restore began.
        state = board.rpc_state()
        assert not state.inflight and state.pending == 0
        assert board.stats.reboots == 3
        assert pin_values(sim.trace()[before:], 9) in ([0], [])


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_reconnect_and_restore_after_the_sim_is_killed(backend: str, tmp_path: Path) -> None:
    link = tmp_path / "port"  # a stable path: the restarted board's pty appears under it
    first = SimBoard(backend, trace=tmp_path / "one.jsonl", link=link)
    second = SimBoard(backend, trace=tmp_path / "two.jsonl", link=link)
    try:
        first.start()
        with Board.open(str(link), handshake_timeout=1.0) as board:
            rec = Recorder(board)
            board.servo(9).write(120)
            board.digital_output(13).on()
            first.kill()  # the pty disappears ...
            link.unlink(missing_ok=True)  # ... and its path (a stale link could meet a new pty)
            assert wait_until(lambda: not board.stats.connected, 5)
            with pytest.raises(protoduino.ProtoduinoError):
                board.ping()  # fails within its bound while nothing is there
            second.start()  # the pty reappears under the same path
            rec.wait(EventKind.RESTORED, timeout=10)
            board.ping()
            assert board.stats.reconnects >= 1
            # a new device (another boot id, or a session it never heard of): outputs lost,
            # re-initialised at their safe values
            assert rec.of(EventKind.REBOOTED) or rec.of(EventKind.SESSION_LOST)
            expect_pin(second, 9, [SAFE_90_US])
            expect_pin(second, 13, [0], digital=True)
    finally:
        first.stop()
        second.stop()


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_call_waits_across_a_short_outage(backend: str, tmp_path: Path) -> None:
    link = tmp_path / "port"
    first = SimBoard(backend, link=link)
    second = SimBoard(backend, trace=tmp_path / "two.jsonl", link=link)
    try:
        first.start()
        with Board.open(str(link), handshake_timeout=5.0) as board:
            servo = board.servo(9)
            first.kill()
            link.unlink(missing_ok=True)
            assert wait_until(lambda: not board.stats.connected, 5)
            restart = threading.Timer(0.5, second.start)
            restart.start()
            servo.write(60)  # held until the new board is up and restored
            restart.join(10)
            expect_pin(second, 9, [SAFE_90_US, us(60)])
    finally:
        first.stop()
        second.stop()


CHILD = textwrap.dedent(
    """
    import sys, time
    import protoduino
    board = protoduino.Board.open(sys.argv[1], failsafe_timeout=float(sys.argv[2]))
    board.servo(9, safe=90).write(10)
    board.digital_output(13, safe=False).on()
    print("ready", flush=True)
    time.sleep(60)
    """
)


@pytest.mark.slow
@pytest.mark.mega
def test_failsafe_when_the_host_process_is_killed(sim: SimBoard) -> None:
    # A 2 s failsafe: the rule is the default 10 s one's (test_sim_e2e's raw host waits
    # out that one), 8 s less of the suite on each board; a host starved of the CPU for
    # 1.5 s (a Ping every 0.5 s) would still not trip it before the kill.
    timeout = 2.0
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, sim.port, str(timeout)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "ready"
        expect_pin(sim, 9, [SAFE_90_US, us(10)])  # the child's command reached the pin
        os.kill(child.pid, signal.SIGKILL)
        child.wait(5)
        killed_trace = sim.trace()

        def failsafe_done() -> bool:
            trace = sim.trace()
            servo = pin_values(trace, 9)[-1:]
            servo_safe = bool(servo) and abs(servo[0] - SAFE_90_US) <= PULSE_TOLERANCE_US
            return servo_safe and pin_values(trace, 13)[-1:] == [0]

        assert wait_until(failsafe_done, 15.0), f"no failsafe in the trace: {sim.trace()}"
        trace = sim.trace()
        last_cmd = killed_trace[-1]["t"]
        fired = trace[-1]["t"]
        # Not before the timeout after the last Ping, which the child sent after the trace's
        # last line before the kill; less a Ping interval (a quarter of it) of slack, as
        # the 1.1 s on the default 10 s was.
        assert fired - last_cmd >= timeout - timeout / 4
    finally:
        if child.poll() is None:
            child.kill()
        child.wait(5)
        if child.stdout is not None:
            child.stdout.close()


@pytest.mark.mega
def test_concurrent_callers(board: Board, sim: SimBoard) -> None:
    # Four servos: thread safety, not servo count, is under test here (the emulated Uno
    # answers slowly with all eight servos running; test_state_dependent_checks uses eight).
    servos = [board.servo(pin) for pin in range(2, 6)]
    led = board.digital_output(13)
    errors: list[BaseException] = []
    finals: dict[int, int] = {}

    def sweep(servo: protoduino.Servo) -> None:
        try:
            for degrees in range(0, 181, 4):
                servo.write(degrees)
            finals[servo.pin] = (servo.pin * 11) % 181
            servo.write(finals[servo.pin])
        except BaseException as error:
            errors.append(error)

    def blink_and_ping() -> None:
        try:
            for i in range(40):
                led.write(bool(i % 2))
                board.ping(bytes([i]))
        except BaseException as error:
            errors.append(error)

    threads = [threading.Thread(target=sweep, args=(s,)) for s in servos]
    threads.append(threading.Thread(target=blink_and_ping))
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert errors == []
    for pin, degrees in finals.items():
        expect_pin(sim, pin, [SAFE_90_US, *(us(d) for d in range(0, 181, 4)), us(degrees)])
    expect_pin(sim, 13, [0, 1] * 20, digital=True)


@pytest.mark.mega
def test_lossy_line_is_repaired(sim: SimBoard) -> None:
    url = f"faulty://{sim.port}?drop=0.002&seed=11"
    with Board.open(url) as board:
        servo = board.servo(9)
        for degrees in range(0, 181, 2):
            servo.write(degrees)
        stats = board.stats
    expect_pin(sim, 9, [SAFE_90_US, *(us(d) for d in range(0, 181, 2))])
    assert stats.retransmits > 0 or stats.seq_lost > 0 or sum(stats.dropped.values()) > 0


@pytest.mark.mega
def test_a_frame_monitor_calling_the_board_is_refused(board: Board, sim: SimBoard) -> None:
    # A monitor runs on the I/O thread; a call from it would wait for an Ack only that
    # thread can read (it stalled the link for 8 s). It is refused at once instead.
    servo = board.servo(9)
    expect_pin(sim, 9, [SAFE_90_US])
    errors: list[BaseException] = []
    armed = threading.Event()

    def meddling(record: FrameRecord) -> None:
        if armed.is_set() and record.direction == "rx":
            armed.clear()
            try:
                servo.write(150)
            except protoduino.ProtoduinoError as error:
                errors.append(error)

    board.add_frame_monitor(meddling)
    armed.set()
    servo.write(30)  # its Ack is the frame the monitor sees
    assert len(errors) == 1 and isinstance(errors[0], protoduino.ReentrantCallError), errors
    servo.write(60)
    expect_pin(sim, 9, [SAFE_90_US, us(30), us(60)])  # the monitor's 150 never went out
    assert board.stats.timeouts == 0 and board.stats.retransmits == 0


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    """Run the command line in another process (bounded: a hung one fails the test)."""
    return subprocess.run(
        [sys.executable, "-m", "protoduino.cli.main", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


@pytest.mark.mega
def test_a_second_opener_is_refused_and_the_first_notices_nothing(
    board: Board, sim: SimBoard
) -> None:
    servo = board.servo(9)
    servo.write(30)
    expect_pin(sim, 9, [SAFE_90_US, us(30)])
    before = board.stats
    # Another process: a one-shot command that would move the servo, and a monitor.
    second = cli("servo", sim.port, "9", "150", "--handshake-timeout", "2")
    monitor = cli("monitor", sim.port, "--duration", "1")
    for other in (second, monitor):
        assert other.returncode == 1, other
        assert "in use" in other.stderr, other.stderr
    servo.write(60)
    # The pin took the first session's values only: never 150 degrees, never a reset.
    expect_pin(sim, 9, [SAFE_90_US, us(30), us(60)])
    after = board.stats
    assert (after.handshakes, after.reboots, after.reconnects, after.timeouts) == (
        before.handshakes,
        before.reboots,
        before.reconnects,
        0,
    )


@pytest.mark.parametrize("window", [4, 8, 16])
def test_clean_line_never_retransmits_at_any_window(sim: SimBoard, window: int) -> None:
    """Flow control by bytes: a burst at any window fits the device's receive buffer.

    Judged by the link counters: every call acknowledged at its first transmission, no
    receive overflow reported by the device, no frame dropped on either side. GetInfo is
    the hard case: its Ack is seven times its command, so while Acks queue up behind the
    line, commands pile up in the device's receive buffer; a window counted in commands
    only overflows it there (an emulated Uno at window 16 did).
    """
    with Board.open(sim.port, window=window, ping=False) as board:
        assert board.info.rx_buffer > 0
        servo = board.servo(9)
        info = ArduinoIn()
        info.get_info.SetInParent()
        # All at once, so the window fills: servo writes, 64-byte Pings, and GetInfo (a
        # 14-byte command whose Ack, DeviceInfo, takes 100 bytes) from as many threads.
        futures: list[Future[Any]] = [servo.submit((i * 7) % 181) for i in range(60)]
        futures += [board.submit_ping(bytes([i + 1]) * 64) for i in range(12)]
        with ThreadPoolExecutor(max_workers=24) as pool:
            infos = [pool.submit(board.request, info) for _ in range(24)]
            for future in [*futures, *infos]:
                future.result(timeout=60)
        calls = futures + infos
        servo.write(90)
        stats = board.stats
        assert stats.retransmits == 0, stats
        assert stats.timeouts == 0 and stats.device_rx_overflows == 0, stats
        assert not stats.dropped, stats
        assert stats.acks >= len(calls)


class _SocketBridge:
    """socket://127.0.0.1:PORT in front of the board's pty, whose connection can be dropped.

    The board keeps running (its pty stays open): a drop is a reconnect, not a reboot.
    """

    def __init__(self, pty: str) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.url = f"socket://127.0.0.1:{self.server.getsockname()[1]}"
        self.pty = serial.Serial(pty, baudrate=115200, timeout=0.01)
        self.client: socket.socket | None = None
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="socket-bridge", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        self.server.settimeout(0.05)
        while not self.stop.is_set():
            if self.client is None:
                try:
                    self.client, _ = self.server.accept()
                    self.client.settimeout(0.01)
                except TimeoutError:
                    continue
            client = self.client
            data = self.pty.read(4096)
            try:
                if data:
                    client.sendall(data)
                incoming = client.recv(4096)
                if incoming:
                    self.pty.write(incoming)
            except TimeoutError:
                pass
            except OSError:
                self.client = None

    def drop(self) -> None:
        client, self.client = self.client, None
        if client is not None:
            client.close()

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)
        self.drop()
        self.server.close()
        self.pty.close()


@pytest.mark.mega
def test_a_socket_drop_is_a_reconnect_not_a_reboot(sim: SimBoard) -> None:
    """Same boot id, session resumed: nothing is restored and nothing twitches at the pin
    (before sessions a reopened port counted as a reboot: 1472 -> 2369 us within 0.6 ms)."""
    bridge = _SocketBridge(sim.port)
    try:
        with Board.open(bridge.url, handshake_timeout=3.0) as board:
            rec = Recorder(board)
            board.servo(9).write(150)
            expect_pin(sim, 9, [SAFE_90_US, us(150)])
            lines = len(sim.trace())
            bridge.drop()
            rec.wait(EventKind.CONNECTED)
            board.ping()
            assert board.stats.reconnects >= 1
            assert board.stats.reboots == 0 and board.stats.sessions_lost == 0
            assert not rec.of(EventKind.RESTORED) and not rec.of(EventKind.REBOOTED)
            assert rec.of(EventKind.CONNECTED)[0].details["lost"] is False
            board.servo(9).write(150)  # the same Init again and the same value: no change
            # A change would be in the trace within two servo frames (the emulated Uno
            # measures a width over two); this only bounds how long we look for one.
            time.sleep(0.1)
            assert sim.trace()[lines:] == []  # the pin never moved
    finally:
        bridge.close()


@pytest.mark.mega
def test_detach_safe_state_and_release_at_the_pins(board: Board, sim: SimBoard) -> None:
    limp = board.servo(9, safe="detach")  # no pulses until commanded
    assert limp.value == 0
    limp.write(30)
    # At the pins before the next step: on a fast line (docs/protocol.md 5, *Line rate*)
    # the Stop would come before the first pulse.
    expect_pin(sim, 9, [0, us(30)])
    board.stop()  # its safe state: pulses stop
    expect_pin(sim, 9, [0, us(30), 0])
    assert limp.value == 0
    led = board.digital_output(13)
    led.on()
    expect_pin(sim, 13, [0, 1], digital=True)
    led.release()  # an input: the trace says 0
    expect_pin(sim, 13, [0, 1, 0], digital=True)
    assert led.value is None
    since = len(sim.trace())
    arm = board.servo(13)  # the released pin takes another mode
    expect_pin(sim, 13, [SAFE_90_US], since=since)
    arm.release()
    expect_pin(sim, 13, [SAFE_90_US, 0], since=since)
    with pytest.raises(protoduino.CommandRejectedError) as info:
        arm.write(10)  # released: the device refuses it
    assert info.value.status == Status.STATUS_NOT_INITIALISED and info.value.sent
    board.release_all()
    since = len(sim.trace())
    board.servo(9).write(60)  # a free slot and pin again
    expect_pin(sim, 9, [SAFE_90_US, us(60)], since=since)


@pytest.mark.mega
def test_a_call_in_flight_at_a_reboot_fails_and_never_reaches_the_new_boot(sim: SimBoard) -> None:
    """Defect 3 at the pins: the command that (say) browned the board out runs on the old
    boot only; the call fails with DeviceRebootedError, the servo comes back at its safe
    value and stays there (it used to be sent again after every reboot until its deadline)."""
    from protoduino_dev import faults

    name = f"reboot-{os.getpid()}-{id(sim)}"
    url = f"faulty://{sim.port}?dir=rx&drop=1&paused=1&name={name}"
    with Board.open(url, ping=False, ack_timeout=1.0) as b:  # room for the reboot
        rec = Recorder(b)
        servo = b.servo(9)
        expect_pin(sim, 9, [SAFE_90_US])
        line = faults.line(name)
        assert line is not None
        line.resume()  # from here every byte from the device is lost: the Ack too
        call = servo.submit(150)
        expect_pin(sim, 9, [SAFE_90_US, us(150)])  # it ran on this boot
        sim.reboot()
        line.heal()
        with pytest.raises(protoduino.DeviceRebootedError):
            call.result(timeout=10)
        rec.wait(EventKind.RESTORED)
        b.ping()
        expect_pin(sim, 9, [SAFE_90_US, us(150), 0, SAFE_90_US])  # never 150 again
        assert b.stats.reboots == 1

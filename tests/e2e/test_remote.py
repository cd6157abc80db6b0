"""A board over the network: ``rfc2217://`` through a real RFC 2217 server (ser2net).

The test starts ser2net itself, on loopback only and a free port, in front of
the simulated board's pseudo-terminal: what a Raspberry Pi does in front of
its Arduino (docs/remote.md). A pseudo-terminal has no modem lines, so ser2net
never acknowledges pyserial's modem-control requests there: the URL carries
pyserial's documented ``?ign_set_control`` option.
"""

from __future__ import annotations

import os
import queue
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from protoduino import Board, TransportError
from protoduino.cli.main import main
from protoduino.events import Event, EventKind
from protoduino.simboard import SimBoard
from simfixtures import PULSE_TOLERANCE_US, wait_for_pin

# pyserial 3.5's rfc2217 reader thread uses the old threading setters.
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning:serial.rfc2217")

BOUND = 20.0  # seconds: only how long a failing test waits


def _listening(port: int) -> bool:
    """Whether something listens on 127.0.0.1:port (read from the kernel, not by connecting:
    a probe connection would be a client to ser2net)."""
    want = f"0100007F:{port:04X}"
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        fields = line.split()
        if fields[1] == want and fields[3] == "0A":  # LISTEN
            return True
    return False


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Ser2net:
    """ser2net serving one device as RFC 2217 on 127.0.0.1:port, in the foreground."""

    def __init__(self, device: str, workdir: Path) -> None:
        self.port = _free_port()
        self.workdir = workdir
        self.config = workdir / "ser2net.yaml"
        # `local`: ignore the modem lines (a pty has none); loopback only.
        self.config.write_text(
            "%YAML 1.1\n---\n"
            "connection: &board\n"
            f"  accepter: telnet(rfc2217),tcp,127.0.0.1,{self.port}\n"
            f"  connector: serialdev,{os.path.realpath(device)},115200n81,local\n"
            "  options:\n"
            "    kickolduser: true\n"
        )
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"rfc2217://127.0.0.1:{self.port}?ign_set_control"

    def start(self) -> None:
        self.proc = subprocess.Popen(
            # -n foreground, -u no UUCP lock files, its own pid file and config only
            ["ser2net", "-n", "-u", "-P", str(self.workdir / "pid"), "-c", str(self.config)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + BOUND
        while not _listening(self.port):
            assert self.proc.poll() is None, "ser2net exited"
            assert time.monotonic() < deadline, "ser2net did not listen"
            time.sleep(0.02)

    def stop(self) -> None:
        proc, self.proc = self.proc, None
        if proc is not None:
            proc.terminate()
            try:
                proc.wait(5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@pytest.fixture
def server(sim_board: SimBoard, tmp_path: Path) -> Iterator[Ser2net]:
    if shutil.which("ser2net") is None:
        pytest.skip("ser2net is not installed (tools/dev.sh setup installs it)")
    s = Ser2net(sim_board.port, tmp_path)
    s.start()
    try:
        yield s
    finally:
        s.stop()


def _wait_event(events: queue.Queue[Event], kind: EventKind) -> Event:
    deadline = time.monotonic() + BOUND
    while (left := deadline - time.monotonic()) > 0:
        try:
            event = events.get(timeout=left)
        except queue.Empty:
            break
        if event.kind is kind:
            return event
    raise AssertionError(f"no {kind.value} event")


def test_commands_events_and_reconnect_through_ser2net(
    sim_board: SimBoard, server: Ser2net
) -> None:
    events: queue.Queue[Event] = queue.Queue()
    with Board.open(server.url) as board:
        board.on_event(events.put)
        assert board.info.num_pins == 20
        servo = board.servo(9, safe=90)
        servo.write_us(1000)
        wait_for_pin(sim_board, 9, lambda v: bool(v) and abs(v[-1] - 1000) <= PULSE_TOLERANCE_US)
        led = board.digital_output(13)
        led.on()
        wait_for_pin(sim_board, 13, lambda v: v[-1:] == [1])

        # An event the device sends: the emergency stop's failsafe report.
        board.stop()
        failsafe = _wait_event(events, EventKind.FAILSAFE)
        assert failsafe.details["active"] and failsafe.details["cause"] == "stop"
        wait_for_pin(sim_board, 13, lambda v: v[-1:] == [0])

        # The server goes away and comes back: the link reconnects by itself.
        server.stop()
        _wait_event(events, EventKind.DISCONNECTED)
        server.start()
        _wait_event(events, EventKind.CONNECTED)
        led.on()  # a command after the reconnect reaches the pin
        wait_for_pin(sim_board, 13, lambda v: v[-1:] == [1])
        assert board.stats.reconnects >= 1 and board.ping() > 0


def test_the_cli_reaches_a_board_through_ser2net(
    server: Ser2net, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["info", server.url]) == 0
    out = capsys.readouterr().out
    assert "num_pins          20" in out and "handshakes        1" in out


def test_a_server_that_never_acknowledges_modem_control_is_a_transport_error(
    server: Ser2net,
) -> None:
    with pytest.raises(TransportError, match=r"add \?ign_set_control"):
        Board.open(server.url.removesuffix("?ign_set_control"))


def test_a_stalled_server_during_a_re_handshake_is_a_reconnect(
    sim_board: SimBoard, server: Ser2net
) -> None:
    """Issue 32: ser2net stopped (SIGSTOP) long enough for the watchdog's re-handshake to
    change the line rate on the stalled port. pyserial's rfc2217 then raises (the server
    does not acknowledge the change): that is a lost port, reopened once the server is
    back, not an I/O thread that dies and leaves every later call to time out."""
    events: queue.Queue[Event] = queue.Queue()
    with Board.open(server.url) as board:
        board.on_event(events.put)
        transport: Any = board._link.transport
        assert board.baudrate != 115_200  # the agreed rate: a re-handshake cycles rates
        led = board.digital_output(13, safe=False)
        led.on()
        wait_for_pin(sim_board, 13, lambda v: v[-1:] == [1])
        assert server.proc is not None
        server.proc.send_signal(signal.SIGSTOP)
        try:
            _wait_event(events, EventKind.DISCONNECTED)  # the watchdog (pings unanswered)
            # The re-handshake's first rate change on the stalled port has failed.
            deadline = time.monotonic() + BOUND
            while transport.last_error is None:
                assert time.monotonic() < deadline, "no rate change failed"
                time.sleep(0.02)
        finally:
            server.proc.send_signal(signal.SIGCONT)
        assert "crashed" not in str(transport.last_error), transport.last_error
        _wait_event(events, EventKind.CONNECTED)
        led.off()
        wait_for_pin(sim_board, 13, lambda v: v[-1:] == [0])
        assert board.ping() > 0

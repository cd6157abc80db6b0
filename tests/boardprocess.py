"""A board process a test starts itself (the avrsim runner, ``protoduino sim``): its port, its stop.

Every simulated board prints its port as the first line of stdout and exits
cleanly on SIGTERM (docs/architecture.md, contracts); the fixtures of
``simfixtures.py`` go through ``protoduino.simboard.SimBoard``, these are for
the tests that need the process's own command line (extra runner options, an
installed venv, a bootloader alone in the flash). Also the one check of which
tools a test needs.
"""

from __future__ import annotations

import json
import select
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from protoduino import simboard

#: simavr's development headers: the runner (tools/avrsim) is built against them.
SIMAVR_HEADER = Path("/usr/include/simavr/sim_avr.h")


def missing_tool(*tools: str, simavr: bool = False) -> str | None:
    """The first of ``tools`` not on PATH, then libsimavr-dev if ``simavr`` and its headers
    are missing; None when everything is there (a test skips naming what is not)."""
    for tool in tools:
        if shutil.which(tool) is None:
            return tool
    if simavr and not SIMAVR_HEADER.exists():
        return "libsimavr-dev"
    return None


class BoardProcess:
    """A started board process and the port it printed.

    ``startup`` bounds only how long a board that prints nothing is waited for;
    ``popen`` goes to :class:`subprocess.Popen` (cwd, env, stderr: DEVNULL unless given).
    The board is owned by the test process (``protoduino.simboard.owned``: it ends when
    the test process does, however it ends); ``owned=False`` for a command that is not a
    board program itself.
    """

    def __init__(
        self,
        cmd: list[str],
        *,
        startup: float = 10.0,
        what: str = "the runner",
        owned: bool = True,
        **popen: Any,
    ) -> None:
        popen.setdefault("stderr", subprocess.DEVNULL)
        if owned:
            cmd = simboard.owned(cmd)
        stdin = subprocess.PIPE if owned else subprocess.DEVNULL
        self.proc = subprocess.Popen(cmd, stdin=stdin, stdout=subprocess.PIPE, **popen)
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], startup)
        if not ready:
            self.stop(strict=False)
            raise AssertionError(f"{what} printed no port")
        self.port = self.proc.stdout.readline().decode().rstrip("\n")
        if not self.port:
            self.stop(strict=False)
            raise AssertionError(f"{what} exited before printing its port")

    def stop(
        self, sig: int = signal.SIGTERM, *, timeout: float = 10.0, strict: bool = True
    ) -> int | None:
        """Signal the process (if it still runs) and reap it; its exit status.

        A process that outlives ``timeout`` is killed; ``strict`` then raises
        ``subprocess.TimeoutExpired``, as a board that does not exit on its signal
        is a defect, and returns None otherwise.
        """
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            if strict:
                raise
            return None
        finally:
            for stream in (self.proc.stdin, self.proc.stdout, self.proc.stderr):
                if stream is not None:
                    stream.close()


def detached_sim_info(pid_file: Path, *sim_args: str) -> dict[str, Any]:
    """``protoduino sim *sim_args --detach`` (its pid in ``pid_file``), then what
    ``protoduino info --json --new-session`` reads on the port it printed (its "info"
    object); the board is stopped with ``protoduino sim --stop`` after, whatever happened.
    Each command's own failure fails the test with its stderr."""
    cli = [sys.executable, "-m", "protoduino.cli.main"]
    started = subprocess.run(
        [*cli, "sim", *sim_args, "--detach", "--pid-file", str(pid_file)],
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
        stated: dict[str, Any] = json.loads(info.stdout)["info"]
        return stated
    finally:
        subprocess.run([*cli, "sim", "--stop", str(pid_file)], check=False, timeout=60)

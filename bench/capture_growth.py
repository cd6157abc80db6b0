"""How fast a capture file grows: ``python -m bench.capture_growth [--backend avr] [--window 4]``.

Opens a Board with a capture on a simulated board, writes a servo as fast as the link allows
for ``--seconds`` (``--window 1``: each write waits for its Ack; more: that many ``submit_us``
in flight), and reads the file's size before and after. Also the idle growth (the automatic
Ping and the counters line only). The figures in docs/api.md ("How fast a capture grows") come
from this script; the bytes per command are checked by tests/e2e/test_capture_loss.py.
"""

from __future__ import annotations

import argparse
import collections
import tempfile
import time
from concurrent.futures import Future
from pathlib import Path

from protoduino import Board
from protoduino.simboard import SimBoard


def measure(backend: str, seconds: float, window: int) -> dict[str, float]:
    with tempfile.TemporaryDirectory(prefix="capture-growth-") as tmp:
        cap = Path(tmp) / "c.jsonl"
        with SimBoard(backend) as sim:
            port = sim.start()
            with Board.open(port, capture=cap):
                start, t0 = cap.stat().st_size, time.monotonic()
                time.sleep(seconds)
                idle = (cap.stat().st_size - start) / (time.monotonic() - t0)
            with Board.open(port, capture=cap) as board:
                servo = board.servo(9)
                start, commands = cap.stat().st_size, board.stats.commands
                pending: collections.deque[Future[None]] = collections.deque()
                n = 0
                t0 = time.monotonic()
                while time.monotonic() - t0 < seconds:
                    if window == 1:
                        servo.write_us(1000 + n % 1000)
                    else:
                        if len(pending) >= window:
                            pending.popleft().result()
                        pending.append(servo.submit_us(1000 + n % 1000))
                    n += 1
                for future in pending:
                    future.result()
                elapsed = time.monotonic() - t0
                grown = cap.stat().st_size - start
                commands = board.stats.commands - commands
    return {
        "idle_bytes_per_s": idle,
        "commands_per_s": commands / elapsed,
        "bytes_per_command": grown / commands,
        "mb_per_hour": grown / elapsed * 3600 / 1e6,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backend", default="native", choices=["native", "avr"])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--window", type=int, default=1)
    args = parser.parse_args()
    r = measure(args.backend, args.seconds, args.window)
    print(
        f"{args.backend}, window {args.window}: {r['commands_per_s']:.0f} commands/s, "
        f"{r['bytes_per_command']:.1f} B/command, {r['mb_per_hour']:.0f} MB/hour; idle "
        f"{r['idle_bytes_per_s']:.0f} B/s = {r['idle_bytes_per_s'] * 3600 / 1e6:.1f} MB/hour"
    )


if __name__ == "__main__":
    main()

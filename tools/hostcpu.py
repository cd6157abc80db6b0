"""Host CPU per acked command, per call kind (issue 23), as bench part 9 measures it.

``time.process_time`` around each call (every thread of the process: the caller's, the
I/O thread's, the event thread's), against the simulated board (``native``) or the emulated
Uno (``avr``), with the call pattern of bench/race.py: digital writes one at a time after a
random pause of up to 2 ms, servo writes after up to 20 ms, then flat out at window 4
(digital submits, and poses of six digital outputs), whose CPU is the run's over its calls.

A call's round trip (wall clock, the blocking call's own) is given beside its CPU.
Each thread's own CPU over each phase comes from /proc/self/task/TID/schedstat (ns), to
say where the time goes (caller, I/O thread, event thread).

    .venv/bin/python tools/hostcpu.py [native|avr] [--samples N] [--commands N]

A measurement, not a test: the figures depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import random
import statistics
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, wait
from pathlib import Path

from protoduino import Board
from protoduino.simboard import SimBoard

DIGITAL_PIN = 13
SERVO_PIN = 9
POSE_PINS = (2, 4, 7, 8, 12, 13)
WINDOW = 4


def thread_cpu() -> dict[str, int]:
    """CPU ns so far of each thread of this process, by name."""
    names = {t.native_id: t.name for t in threading.enumerate()}
    out: dict[str, int] = {}
    for task in Path("/proc/self/task").iterdir():
        try:
            ns = int((task / "schedstat").read_text().split()[0])
        except (OSError, ValueError):
            continue
        name = names.get(int(task.name), f"tid{task.name}")
        name = name.split("[")[0]
        out[name] = out.get(name, 0) + ns
    return out


def per_thread(before: dict[str, int], after: dict[str, int], calls: int) -> str:
    parts = []
    for name in sorted(after):
        d = after[name] - before.get(name, 0)
        if d > calls * 1000:  # over 1 us per call
            parts.append(f"{name} {d / calls / 1000:.0f}")
    return ", ".join(parts)


def timed_singles(
    label: str, n: int, gap: float, call: Callable[[int], object], rng: random.Random
) -> None:
    cpu: list[float] = []
    wall: list[float] = []
    t0 = thread_cpu()
    for i in range(n):
        time.sleep(rng.uniform(0.0, gap))
        c0 = time.process_time()
        w0 = time.perf_counter()
        call(i)
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    t1 = thread_cpu()
    cpu.sort()
    print(
        f"{label:18s} median {statistics.median(cpu) * 1e6:6.0f} us  "
        f"p10 {cpu[len(cpu) // 10] * 1e6:5.0f}  p90 {cpu[len(cpu) * 9 // 10] * 1e6:5.0f}  "
        f"(round trip median {statistics.median(wall) * 1e6:.0f} us; "
        f"per thread over the phase, sleeps included, us/call: {per_thread(t0, t1, n)})"
    )


def flat_out(label: str, n: int, issue: Callable[[int], Future[None]]) -> None:
    futures: list[Future[None]] = []
    t0 = thread_cpu()
    c0 = time.process_time()
    for i in range(n):
        futures.append(issue(i))
    for f in wait(futures).done:
        f.result()
    cpu = time.process_time() - c0
    t1 = thread_cpu()
    print(
        f"{label:18s} {cpu / n * 1e6:6.0f} us/call over {n} calls  "
        f"(per thread, us/call: {per_thread(t0, t1, n)})"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("backend", nargs="?", default="native", choices=("native", "avr"))
    ap.add_argument("--samples", type=int, default=400)
    ap.add_argument("--commands", type=int, default=400)
    ap.add_argument("--baudrate", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rng = random.Random(args.seed)
    with SimBoard(args.backend) as sim:
        port = sim.start()
        with Board.open(port, window=WINDOW, baudrate=args.baudrate) as board:
            led = board.digital_output(DIGITAL_PIN)
            servo = board.servo(SERVO_PIN)
            print(f"{args.backend} board at {board.baudrate} baud, window {WINDOW}")
            timed_singles(
                "digital write", args.samples, 0.002, lambda i: led.write(i % 2 == 0), rng
            )
            timed_singles(
                "servo write",
                max(5, args.samples // 4),
                0.020,
                lambda i: servo.write((37 * i) % 171 + 5),
                rng,
            )
            led.write(False)
            flat_out("digital flat out", args.commands, lambda i: led.submit(i % 2 == 0))
            outs = [led, *(board.digital_output(p) for p in POSE_PINS if p != DIGITAL_PIN)]
            poses = max(20, args.commands // 3) // 2 * 2
            flat_out(
                "pose (6) flat out",
                poses,
                lambda i: board.submit_pose(dict.fromkeys(outs, i % 2 == 0)),
            )


if __name__ == "__main__":
    main()

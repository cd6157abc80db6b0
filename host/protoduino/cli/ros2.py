"""``protoduino ros2 PORT --config robot.yaml``: run the ROS 2 bridge until Ctrl-C or SIGTERM.

The configuration is read and checked before the port is opened (a bad one is
a usage error, exit status 2). The bridge runs in the foreground; SIGINT and
SIGTERM end it cleanly (every output driven safe by the device's Stop, then the
board closed); the exit status is then 130 after Ctrl-C, as every command's, and 0 after
SIGTERM. ``--sim`` instead of PORT starts a simulated board owned by this
process (stopped after the bridge) and, without ``--config``, bridges the
example robot of docs/ros2.md: the README's one command; its ``--control PATH`` drives that
board's inputs (a bumper pressed), as ``protoduino sim --control`` does. docs/ros2.md has the
details.
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path
from types import FrameType

from ..errors import ProtoduinoError
from . import argtypes
from .options import (
    add_port,
    add_sim,
    error,
    load_url_handlers,
    session_of,
    sim_check,
    start_afresh,
)

HELP = "run the ROS 2 bridge: the board's pins as ROS 2 topics on DDS (see docs/ros2.md)"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser, required=False)
    parser.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="robot.yaml: the namespace and which pins are which topics (required with a "
        "PORT; with --sim the default is the example robot of docs/ros2.md)",
    )
    add_sim(parser, what="and bridge it; it stops with the bridge")
    parser.add_argument(
        "--control",
        type=Path,
        metavar="PATH",
        help="with --sim: a Unix socket driving the board's inputs, as protoduino sim's "
        '(one JSON object per line, e.g. {"pin": 7, "level": 0})',
    )
    parser.add_argument(
        "--domain-id",
        type=argtypes.integer(0, 232, name="domain id"),
        metavar="N",
        help="DDS domain (default: the config's domain_id, else $ROS_DOMAIN_ID, else 0)",
    )


def check(args: argparse.Namespace) -> str | None:
    """The configuration is read here: a bad one is refused before any port opens."""
    from ..ros2.config import load_config
    from ..ros2.example import example_config

    if (problem := sim_check(args, "control")) is not None:
        return problem
    if args.config is None and args.sim is None:
        return "--config FILE is required with a PORT (docs/ros2.md shows one)"
    try:
        config = example_config() if args.config is None else load_config(args.config)
    except ProtoduinoError as exc:
        return str(exc)
    if args.domain_id is not None:
        from dataclasses import replace

        config = replace(config, domain_id=args.domain_id)
    args.ros2_config = config
    return None


def run(args: argparse.Namespace) -> int:
    if args.sim is None:
        return _bridge(args)
    from ..simboard import SimBoard

    try:
        with SimBoard(args.sim, trace=args.trace, control=args.control) as sim:
            args.port = sim.start()
            print(f"protoduino ros2: simulated board ({args.sim}) on {args.port}", flush=True)
            return _bridge(args)
    except ProtoduinoError as exc:
        return error("ros2", exc)


def _bridge(args: argparse.Namespace) -> int:
    from .. import ros2

    try:
        bridge_type = ros2.Bridge
        load_url_handlers(args.port)
        bridge = bridge_type(
            args.port,
            args.ros2_config,
            board_options={
                "baudrate": args.baud,
                "ack_timeout": args.ack_timeout,
                "handshake_timeout": args.handshake_timeout,
                "capture": args.capture,
                "session": session_of(args),
            },
            on_open=lambda board: start_afresh(board, args),
        )
    except ProtoduinoError as exc:
        return error("ros2", exc)

    interrupted = False

    def stop(signum: int, frame: FrameType | None) -> None:
        nonlocal interrupted
        interrupted = interrupted or signum == signal.SIGINT
        bridge.stop()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        with bridge:
            topics = bridge.topics()
            print(
                f"protoduino ros2: {args.port} on DDS domain "
                f"{bridge.config.resolved_domain()}, {len(topics)} topics:",
                flush=True,
            )
            for name, kind in sorted(topics.items()):
                print(f"  {name}  {kind}", flush=True)
            services = bridge.services()
            if services:  # docs/ros2.md, Services: its rclpy node says when they are up
                print(f"protoduino ros2: {len(services)} services:", flush=True)
                for name, kind in sorted(services.items()):
                    print(f"  {name}  {kind}", flush=True)
            bridge.run()
    except ProtoduinoError as exc:
        return error("ros2", exc)
    print("protoduino ros2: stopped", file=sys.stderr)
    # Stopped the same way either way (the outputs safe); Ctrl-C says so as every command
    # does (130), while a service manager's SIGTERM is a normal end.
    return 130 if interrupted else 0

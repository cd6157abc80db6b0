"""``protoduino gen robot.proto --out DIR``: a user service's code for both sides.

With a .proto it runs :mod:`protoduino.servicegen` (the ``gen`` extra's tools:
``pip install 'protoduino[gen]'``; docs/services.md). Without one it is the
development command that regenerates protoduino's own schema code in a source
checkout: the development tools declare that generator as an entry point
(:data:`protoduino.plugins.GENERATORS`); the runtime never imports them by name.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .. import plugins

HELP = (
    "generate a user service's C and typed Python code from your .proto (docs/services.md); "
    "without one, protoduino's own (development)"
)


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "proto",
        nargs="?",
        type=Path,
        default=None,
        help="your service's .proto (its nanopb bounds in a .options file beside it)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="folder to write into (with a .proto: default the current folder; without: "
        "below this folder instead of the repository, for comparison)",
    )


def run(args: argparse.Namespace) -> int:
    if args.proto is None:
        return _builtin(args)
    from ..errors import ServiceGenError
    from ..servicegen import generate

    try:
        result = generate(args.proto, args.out if args.out is not None else Path.cwd())
    except ServiceGenError as error:
        print(f"protoduino gen: {error}", file=sys.stderr)
        return 1
    for path in result.files:
        print(path)
    service = result.service
    print(f"{service.name}: {len(service.methods)} rpcs, fingerprint 0x{service.fingerprint:08X}")
    if not service.errors:  # the rule, where a user would look for their codes' names
        print(
            f"{service.name}: no error enum {service.name}Error (<Service>Error): a handler's "
            "codes arrive as protoduino.UserError"
        )
    return 0


def _builtin(args: argparse.Namespace) -> int:
    """protoduino's own schema: the development tools' generator."""
    entry = plugins.find(plugins.GENERATORS, "schema")
    dev_gen = None
    if entry is not None:
        try:
            dev_gen = entry.load()
        except ImportError:  # declared by metadata left behind, its package gone
            dev_gen = None
    if dev_gen is None:
        print(
            "protoduino gen: without a .proto, `protoduino gen` is a development command: it "
            "works in a source checkout with the development tools installed (git clone, then "
            "./tools/dev.sh setup, which installs the protoduino_dev package from dev/); "
            "for your own service: protoduino gen robot.proto --out DIR",
            file=sys.stderr,
        )
        return 2
    status: int = dev_gen.run(args)
    return status

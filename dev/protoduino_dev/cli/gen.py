"""``protoduino gen``: regenerate the Python and nanopb code from proto/."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "generate the Python and nanopb C code and SCHEMA_ID from proto/protoduino.proto"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write below this folder instead of the repository (for comparison)",
    )


def run(args: argparse.Namespace) -> int:
    from ..codegen import CodegenError, generate

    try:
        result = generate(args.out)
    except (CodegenError, ImportError) as error:
        print(f"protoduino gen: {error}", file=sys.stderr)
        return 1
    for path in result.files:
        print(path)
    print(f"SCHEMA_ID = 0x{result.schema_id:08X}")
    return 0

"""The board's options are declared once (protoduino.boardoptions) and taken by every opener."""

from __future__ import annotations

import argparse
import inspect

import pytest
from protoduino import Board, aio
from protoduino.boardoptions import DEFAULTS, BoardOptions, resolved
from protoduino.cli.options import board_options
from protoduino.errors import ArgumentTypeError


def test_every_declared_option_has_its_one_default() -> None:
    assert set(DEFAULTS) == set(BoardOptions.__optional_keys__)
    assert not BoardOptions.__required_keys__


def test_the_openers_take_the_declaration_itself() -> None:
    # Each is (url, **options): no opener re-spells the keywords. (The constructor also
    # takes what the board runs on, which is no option: protoduino.wiring.)
    for opener in (Board.__init__, Board.open, aio.open, aio.Board.open):
        params = list(inspect.signature(opener).parameters.values())
        assert params[-1].kind is inspect.Parameter.VAR_KEYWORD, opener
        assert "BoardOptions" in str(params[-1].annotation), opener
        named = [p.name for p in params[:-1] if p.name not in ("self", "cls")]
        assert named == (["url", "wiring"] if opener is Board.__init__ else ["url"]), opener


def test_given_options_override_the_defaults_and_unknown_ones_are_refused() -> None:
    merged = resolved({"window": 8})
    assert merged["window"] == 8 and merged["baudrate"] == DEFAULTS["baudrate"]
    with pytest.raises(ArgumentTypeError, match="windw"):
        resolved({"windw": 8})  # type: ignore[typeddict-unknown-key]


def test_an_unknown_option_fails_before_any_port_is_opened() -> None:
    with pytest.raises(ArgumentTypeError, match="baud"):
        Board.open("/nonexistent/port", baud=9600)  # type: ignore[call-arg]


def test_the_command_line_gives_declared_options() -> None:
    args = argparse.Namespace(
        baud=57600,
        ack_timeout=0.2,
        handshake_timeout=3.0,
        capture=None,
        port="/dev/ttyACM7",
    )
    options = board_options(args, ping=False)
    assert set(options) <= set(DEFAULTS)
    assert options["baudrate"] == 57600 and options["ping"] is False
    assert resolved(options)["ack_timeout"] == 0.2
    assert options["session"] is not None  # the port's one command-line session

"""User calls are executed exactly once on a faulty line (docs/protocol.md section 7).

The blinker example's firmware behind ``faulty://`` with bit errors on what the host
receives: Acks are lost, the board retransmits with the same message id, and the device's
dedupe window answers the repeats instead of running them. The blinker counts the level
changes its handlers make (a start drives the pin high, a stop low; the period is long
enough that its poll hook never toggles within the test), so after N starts and stops its
count is exactly 2N whatever was lost, and every lost reply was reported as such.
"""

from __future__ import annotations

from pathlib import Path

import protoduino
import protoduino_dev  # noqa: F401  (registers faulty://)
import pytest
from protoduino.simboard import SimBoard
from userbuilds import client, need, program

PAIRS = 40


@pytest.mark.parametrize("backend", ["native", "avr"])
def test_user_calls_run_exactly_once_through_lost_acks(
    backend: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    need(backend)
    mod = client("blinker", monkeypatch)
    with SimBoard(backend, firmware=program("blinker", backend)) as sim:
        sim.start()
        url = f"faulty://{sim.port}?ber=4e-4&dir=rx&seed=11"
        with protoduino.Board.open(url, max_retries=6) as board:
            blinker = mod.Blinker(board)
            lost = 0
            for _ in range(PAIRS):
                for start in (True, False):
                    try:
                        if start:
                            blinker.start_blink(mod.pb.Blink(pin=13, period_ms=60000))
                        else:
                            blinker.stop_blink(mod.pb.Empty())
                    except protoduino.UserReplyLostError:
                        lost += 1  # it ran once: the window answered the repeat
            count = blinker.count(mod.pb.Empty()).count
            stats = board.stats
    assert stats.retransmits >= 1, "the line lost nothing: the test proved nothing"
    assert count == 2 * PAIRS, (count, lost, stats)

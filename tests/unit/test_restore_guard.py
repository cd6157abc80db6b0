"""rpc: a call in flight when the device is found to have restarted unseen (its STATUS_
NOT_INITIALISED for a configured output, ``Rpc._session_lost``) is never executed twice.

It may have run on the restarted device, its id in the device's dedupe window; the restore's
messages go out first, and past DEDUPE_WINDOW - 1 of them a retransmission of that id would
run again. As after a reboot (docs/api.md, *Sessions and the restore policy*), it fails with
DeviceRebootedError and is not sent again.

Against the pty fake (PtyDevice), whose dedupe window is the firmware's
(:class:`protoduino.testing.DedupeWindow`): what the device executes is counted per id,
dedupe hits excluded, so a retransmission that fell out of its window shows as a second
execution.
"""

from __future__ import annotations

import collections
from typing import Any

import pytest
from protoduino import Board
from protoduino.commands import command
from protoduino.constants import DEDUPE_WINDOW
from protoduino.errors import DeviceRebootedError
from protoduino.testing import PtyDevice

#: Outputs configured before the unseen restart: the restore sends a ConfigureFailsafe and
#: one Init each, more than the DEDUPE_WINDOW - 1 ids the guard lets go out after a call.
PINS = [p for p in range(2, 19) if p != 9]
X_PIN = 19  # configured while the device has already restarted


def test_a_call_in_flight_when_the_session_is_lost_is_executed_once(fake: PtyDevice) -> None:
    executed: collections.Counter[int] = collections.Counter()
    dropped: list[int] = []

    def handler(msg: Any) -> Any:
        mid, kind = msg.message_id, msg.WhichOneof("data")
        if not command(kind).idempotent and not fake.dedupe.holds(mid):
            executed[mid] += 1
        replies = fake.default_reply(msg)
        if kind == "digital_init" and msg.digital_init.pin == X_PIN and not dropped:
            dropped.append(mid)  # X ran on the restarted device; its Ack is lost
            return []
        return replies

    with Board.open(fake.port, ack_timeout=0.2, ping=False) as board:
        for pin in PINS:
            board.digital_output(pin)
        servo = board.servo(9)
        servo.write(45)
        assert len(PINS) + 2 > DEDUPE_WINDOW - 1  # the restore alone overflows the guard
        fake.handler = handler
        fake.forget()  # a reset whose BOOT was lost: state gone, link still up
        x = board.submit_digital_output(X_PIN)
        servo.write(120)  # refused NOT_INITIALISED while X awaits its Ack: the restore runs
        with pytest.raises(DeviceRebootedError):
            x.result(timeout=30)
        assert board.stats.reboots == 1
        board.digital_output(X_PIN).on()  # the session goes on
        assert fake.values == {9: 120, X_PIN: 1}
    assert dropped, "X's first Ack was never dropped: the scenario did not happen"
    (x_id,) = dropped
    # Before the fix X went out again after the restore's 18 ids, 19 behind the device's
    # newest, and ran a second time.
    assert executed[x_id] == 1, f"X (id {x_id}) executed {executed[x_id]} times"
    assert [r.msg.message_id for r in fake.arrivals("digital_init")].count(x_id) == 1

"""The session layer's rules alone (protoduino.session): no link, no table, no clock but numbers."""

from __future__ import annotations

from protoduino.errors import AckTimeoutError, rejection
from protoduino.messages import ArduinoIn, ArduinoOut, Status
from protoduino.session import (
    RESTORE_RETRIES,
    FailsafeLiveness,
    RebootLoop,
    RestorePlan,
    refused_configured_output,
)


def test_the_limit_th_loss_within_the_window_is_a_loop() -> None:
    loop = RebootLoop(limit=3, window=60.0)
    assert loop.lost(0.0) is None and loop.lost(30.0) is None
    assert loop.lost(61.0) is None  # the first one left the window
    error = loop.lost(80.0)
    assert error is not None and loop.error is error and "3 times within 60 s" in str(error)


def init(pin: int) -> ArduinoIn:
    msg = ArduinoIn()
    msg.servo_init.pin = pin
    return msg


def test_a_restore_message_that_times_out_goes_again_a_bounded_number_of_times() -> None:
    plan = RestorePlan()
    plan.start([init(9), init(10)])
    first = plan.next()
    for _ in range(RESTORE_RETRIES):
        plan.finished("servo_init", first.SerializeToString(), AckTimeoutError("lost"))
        assert plan.next().servo_init.pin == 9  # the same message, first again
    plan.finished("servo_init", first.SerializeToString(), AckTimeoutError("lost"))
    assert plan.next().servo_init.pin == 10  # given up: recorded as failed
    plan.finished("servo_init", b"", rejection(Status.STATUS_INVALID_PIN, "refused"))
    assert not plan.pending
    event = plan.event(values=False)
    assert event.details["replayed"] == 2 and len(event.details["failed"]) == 2


def refusal(status: Status.ValueType, item: int = 0) -> ArduinoOut:
    out = ArduinoOut()
    out.ack.status = status
    out.ack.refused_item = item
    return out


def test_an_unseen_reboot_is_a_not_initialised_control_of_a_configured_output() -> None:
    control = ArduinoIn()
    control.servo_control.pin = 9
    payload = control.SerializeToString()
    configured = [init(9)]
    assert refused_configured_output(
        payload, refusal(Status.STATUS_NOT_INITIALISED).ack, configured
    )
    assert not refused_configured_output(
        payload, refusal(Status.STATUS_OUT_OF_RANGE).ack, configured
    )
    assert not refused_configured_output(
        payload, refusal(Status.STATUS_NOT_INITIALISED).ack, [init(3)]
    )
    pose = ArduinoIn()
    pose.pose.items.add().digital.pin = 4
    pose.pose.items.add().servo.pin = 9
    ack = refusal(Status.STATUS_NOT_INITIALISED, item=2).ack  # the servo item, 1-based
    assert refused_configured_output(pose.SerializeToString(), ack, configured)


def test_only_the_sessions_liveness_source_with_the_devices_epoch_feeds_the_timer() -> None:
    liveness = FailsafeLiveness(timeout=0.5, heartbeat_only=True)
    ok = ArduinoOut().ack
    assert liveness.lapsed(0.0)
    liveness.acked("ping", 0, 1.0, ok)  # a Ping does not count under heartbeat liveness
    assert liveness.lapsed(1.1)
    liveness.acked("heartbeat", 0, 1.0, ok)
    assert not liveness.lapsed(1.49) and liveness.lapsed(1.5)
    fs = ArduinoOut().failsafe
    fs.active, fs.epoch = True, 2
    assert liveness.seen(fs) and liveness.epoch == 2
    assert not liveness.seen(fs)  # reported once per epoch
    tripped = ArduinoOut().ack
    tripped.failsafe.CopyFrom(fs)
    liveness.acked("heartbeat", 0, 2.0, tripped)  # carried an older epoch: fed nothing
    assert liveness.lapsed(2.1)
    liveness.acked("heartbeat", 2, 2.0, tripped)  # carried it back: the device re-armed
    assert not liveness.lapsed(2.1)
    liveness.rebooted()
    assert liveness.epoch == 0

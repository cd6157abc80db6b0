"""The session layer's rules: what the host keeps of the device's session across calls.

The request layer (:mod:`protoduino.rpc`) matches Acks to calls; the rules here decide what a
lost session means and how it comes back. Each is a small object or function with no lock,
no thread and no I/O; the request layer holds them and calls them under its lock, so their
order with the transaction table stays one order.

* :class:`RebootLoop`: the ``limit``-th loss of the outputs within ``window`` seconds is a
  reboot loop (a brown-out?): the board stops restoring and fails every user call.
* :class:`RestorePlan`: the restore sequence, one message at a time and in order (an Init must
  land before its Control); a message that times out is sent again, up to
  :data:`RESTORE_RETRIES` times (a restore that skipped an Init would leave that output dead);
  the RESTORED event that ends it.
* :func:`refused_configured_output`: inferring a reboot nobody saw: a device that refuses a
  Control with STATUS_NOT_INITIALISED for an output the board configured has restarted unseen.
* :class:`FailsafeLiveness`: the device's failsafe epoch as last reported, and whether its
  failsafe may have fired without this host hearing of it (protocol.md section 7).
"""

from __future__ import annotations

import collections
import logging
from typing import Any

from .commands import command
from .errors import AckTimeoutError, ProtoduinoError, RebootLoopError
from .events import Event, EventKind
from .messages import ArduinoIn, Status, parse_in, pose_refused

log = logging.getLogger(__name__)

#: A restore message that gets no Ack is sent again (a new call) this many more times:
#: a restore left half done would leave an output unconfigured on the device.
RESTORE_RETRIES = 3

#: A reboot loop: this many losses of the outputs within REBOOT_WINDOW seconds.
REBOOT_LIMIT = 3
REBOOT_WINDOW = 60.0

Ack = Any  # protoduino_pb2.Ack (protobuf message classes are dynamic)
Failsafe = Any  # protoduino_pb2.Failsafe


class RebootLoop:
    """Counts losses of the outputs; the ``limit``-th within ``window`` seconds is a loop."""

    def __init__(self, limit: int = REBOOT_LIMIT, window: float = REBOOT_WINDOW) -> None:
        self.limit = limit
        self.window = window
        self._losses: collections.deque[float] = collections.deque()
        #: Set once a loop was detected (for good: the board must be opened again).
        self.error: RebootLoopError | None = None

    def lost(self, now: float) -> RebootLoopError | None:
        """One more loss at ``now``; the loop's error if this one makes a loop."""
        self._losses.append(now)
        while self._losses and now - self._losses[0] > self.window:
            self._losses.popleft()
        if len(self._losses) >= self.limit:
            self.error = RebootLoopError(
                f"the device lost its outputs {len(self._losses)} times within "
                f"{self.window:g} s (a reboot loop: a brown-out?); the board stopped "
                "restoring them: close it, fix the cause and open it again"
            )
        return self.error


class RestorePlan:
    """The restore sequence: the messages still to send, retries, what failed."""

    def __init__(self) -> None:
        self._queue: collections.deque[ArduinoIn] = collections.deque()
        self._failed: list[str] = []
        self._count = 0
        self._tries = 0

    def start(self, msgs: list[ArduinoIn]) -> None:
        self._queue = collections.deque(msgs)
        self._failed = []
        self._count = len(msgs)
        self._tries = 0

    def clear(self) -> None:
        self._queue.clear()

    @property
    def pending(self) -> bool:
        """Whether messages are still to be sent."""
        return bool(self._queue)

    def next(self) -> ArduinoIn:
        return self._queue.popleft()

    def put_back(self, payload: bytes) -> None:
        """A message that was in flight when the link went down goes first again."""
        self._queue.appendleft(parse_in(payload))

    def finished(self, kind: str, payload: bytes, error: ProtoduinoError | None) -> None:
        """One restore message completed: sent again if it timed out (a lossy line, not a
        refusal: Inits and values are absolute, so running one twice changes nothing)."""
        if isinstance(error, AckTimeoutError) and self._tries < RESTORE_RETRIES:
            self._tries += 1
            self.put_back(payload)
            return
        self._tries = 0
        if error is not None:
            self._failed.append(f"{kind}: {error}")

    def event(self, values: bool) -> Event:
        """The RESTORED event that ends the sequence (logged as well)."""
        failed = list(self._failed)
        text = f"outputs restored: {self._count} commands replayed " + (
            "(last values included)" if values else "(outputs at their safe values)"
        )
        if failed:
            text += f", {len(failed)} failed ({'; '.join(failed)})"
            log.warning(text)
        else:
            log.info(text)
        return Event(
            EventKind.RESTORED,
            text,
            {"replayed": self._count, "failed": failed, "values": values},
        )


def refused_configured_output(payload: bytes, ack: Ack, restore: list[ArduinoIn]) -> bool:
    """Did the device refuse this command because it lost what the board configured?

    STATUS_NOT_INITIALISED for a Control on an output the board did configure (its Init is
    among the ``restore`` messages) means the device restarted without the host seeing it:
    its EVENT BOOT was lost and a re-handshake (watchdog, desync) found it answering again.
    A Pose counts by its refused item, which is such a Control.
    """
    if ack.status != Status.STATUS_NOT_INITIALISED:
        return False
    control = _refused_control(parse_in(payload), ack)
    if control is None:
        return False
    kind, pin = control
    init = command(kind).needs_init
    if init is None:
        return False
    return any(_kind(m) == init and getattr(m, init).pin == pin for m in restore)


class FailsafeLiveness:
    """The device's failsafe as this session knows it.

    ``epoch``: the latest failsafe epoch the device reported (an event or a liveness Ack);
    every Ping, Heartbeat and ClearInterlock carries it back. ``armed_until``: until when the
    device's failsafe timer surely ran: the first transmission of the last liveness message
    it acknowledged as one, plus the timeout (None: no such message since the session began).
    """

    def __init__(self, timeout: float, heartbeat_only: bool) -> None:
        self.timeout = timeout
        self.heartbeat_only = heartbeat_only
        self.epoch = 0
        self._armed_until: float | None = None

    def seen(self, fs: Failsafe) -> bool:
        """The device's failsafe state; True when it is a new, active one (the host should
        send the epoch back at once: the device re-arms)."""
        if fs.epoch == self.epoch:
            return False
        self.epoch = fs.epoch
        return bool(fs.active)

    def rebooted(self) -> None:
        self.epoch = 0  # a new power-up counts its failsafes from 0

    def acked(self, kind: str, epoch: int | None, first_tx: float, ack: Ack) -> None:
        """What an acknowledged call tells of the timer: a Ping or Heartbeat fed it if it
        carried the device's epoch and is the session's liveness source; a
        ConfigureFailsafe restarts a timer that has not run out."""
        if kind in ("ping", "heartbeat"):
            device = ack.failsafe.epoch if ack.HasField("failsafe") else 0
            counts = kind == "heartbeat" or not self.heartbeat_only
            if not (counts and epoch == device):
                return
        elif kind != "configure_failsafe":
            return
        until = first_tx + self.timeout
        if self._armed_until is None or until > self._armed_until:
            self._armed_until = until

    def lapsed(self, now: float) -> bool:
        """May the device's failsafe have fired without this host hearing of it?

        True when no liveness message was acknowledged within the last failsafe timeout:
        the device may have driven its outputs safe and, having then rebooted or lost the
        session, can no longer say so. A restore must then not send the values from before
        (protocol.md section 7, restore policy).
        """
        return self._armed_until is None or now >= self._armed_until


def _kind(msg: ArduinoIn) -> str | None:
    kind: str | None = msg.WhichOneof("data")
    return kind


def _refused_control(msg: ArduinoIn, ack: Ack) -> tuple[str, int] | None:
    """The ArduinoIn member and pin of the Control a refusal was about, if any.

    A command that names a pin is its own Control; a Pose's refused item is
    one of its Controls (a PoseItem member of the same message type).
    """
    kind = _kind(msg)
    if kind is None:
        return None
    body = getattr(msg, kind)
    if kind == "pose":
        control = pose_refused(body, ack.refused_item)
        if control is None:
            return None
        body = control
        kind = _MEMBER_OF_TYPE.get(body.DESCRIPTOR.full_name, "")
    pin = getattr(body, "pin", None)
    return (kind, pin) if isinstance(pin, int) else None


#: ArduinoIn member by its message type (a Pose item's Control -> "servo_control", ...).
_MEMBER_OF_TYPE = {
    field.message_type.full_name: field.name
    for field in ArduinoIn.DESCRIPTOR.oneofs_by_name["data"].fields
    if field.message_type is not None
}

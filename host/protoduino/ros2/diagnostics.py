"""What the bridge reports on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray).

Three statuses per board, named after its namespace so that several boards
share the one ``/diagnostics`` topic, as ROS 2's diagnostic aggregator expects:

* ``<name>: link``: the link counters of ``board.stats``; OK while the link is
  up, WARN while it handshakes, ERROR when it is down or failed, STALE once the
  bridge closed it;
* ``<name>: failsafe``: whether the device holds its outputs safe and why
  (ping or heartbeat timeout, stop, interlock), reboots and lost sessions;
  ERROR while a failsafe is active;
* ``<name>: bridge``: the messages it refused (by topic and reason), the
  commands the device refused, those a newer one of the same topic replaced
  before they were sent, those a latched STOP held, the stale ``cmd_vel`` stops, and with
  ``services:`` whether its Trigger services are up (:mod:`.services`);
  WARN while a STOP is latched or when a message was refused since the previous
  report; STALE in the last report of a clean shutdown.

:class:`Health` collects the counts from both the bridge's loop and the
board's event thread (hence its lock); :meth:`Health.report` turns them into
a message.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Mapping
from typing import Any

from ..events import Event, EventKind, Stats
from .msgs import DiagnosticArray, DiagnosticStatus, Header, KeyValue, Time

OK, WARN, ERROR, STALE = 0, 1, 2, 3

#: Board events that change what /diagnostics says: published at once, not at the next period.
URGENT = frozenset(
    {
        EventKind.FAILSAFE,
        EventKind.REBOOTED,
        EventKind.SESSION_LOST,
        EventKind.DISCONNECTED,
        EventKind.CONNECTED,
        EventKind.ERROR,
    }
)


def stamp(now: float | None = None) -> Header:
    """A header stamped with the wall clock (ROS time is the Unix epoch)."""
    t = time.time() if now is None else now
    sec = int(t)
    return Header(stamp=Time(sec=sec, nanosec=int((t - sec) * 1e9)))


def _text(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _values(pairs: Mapping[str, object]) -> list[KeyValue]:
    return [KeyValue(key=k, value=_text(v)) for k, v in pairs.items()]


def link_values(stats: Stats) -> dict[str, object]:
    """Every counter of ``board.stats``, mappings flattened to ``name.key``."""
    values: dict[str, object] = {}
    for name, value in stats.as_dict().items():
        if isinstance(value, Mapping):
            for key, count in sorted(value.items()):
                values[f"{name}.{key}"] = count
        elif value is not None:
            values[name] = value
    return values


class Health:
    """The bridge's counters and the device's failsafe state, for :meth:`report`."""

    def __init__(self, name: str, hardware_id: str) -> None:
        self.name = name
        self.hardware_id = hardware_id
        self._lock = threading.Lock()
        #: Messages refused, by "topic: reason".
        self.bad: collections.Counter[str] = collections.Counter()
        self.bad_total = 0
        self._bad_reported = 0
        self.refused = 0  # commands the device (or the board's checks) refused
        self.forwarded = 0  # commands that reached the device
        self.superseded = 0  # valid commands a newer one of the same topic replaced unsent
        self.stale_stops = 0
        self.stops = 0
        self.held = 0  # commands a latched STOP held
        self.stop_latched = False
        self.interlock_clears = 0
        #: The Trigger services' state (.services); None: robot.yaml asks for none.
        self.services: str | None = None
        #: None while running; at a clean shutdown, whether the bridge's Stop drove the
        #: outputs safe (else the device's failsafe will).
        self.shut_down_stopped: bool | None = None
        self.failsafe_active = False
        self.failsafe_cause = "none"
        self.failsafes = 0
        self.reboots = 0
        self.sessions_lost = 0
        self.last_event = ""

    def bad_message(self, topic: str, reason: str) -> None:
        with self._lock:
            self.bad[f"{topic}: {reason}"] += 1
            self.bad_total += 1

    def count(self, what: str, n: int = 1) -> None:
        """Add to one of the plain counters (forwarded, refused, stale_stops, stops, held,
        interlock_clears)."""
        with self._lock:
            setattr(self, what, getattr(self, what) + n)

    def latch(self, latched: bool) -> None:
        """A STOP latched (True) or released by a resume (False)."""
        with self._lock:
            self.stop_latched = latched

    def shut_down(self, stopped: bool) -> None:
        """The bridge shut down cleanly: the next report is its last."""
        with self._lock:
            self.shut_down_stopped = stopped

    def event(self, event: Event) -> bool:
        """Take in a board event; True if it should be reported at once."""
        with self._lock:
            if event.kind is EventKind.FAILSAFE:
                self.failsafe_active = bool(event.details.get("active", False))
                self.failsafe_cause = str(event.details.get("cause", "none"))
                self.failsafes += int(self.failsafe_active)
            elif event.kind is EventKind.REBOOTED:
                self.reboots += 1
            elif event.kind is EventKind.SESSION_LOST:
                self.sessions_lost += 1
            if event.kind in URGENT:
                self.last_event = str(event)
                return True
            return False

    def report(self, stats: Stats, now: float | None = None) -> DiagnosticArray:
        """The three statuses (see the module docstring), stamped ``now`` (Unix time)."""
        with self._lock:
            link = self._link_status(stats)
            failsafe = self._failsafe_status()
            bridge = self._bridge_status()
            self._bad_reported = self.bad_total
        return DiagnosticArray(header=stamp(now), status=[link, failsafe, bridge])

    def _status(
        self, what: str, level: int, message: str, values: dict[str, Any]
    ) -> DiagnosticStatus:
        return DiagnosticStatus(
            level=level,
            name=f"{self.name}: {what}",
            message=message,
            hardware_id=self.hardware_id,
            values=_values(values),
        )

    def _link_status(self, stats: Stats) -> DiagnosticStatus:
        level = {"active": OK, "handshaking": WARN, "closed": STALE}.get(stats.state, ERROR)
        return self._status("link", level, f"link {stats.state}", link_values(stats))

    def _failsafe_status(self) -> DiagnosticStatus:
        if self.failsafe_active:
            level, message = ERROR, f"outputs held safe by the device ({self.failsafe_cause})"
        else:
            level, message = OK, "outputs commanded by the host"
        values = {
            "active": self.failsafe_active,
            "cause": self.failsafe_cause,
            "failsafes": self.failsafes,
            "reboots": self.reboots,
            "sessions_lost": self.sessions_lost,
            "last_event": self.last_event,
        }
        return self._status("failsafe", level, message, values)

    def _bridge_status(self) -> DiagnosticStatus:
        fresh = self.bad_total - self._bad_reported
        level = WARN if fresh else OK
        message = f"{fresh} message(s) refused since the last report" if fresh else "running"
        if self.stop_latched:
            level, message = WARN, "STOP latched: commands held until a resume"
        if self.shut_down_stopped is not None:
            level = STALE
            message = "shut down: " + (
                "every output driven safe by the device's Stop"
                if self.shut_down_stopped
                else "the outputs left to the device's failsafe"
            )
        values: dict[str, Any] = {
            "bad_messages": self.bad_total,
            "forwarded": self.forwarded,
            "superseded": self.superseded,
            "refused_by_device": self.refused,
            "stops": self.stops,
            "stop_latched": self.stop_latched,
            "held_by_stop": self.held,
            "cmd_vel_stale_stops": self.stale_stops,
            "interlock_clears": self.interlock_clears,
        }
        if self.services is not None:
            values["services"] = self.services
        values.update({f"bad.{k}": v for k, v in sorted(self.bad.items())})
        return self._status("bridge", level, message, values)

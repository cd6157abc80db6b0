"""The clock the link and request layers read: injected, so tests can move it themselves.

A ``Clock`` returns seconds on a monotonic scale. Production code passes
``time.monotonic``; a test passes a clock it advances by hand, so every timer
(handshake retries, watchdog, Ack timeouts, pings) fires exactly when the test
says, with no thread and no wall clock involved.
"""

from __future__ import annotations

from collections.abc import Callable

Clock = Callable[[], float]

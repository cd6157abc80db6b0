"""What every pin mode's module shares: a configured pin's record, and what a mode needs of
its board.

The board is what :class:`ModeBoard` (for a mode's Init) and :class:`OutputBoard` (for an
output's handle) name, so no mode module depends on the board's module: data flows one way,
the board composing the modes.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Protocol, TypeVar

from ..commands import PinMode
from ..inputs import InputTable
from ..messages import ArduinoIn, InputKind
from ..readback import DeviceInfo

T = TypeVar("T")

#: A mode's Init as the board sends it: the message, what to record at its OK Ack (run on
#: the I/O thread with the board's lock held), and the mode's handle (or what makes it).
Built = tuple[ArduinoIn, Callable[[], None], T]


@dataclass(slots=True)
class PinRecord:
    """What the host knows of one configured pin, for checks and session restore."""

    mode: PinMode
    init: bytes  # the Init as sent, without its message_id: what a restore sends again
    safe: int  # the safe value: a pulse width (us) or a level (0, 1)
    min_us: int = 0
    max_us: int = 0
    last: bytes | None = None  # the last acknowledged Control, if any since init/stop/failsafe
    #: The value last acknowledged (us or level); an Init, a Stop and a failsafe make it safe.
    value: int = 0

    def __post_init__(self) -> None:
        self.value = self.safe


class OutputBoard(Protocol):
    """What an output needs of its board (:class:`protoduino.Board`)."""

    def _value(self, pin: int, mode: PinMode) -> int | None: ...

    def _control(self, pin: int, msg: ArduinoIn, value: int) -> None: ...

    def _control_future(self, pin: int, msg: ArduinoIn, value: int) -> Future[None]: ...

    def release(self, pin: int) -> None: ...

    def submit_release(self, pin: int) -> Future[None]: ...


class ModeBoard(OutputBoard, Protocol):
    """What a mode's Init needs of its board (:class:`protoduino.Board`): the device's
    figures, the checks that span the modes, and the record of what the board configured."""

    info: DeviceInfo
    _lock: threading.Lock
    _outputs: dict[int, PinRecord]

    @property
    def call_timeout(self) -> float: ...

    @property
    def inputs(self) -> InputTable: ...

    def pin_number(self, pin: object) -> int: ...

    def _check_pin(
        self, pin: object, mode: PinMode | None = None, *, reserved: bool = True
    ) -> int: ...

    def _check_reserved(self, pin: int) -> None: ...

    def _check_feature(self, mode: PinMode) -> None: ...

    def _check_capable(self, pin: int, mode: PinMode) -> None: ...

    def _check_free(self, pin: int, mode: PinMode) -> None: ...

    def _set_output(self, pin: int, state: PinRecord) -> None: ...

    def _input_recorder(
        self, pin: int, mode: PinMode, msg: ArduinoIn, kind: InputKind
    ) -> Callable[[], None]: ...

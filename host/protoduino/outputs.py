"""The board's outputs: :class:`Servo`, :class:`DigitalOutput`, :class:`PwmOutput`.

Each is a handle on one configured pin: it checks its values (the pin's limits, the argument
checks of :mod:`protoduino.arguments`) and asks its board to send them. Each lives with the
rest of its pin mode's host code, in :mod:`protoduino.modes` (``servo``, ``digital``,
``pwm``); this module names them together, as before. The board is what
:class:`OutputBoard` names, so no output depends on the board's module.
"""

from __future__ import annotations

# Explicit re-exports: the outputs' names, where they were first.
from .modes.base import OutputBoard as OutputBoard  # noqa: PLC0414
from .modes.digital import DigitalOutput as DigitalOutput  # noqa: PLC0414
from .modes.pwm import PwmOutput as PwmOutput  # noqa: PLC0414
from .modes.servo import Servo as Servo  # noqa: PLC0414

"""The pin modes on the host, one module each (docs/architecture.md, *Adding a built-in
command or pin mode*).

A mode's module holds everything the host does for that mode alone: its Init's arguments,
checked in the device's order, the Init itself (the message a session restore sends again),
what the board records at its Ack, and its handle (:class:`~protoduino.modes.servo.Servo`,
...). What the modes share is in :mod:`protoduino.modes.base`: the record of a configured
pin and what a mode needs of its board (a protocol, so no mode imports the board).
:class:`protoduino.Board` composes them: its methods check what spans the modes (the pin,
the feature, the pins the board holds, timers) through the mode's calls, and send.
The modes themselves are declared once, in the schema (``commands.PIN_MODES``).
"""

"""protoduino's development and test tooling, kept out of the runtime package.

Installed from the source checkout (``./tools/dev.sh setup`` runs ``pip install -e ./dev``);
a user's ``pip install protoduino`` does not carry it. Modules:

* :mod:`~protoduino_dev.build`: builds the firmware, the simulated board and the emulated
  Uno's runner from the checkout with make (declared to the runtime as its program source by
  entry point, see :mod:`protoduino.plugins`);
* :mod:`~protoduino_dev.codegen`: ``protoduino gen``;
* :mod:`~protoduino_dev.faults` and ``urlhandler``: the ``faulty://`` pyserial URL (seeded,
  repeatable line faults), registered by importing this package;
* :mod:`~protoduino_dev.soak`: seeded fault scenarios behind ``protoduino soak``.
"""

from __future__ import annotations

import serial as _serial

# Make faulty:// known to serial.serial_for_url: only where the development tools are
# imported, never merely because an application imported protoduino.
if "protoduino_dev.urlhandler" not in _serial.protocol_handler_packages:
    _serial.protocol_handler_packages.append("protoduino_dev.urlhandler")

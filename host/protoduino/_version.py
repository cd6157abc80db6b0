"""The version of protoduino: the one place it is written.

The package (``protoduino.__version__``), its distribution's metadata (pyproject.toml reads this
file), protoduino-dev's (dev/setup.py), the firmware's ``DeviceInfo.firmware_version``
(``protoduino gen`` writes it into firmware/generated/pd_protocol.h) and the Arduino library's
library.properties (``make -C firmware arduino-lib``, from that header) all take it from here.
Standard library only and no imports, so that the build and the generator read it by its path.
"""

__version__ = "0.1.0"

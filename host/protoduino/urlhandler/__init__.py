"""pyserial URL handlers of protoduino's own (``faulty://``).

Registered in ``serial.protocol_handler_packages`` when protoduino is imported.
"""

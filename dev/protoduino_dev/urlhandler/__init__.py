"""pyserial URL handlers of protoduino's own (``faulty://``).

Registered in ``serial.protocol_handler_packages`` when protoduino_dev is imported.
"""

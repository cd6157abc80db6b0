"""Code generated from proto/protoduino.proto by ``protoduino gen``. Do not edit."""

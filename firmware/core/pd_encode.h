/*
 * Encoder for the device's one outgoing message, ArduinoOut.
 *
 * Why not pb_encode: nanopb's encoder is generic (descriptor tables, sizing
 * passes, callbacks) and costs about 2.7 KB of the Uno's flash plus the
 * ArduinoOut descriptors' RAM, to encode five small, fixed shapes. This one
 * writes the same bytes directly from the generated structs and field tags.
 * "The same bytes" is checked, not assumed: the unit tests compare it with
 * pb_encode on every message shape and edge value, and the fuzz target
 * re-encodes every DATA frame the device sends with pb_encode and aborts on
 * any difference. Decoding (untrusted input) stays with nanopb.
 *
 * Encoding rules followed (nanopb's, i.e. protobuf's canonical form): fields
 * in tag order; proto3 singular fields omitted at their default (0, false,
 * empty); the set member of a oneof always written; repeated scalars packed.
 */
#ifndef PD_ENCODE_H
#define PD_ENCODE_H

#include <stddef.h>
#include <stdint.h>

#include "protoduino.pb.h"

/* Encode `msg` into buf (capacity cap). Returns the length, or 0 if cap is
 * below protoduino_ArduinoOut_size (the largest message: any message fits a
 * buffer that size, and is written without a bounds check per byte) or a field
 * is out of its bounds (an empty ArduinoOut also encodes to 0 bytes; the core
 * never sends one). */
size_t pd_encode_out(const protoduino_ArduinoOut *msg, uint8_t *buf, size_t cap);

#endif /* PD_ENCODE_H */

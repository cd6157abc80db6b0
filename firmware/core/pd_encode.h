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

#include "pd_features.h"
#include "pd_hal.h"
#include "protoduino.pb.h"

/*
 * DeviceInfo's pin table (pins, timers: protocol version 7), written from the
 * board's table (pd_hal_board_info) of the HAL in DeviceInfo.pins.arg (the
 * core's opaque HAL pointer: pd_dispatch.c) for a DeviceInfo of num_pins > 0:
 * never copied into the message's struct, so it costs the Uno's RAM nothing
 * but the callbacks' pointers. The schema bounds them (max_size in
 * protoduino.options, which nanopb's DeviceInfo size counts: PD_INFO_PINS_MAX,
 * PD_INFO_TIMERS_MAX); a build's own bound is its PD_MAX_PINS (20 on the Uno, 70 on the Mega,
 * whose DeviceInfo is sized by it: PD_ENCODE_INFO_MAX).
 */
#define PD_INFO_PINS_MAX 70u
#define PD_INFO_TIMERS_MAX 3u
typedef char pd_assert_info_pins[(PD_MAX_PINS <= PD_INFO_PINS_MAX) ? 1 : -1];
/* Pin `pin`'s byte of DeviceInfo.pins: its PinBit flags and, in bits 5-7, 1 +
 * the number of the timer the device holds that its PWM output needs. */
uint8_t pd_encode_pin(const pd_board_info_t *board, uint8_t pin);
/* How many bytes DeviceInfo.timers has (up to the highest timer held), and
 * Timer `timer`'s (a TimerUse). */
uint8_t pd_encode_timer_count(const pd_board_info_t *board);
uint8_t pd_encode_timer(const pd_board_info_t *board, uint8_t timer);

/* The schema's bound of a pin set (protoduino.options: the Mega's 9 bytes); a build sends
 * PD_PINSET_BYTES at most, which sizes its messages below. */
#define PD_PINSET_WIRE_MAX 9u
typedef char pd_assert_pinset_bytes[(PD_PINSET_BYTES <= PD_PINSET_WIRE_MAX) ? 1 : -1];
#define PD_PINSET_SPARE (PD_PINSET_WIRE_MAX - PD_PINSET_BYTES)

/*
 * The largest ArduinoOut the device can send, tighter than nanopb's
 * protoduino_ArduinoOut_size, which adds up every field of an Ack as if all
 * could be set at once: an Ack carries one result (DeviceInfo, OutputStates or
 * a ping echo of up to 64 B), a Failsafe only beside a ping echo (the Ack of a
 * liveness message), a refused item only alone. 16 B less per transmit buffer
 * and in the Uno's transmit ring. An Ack of another shape is refused by the
 * encoder before it writes (put_ack), never written past this bound.
 */
#define PD_ENCODE_MAX2(a, b) ((a) > (b) ? (a) : (b))
/* DeviceInfo as the device sends it: user_fingerprint (a fixed32, 5 B) only
 * from a firmware with a user service (PD_FEATURE_USER), so that the field
 * costs the default build no transmit buffer, and a pin table of this build's
 * PD_MAX_PINS bytes at most. */
#define PD_ENCODE_INFO_MAX                                                   \
    (protoduino_DeviceInfo_size - (PD_FEATURE_USER ? 0u : 5u) - (PD_INFO_PINS_MAX - PD_MAX_PINS))
/* OutputStates and InputReport with this build's pin sets (3 and 4 of them). */
#define PD_ENCODE_OUTPUTS_MAX (protoduino_OutputStates_size - 3u * PD_PINSET_SPARE)
#define PD_ENCODE_REPORT_MAX (protoduino_InputReport_size - 4u * PD_PINSET_SPARE)
/* A UserCall's Ack: its reply (or none) and its handler's code. */
#define PD_ENCODE_USER_ACK_MAX (2u + 64u + 2u)
#define PD_ENCODE_ACK_MAX                                                    \
    (8u + PD_ENCODE_MAX2(PD_ENCODE_MAX2(2u + PD_ENCODE_INFO_MAX,             \
                                        2u + PD_ENCODE_OUTPUTS_MAX),         \
                         66u + 2u + protoduino_Failsafe_size))
#define PD_ENCODE_NARROW_MAX                                                 \
    (2u + PD_ENCODE_MAX2(PD_ENCODE_MAX2(PD_ENCODE_ACK_MAX, PD_ENCODE_REPORT_MAX), \
                         PD_ENCODE_MAX2(protoduino_Failsafe_size, protoduino_UserReport_size)))
/* A build whose largest message takes 128 B or more (the Mega's DeviceInfo, a byte for each of
 * its 70 pins): its nested messages' lengths may take two bytes, one more for the Ack and one
 * for its DeviceInfo. Every other build writes one-byte lengths (pd_encode.c, close_msg). */
#define PD_ENCODE_WIDE (PD_ENCODE_NARROW_MAX >= 128u)
#define PD_ENCODE_MAX (PD_ENCODE_NARROW_MAX + (PD_ENCODE_WIDE ? 2u : 0u))

/* Encode `msg` into buf (capacity cap). Returns the length, or 0 if cap is
 * below PD_ENCODE_MAX (the largest message: any message fits a buffer that
 * size, and is written without a bounds check per byte) or a field is out of
 * its bounds or an Ack is of no shape the device sends (an empty ArduinoOut
 * also encodes to 0 bytes; the core never sends one). */
size_t pd_encode_out(const protoduino_ArduinoOut *msg, uint8_t *buf, size_t cap);

#endif /* PD_ENCODE_H */

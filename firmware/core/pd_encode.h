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

#include "pd_caps.h" /* first: a board's PD_MAX_TIMERS before the default below */
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
#define PD_INFO_TIMERS_MAX 6u
/* The most timers a board of this build states (DeviceInfo.timers' bytes: up to the highest
 * it holds): the Uno's 3 bound its Timer0 .. Timer2, the Mega's 6 its Timer5 (firmware/Makefile). */
#ifndef PD_MAX_TIMERS
#define PD_MAX_TIMERS 3u
#endif
typedef char pd_assert_info_timers[(PD_MAX_TIMERS <= PD_INFO_TIMERS_MAX) ? 1 : -1];
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
    (protoduino_DeviceInfo_size - (PD_FEATURE_USER ? 0u : 5u) - (PD_INFO_PINS_MAX - PD_MAX_PINS) - \
     (PD_INFO_TIMERS_MAX - PD_MAX_TIMERS))
/*
 * OutputStates.servos (ReadOutputs): 5 B a servo, written by the outputs' own writer
 * (pd_outputs_servos) straight into the message, never copied into its struct (a 120 B
 * field would be the Ack's largest member, and the Uno's stack and code pay for that). The
 * field's callback holds the writer and its argument (pd_encode_servos_set): a call back
 * up, as nanopb's callbacks are, so the encoder knows no outputs. The schema's bound
 * (max_size in protoduino.options) is the largest build's, the Mega's 24 servos; a build's
 * own is its PD_MAX_SERVOS (PD_ENCODE_OUTPUTS_MAX).
 */
#define PD_INFO_SERVOS_MAX 24u
typedef char pd_assert_info_servos[(PD_MAX_SERVOS <= PD_INFO_SERVOS_MAX) ? 1 : -1];
/* Writes the servos' bytes of `ctx` at `b` (at most 5 * PD_MAX_SERVOS); returns their end. */
typedef uint8_t *pd_encode_servos_fn(const void *ctx, uint8_t *b);
/* The writer in the callback's function slot (a function pointer converted, through
 * void (*)(void) as GCC's -Wcast-function-type asks, and converted back before the call:
 * C99 6.3.2.3); nanopb's encoder never meets it. */
typedef bool pd_encode_cb_fn(pb_ostream_t *, const pb_field_t *, void *const *);
static inline void pd_encode_servos_set(pb_callback_t *field, pd_encode_servos_fn *write,
                                        const void *ctx)
{
    field->funcs.encode = (pd_encode_cb_fn *)(void (*)(void))write;
    field->arg = (void *)(uintptr_t)ctx;
}
static inline pd_encode_servos_fn *pd_encode_servos_get(const pb_callback_t *field)
{
    return (pd_encode_servos_fn *)(void (*)(void))field->funcs.encode;
}
/* OutputStates and InputReport with this build's pin sets (3 and 4 of them) and servos. */
#define PD_ENCODE_OUTPUTS_MAX                                                \
    (protoduino_OutputStates_size - 3u * PD_PINSET_SPARE - 5u * (PD_INFO_SERVOS_MAX - PD_MAX_SERVOS))
#define PD_ENCODE_REPORT_MAX (protoduino_InputReport_size - 4u * PD_PINSET_SPARE)
/* A UserCall's Ack: its reply (or none) and its handler's code. */
#define PD_ENCODE_USER_ACK_MAX (2u + 64u + 2u)
/* A nested message of `n` bytes with its tag and length (one byte below 128, else two:
 * only the Mega's DeviceInfo, a byte for each of its 70 pins, and its ReadOutputs, whose 24
 * servos take 120 B, are longer). */
#define PD_ENCODE_NESTED(n) (2u + (n) + ((n) >= 128u ? 1u : 0u))
#define PD_ENCODE_ACK_MAX                                                    \
    (8u + PD_ENCODE_MAX2(PD_ENCODE_MAX2(PD_ENCODE_NESTED(PD_ENCODE_INFO_MAX),  \
                                        PD_ENCODE_NESTED(PD_ENCODE_OUTPUTS_MAX)), \
                         66u + 2u + protoduino_Failsafe_size))
/* A build whose largest message takes 128 B or more (the Mega's: a DeviceInfo byte for each of
 * its 70 pins, a ReadOutputs of 24 servos) writes a nested length of 128 or more in two bytes
 * (pd_encode.c, close_msg); every other build's lengths are one byte. */
#define PD_ENCODE_MAX                                                        \
    PD_ENCODE_NESTED(PD_ENCODE_MAX2(PD_ENCODE_MAX2(PD_ENCODE_ACK_MAX, PD_ENCODE_REPORT_MAX), \
                                    PD_ENCODE_MAX2(protoduino_Failsafe_size, protoduino_UserReport_size)))

/* Encode `msg` into buf (capacity cap). Returns the length, or 0 if cap is
 * below PD_ENCODE_MAX (the largest message: any message fits a buffer that
 * size, and is written without a bounds check per byte) or a field is out of
 * its bounds or an Ack is of no shape the device sends (an empty ArduinoOut
 * also encodes to 0 bytes; the core never sends one). */
size_t pd_encode_out(const protoduino_ArduinoOut *msg, uint8_t *buf, size_t cap);

#endif /* PD_ENCODE_H */

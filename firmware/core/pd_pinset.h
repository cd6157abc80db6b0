/*
 * A set of pins (protocol version 8), the one form of every pin set of the core: the board's
 * (pd_hal.h), the inputs' and the outputs' (pd_inputs.h, pd_outputs.h). Pin P is bit P % 32
 * of word P / 32, in as many 32-bit words as PD_MAX_PINS needs: one on the Uno and the Nano,
 * whose code is then that of a uint32_t mask (the word's index folds to 0), three on the
 * Mega's 70 pins. On the wire a pin set is bytes, pin P bit P % 8 of byte P / 8, without
 * trailing zero bytes (docs/protocol.md section 7, *Pin sets*): pd_pinbytes_add writes that
 * form, pd_pinbytes_has reads it.
 */
#ifndef PD_PINSET_H
#define PD_PINSET_H

#include <stdbool.h>
#include <stdint.h>

#include "protoduino.pb.h" /* pb_size_t */

#include "pd_caps.h" /* first: a board's PD_MAX_PINS before the default below */

/* The most pins a board of this build has (its num_pins): the pin registry's size, and
 * DeviceInfo's pin table's (pd_encode.h). The Nano's profile has 22, the Mega's 70
 * (pd_caps.h). */
#ifndef PD_MAX_PINS
#define PD_MAX_PINS 20
#endif

#define PD_PINSET_WORDS ((PD_MAX_PINS + 31) / 32)
/* The bytes of a pin set on the wire, at most (protoduino.options: 9, the Mega's). */
#define PD_PINSET_BYTES ((PD_MAX_PINS + 7) / 8)

typedef struct pd_pinset {
    uint32_t w[PD_PINSET_WORDS];
} pd_pinset_t;

/* A board table's pin set (pd_hal.h) from the masks of pins 0..31, 32..63 and 64..95: a build
 * keeps the words its PD_MAX_PINS needs (bits past them must be 0). PD_PIN(P): pin P's bit in
 * its word. */
#if PD_PINSET_WORDS == 1
#define PD_PINSET(w0, w1, w2) {{(w0)}}
#elif PD_PINSET_WORDS == 2
#define PD_PINSET(w0, w1, w2) {{(w0), (w1)}}
#else
#define PD_PINSET(w0, w1, w2) {{(w0), (w1), (w2)}}
#endif
#define PD_PIN(pin) (1UL << ((pin) & 31u))

/* Pin `pin`'s word and its bit there (pin < PD_MAX_PINS). */
#define PD_PINSET_WORD(pin) (PD_PINSET_WORDS == 1 ? 0u : (uint8_t)((pin) >> 5))
#define PD_PINSET_BIT(pin) pd_pinset_bit(pin)

/* 1UL << (pin & 31), a byte's bit moved by whole bytes: a 32-bit shift by a variable is a
 * loop of 6 cycles a place on the Uno (about 80 for pin 13, on every digital write). */
static inline uint32_t pd_pinset_bit(uint8_t pin)
{
    uint8_t n = PD_PINSET_WORDS == 1 ? pin : (uint8_t)(pin & 31u);
    uint32_t b = (uint8_t)(1u << (n & 7u));
    switch (n >> 3) {
    case 0:
        return b;
    case 1:
        return b << 8;
    case 2:
        return b << 16;
    default:
        return b << 24;
    }
}

__attribute__((always_inline)) static inline bool pd_pinset_has(const pd_pinset_t *set, uint8_t pin)
{
    return (set->w[PD_PINSET_WORD(pin)] >> (PD_PINSET_WORDS == 1 ? pin : (pin & 31u))) & 1u;
}

static inline void pd_pinset_put(pd_pinset_t *set, uint8_t pin, bool on)
{
    uint32_t bit = PD_PINSET_BIT(pin);
    uint32_t *w = &set->w[PD_PINSET_WORD(pin)];
    *w = on ? (*w | bit) : (*w & ~bit);
}

__attribute__((always_inline)) static inline bool pd_pinset_any(const pd_pinset_t *set)
{
    uint32_t any = 0;
    for (uint8_t i = 0; i < PD_PINSET_WORDS; i++) {
        any |= set->w[i];
    }
    return any != 0;
}

/* Whether pin `pin` is in the wire's pin set `bytes` of `size` bytes (a missing byte is 0). */
static inline bool pd_pinbytes_has(const uint8_t *bytes, pb_size_t size, uint8_t pin)
{
    return (pin >> 3) < size && ((bytes[pin >> 3] >> (pin & 7u)) & 1u);
}

/*
 * Add pin `pin` to the wire's pin set `bytes` of `*size` bytes (zeroed up to PD_PINSET_BYTES
 * beforehand), the pins in ascending order: the set then ends at its highest pin's byte, with
 * no trailing zero byte.
 */
static inline void pd_pinbytes_add(uint8_t *bytes, pb_size_t *size, uint8_t pin)
{
    bytes[pin >> 3] = (uint8_t)(bytes[pin >> 3] | (1u << (pin & 7u)));
    *size = (pb_size_t)((pin >> 3) + 1u);
}

#endif /* PD_PINSET_H */

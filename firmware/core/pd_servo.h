/*
 * Servos: a pulse width per channel, limits, a safe width (or none), a speed
 * limit stepped every servo frame.
 *
 * A pin mode's share of the outputs (pd_outputs.h): its Init and Control, and
 * its safe and release functions, which the pin-mode table (PD_MODES in
 * pd_outputs.c) calls for the walks over every owned pin. It claims and looks
 * up its pins in the pin table (pd_pintable.h); its state is its member of
 * pd_outputs_t.
 */
#ifndef PD_SERVO_H
#define PD_SERVO_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_features.h"
#include "protoduino.pb.h"

struct pd_outputs;

/* The servos' compile-time capacity, PD_MAX_SERVOS: pd_features.h. */

/* safe_us meaning "the safe state is no pulses at all" (real widths are >= 400). */
#define PD_SERVO_SAFE_DETACH 0u

/* A servo channel; its pin is the one the owner table gives the channel (the
 * callers know it: a byte less per channel of the Uno's RAM). */
typedef struct pd_servo {
    uint16_t min_us;
    uint16_t max_us;
    uint16_t safe_us;   /* PD_SERVO_SAFE_DETACH: limp */
    uint8_t step;       /* speed limit: most us per servo frame; 0: none */
    uint16_t us;        /* the width driven now */
    uint16_t target_us; /* the width it moves to (differs only while speed-limited) */
} pd_servo_t;

protoduino_Status pd_outputs_servo_init(struct pd_outputs *out, void *hal,
                                        const protoduino_ServoInit *msg);
protoduino_Status pd_outputs_servo_control(struct pd_outputs *out, void *hal,
                                           const protoduino_ServoControl *msg);

/* A ServoControl checked, then (if `apply`) driven: the Control's and a Pose item's. */
protoduino_Status pd_servo_control(struct pd_outputs *out, void *hal,
                                   const protoduino_ServoControl *msg, bool apply);

/* The pin-mode table's: one servo to its safe width; one servo let go (no pulses). */
void pd_servo_safe(struct pd_outputs *out, void *hal, uint8_t pin, uint8_t slot);
void pd_servo_release(struct pd_outputs *out, void *hal, uint8_t pin, uint8_t slot);

/*
 * Speed limits: move every speed-limited servo one step per servo frame
 * (PD_SERVO_FRAME_MS of `now`) toward its target. Called from pd_core_poll.
 */
void pd_outputs_step(struct pd_outputs *out, void *hal, uint32_t now);

/*
 * x / 180 for x < 32,400 (180 * 180), without a division: (x * 23,302) >> 22
 * is exact there (23,302 / 2^22 exceeds 1/180 by under 7.4e-8, so the error
 * stays below 0.0024 while the fraction it could push over 1 is at most
 * 179/180; tests/c checks every x). A 16 x 16 -> 32 bit multiply takes a few
 * cycles on the AVR's hardware multiplier; libgcc's __udivmodhi4, about 190,
 * twice per servo write, between the command's delimiter and its Ack.
 */
static inline uint16_t pd_div180(uint16_t x)
{
    /* The high half, then 6 more: a 32-bit shift by 22 is a 22-pass loop at -Os. */
    return (uint16_t)((uint16_t)(((uint32_t)x * 23302u) >> 16) >> 6);
}

#endif /* PD_SERVO_H */

/*
 * The output modes and the walks over every owned pin: each mode's per-slot
 * state, limits and safe values (docs/protocol.md section 7,
 * docs/architecture.md "device semantics"). Every check the device makes on
 * an Init or a Control lives here and returns the Ack status; on any status
 * but OK nothing changed.
 *
 * Two tables:
 * - the pin table (pd_pintable.h), pd_outputs_t.owner[]: one byte per pin, the
 *   mode that owns it and the slot of that mode's state it uses (a servo's
 *   channel). Every mode, the inputs' and a user service's too, claims and
 *   looks up pins through pd_pins_claim() and pd_pins_owned(); the table knows
 *   no mode and calls none;
 * - the pin-mode table, PD_MODES in pd_outputs.c: per mode, how to drive a pin
 *   of it to its safe value and how to release it, for the walks over every
 *   owned pin (Release, ReleaseAll, the failsafe's safe-all).
 *
 * How to add a pin mode (the files touched by hand, counted by adding a
 * throwaway output mode; docs/architecture.md):
 *   1. proto/protoduino.proto: its Init and Control messages (each with a `pin`
 *      field; an input has no Control) and their ArduinoIn.data members, and one
 *      Feature value with a (pin_mode) option naming them (and the DeviceInfo
 *      mask of the pins that can do it, if not every pin can); then
 *      `protoduino gen`, which writes PD_MODE_<NAME>, PD_FEATURE_<NAME> and
 *      PD_FEATURES (pd_tables.h), the Makefile's feature list, the command table
 *      and the host's declarations (host/protoduino/commands.py reads them);
 *   2. here: its state, if any, in pd_outputs_t (an array indexed by slot, or a
 *      mask by pin), and its Init/Control functions' prototypes;
 *   3. pd_outputs.c: one X(...) entry in PD_MODES (safe and release; the
 *      compiler checks that every mode has one), and the Init/Control functions,
 *      which call pd_pins_claim() (with the mode's count of slots) and
 *      pd_pins_owned() of pd_pintable.h, under #if PD_FEATURE_<NAME>;
 *   4. pd_dispatch.c: their handlers cmd_<init>() and cmd_<control>();
 *   5. the tests that list the default firmware's features
 *      (tests/unit/test_pins_fake.py, tests/e2e/test_cli.py), and the switch in
 *      firmware/arduino/src/pd_config.h (a feature not listed there is on).
 * Then, for a mode the host offers: docs/protocol.md, its Board method
 * (host/protoduino/board.py, aio.py; a named PinMode in commands.py if the
 * host's code refers to it) and its tests; the HAL (pd_hal.h, avr/, posix/) if
 * it drives a pin in a new way; ReadOutputs (pd_outputs_read, pd_encode.c) if
 * the host reads it back; the fake devices (tests/) when their tests use it.
 */
#ifndef PD_OUTPUTS_H
#define PD_OUTPUTS_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_features.h"
#include "pd_hal.h"
#include "pd_inputs.h"
#include "pd_pintable.h"
#include "pd_tables.h"
#include "protoduino.pb.h"

/* Compile-time capacity; a board reports its real figures in pd_board_info_t
 * (PD_MAX_PINS: pd_hal.h). */
#ifndef PD_MAX_SERVOS
#define PD_MAX_SERVOS 8
#endif
/* PWM outputs at once (the Uno has four PWM pins it can give: 3, 9, 10, 11). */
#ifndef PD_MAX_PWM
#define PD_MAX_PWM 4
#endif
/* A build without servos or PWM keeps one slot of each (the code stays simple), not eight or four. */
#if !PD_FEATURE_SERVO
#undef PD_MAX_SERVOS
#define PD_MAX_SERVOS 1
#endif
#if !PD_FEATURE_PWM
#undef PD_MAX_PWM
#define PD_MAX_PWM 1
#endif

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

typedef struct pd_pwm {
    uint8_t safe; /* duty 0..255 the failsafe, Stop and an interlock drive */
    uint8_t duty; /* the duty driven now */
} pd_pwm_t;

typedef struct pd_outputs {
    uint8_t owner[PD_MAX_PINS]; /* the pin table (pd_pintable.h): PD_OWNER(mode, slot); 0 = free */
    pd_servo_t servo[PD_MAX_SERVOS];
    pd_pwm_t pwm[PD_MAX_PWM];
    uint32_t digital_safe;  /* bit N: safe level of pin N */
    uint32_t digital_level; /* bit N: current level of pin N */
    uint32_t stepped_at;    /* pd_hal_millis() of the last speed step */
    pd_inputs_t inputs;     /* the input modes' state (pd_inputs.h) */
#if PD_FEATURE_USER
    struct pd_core *core;   /* the device whose table this is: the user hooks' ctx (pd_user.h) */
#endif
} pd_outputs_t;


void pd_outputs_init(pd_outputs_t *out);

protoduino_Status pd_outputs_servo_init(pd_outputs_t *out, void *hal,
                                        const protoduino_ServoInit *msg);
protoduino_Status pd_outputs_servo_control(pd_outputs_t *out, void *hal,
                                           const protoduino_ServoControl *msg);
protoduino_Status pd_outputs_digital_init(pd_outputs_t *out, void *hal,
                                          const protoduino_DigitalInit *msg);
protoduino_Status pd_outputs_digital_control(pd_outputs_t *out, void *hal,
                                             const protoduino_DigitalControl *msg);

/* Whether a pin of the servos' timer (pd_board_info_t.servo_timer_pins) does PWM. */
bool pd_outputs_timer_pwm(const pd_outputs_t *out, void *hal);

protoduino_Status pd_outputs_pwm_init(pd_outputs_t *out, void *hal, const protoduino_PwmInit *msg);
protoduino_Status pd_outputs_pwm_control(pd_outputs_t *out, void *hal,
                                         const protoduino_PwmControl *msg);

/*
 * Several outputs at once, all or nothing: every item is checked (in order,
 * each as its Control would be; a pin twice is STATUS_INVALID_ARGUMENT), then
 * every pin of digital_pins in ascending order (as its DigitalControl; a pin
 * also named by an item is STATUS_INVALID_ARGUMENT), before any is applied.
 * On a refusal *bad is Ack.refused_item: the offending item's position counted
 * from 1, the mask's pins counted on after the items; 1 for a Pose that sets
 * nothing, 0 for a level bit outside digital_pins (protocol.md section 7, rule 7).
 */
protoduino_Status pd_outputs_pose(pd_outputs_t *out, void *hal, const protoduino_Pose *msg,
                                  uint8_t *bad);

/* What every configured output drives now (ReadOutputs). */
void pd_outputs_read(const pd_outputs_t *out, protoduino_OutputStates *states);

/*
 * Speed limits: move every speed-limited servo one step per servo frame
 * (PD_SERVO_FRAME_MS of `now`) toward its target. Called from pd_core_poll.
 */
void pd_outputs_step(pd_outputs_t *out, void *hal, uint32_t now);

/*
 * Release one output (STATUS_NOT_INITIALISED if the pin is free): the pin is
 * free again for any mode, its slot for another pin. What the pin does then is
 * its mode's release (pd_hal.h: a servo stops pulsing, a digital pin becomes an
 * input, as at power-up).
 */
protoduino_Status pd_outputs_release(pd_outputs_t *out, void *hal, uint32_t pin);

/* Release every output (ReleaseAll, a new session). */
void pd_outputs_release_all(pd_outputs_t *out, void *hal);

/* Drive every configured output to its safe value (failsafe, Stop); a
 * speed-limited servo moves there at its speed. */
void pd_outputs_all_safe(pd_outputs_t *out, void *hal);

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

#endif /* PD_OUTPUTS_H */

/*
 * The outputs: their state (each mode's part of it, pd_outputs_t, beside the
 * pin table) and what acts on all modes at once: the walks over every owned
 * pin, Pose and ReadOutputs. Each output mode is a file of its own (pd_servo,
 * pd_digital, pd_pwm): its limits and safe values (docs/protocol.md section 7,
 * docs/architecture.md "device semantics"); every check the device makes on
 * its Init or Control lives there and returns the Ack status; on any status
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
 * How to add a pin mode (the files touched by hand; docs/architecture.md counts them):
 *   1. proto/protoduino.proto: its Init and Control messages (each with a `pin`
 *      field; an input has no Control) and their ArduinoIn.data members, and one
 *      Feature value with a (pin_mode) option naming them (and the DeviceInfo
 *      mask of the pins that can do it, if not every pin can); then
 *      `protoduino gen`, which writes PD_MODE_<NAME>, PD_FEATURE_<NAME> and
 *      PD_FEATURES (pd_tables.h), the Makefile's feature list, the command table
 *      and the host's declarations (host/protoduino/commands.py reads them);
 *   2. a file of its own, pd_<mode>.h and pd_<mode>.c (as pd_servo, pd_digital,
 *      pd_pwm), the .c's code within #if PD_FEATURE_<NAME> (built only with its
 *      feature): its state's type, its Init/Control functions, which call
 *      pd_pins_claim() (with the mode's count of slots) and pd_pins_owned() of
 *      pd_pintable.h, and its safe and release functions;
 *   3. here: #include its header, and its state, if any, in pd_outputs_t (an
 *      array indexed by slot, or a mask by pin); pd_outputs.c: one X(...) entry
 *      in PD_MODES (its feature, safe and release; the compiler checks that every
 *      mode has one), and its Pose item and ReadOutputs if it has them (calling
 *      into its file only where PD_FEATURE_<NAME> is on);
 *      an input mode instead: pd_<mode>.c alone (as pd_digital_input.c), its
 *      state in pd_inputs_t and its Init in pd_inputs.h, its poll in
 *      pd_input_modes.h and pd_inputs_poll, its values in pd_inputs_report and
 *      pd_inputs_sent (pd_inputs.c), its release in pd_inputs_state.c, and its
 *      X(...) entry in PD_MODES;
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
#include "pd_digital.h"
#include "pd_pintable.h"
#include "pd_pwm.h"
#include "pd_servo.h"
#include "pd_tables.h"
#include "protoduino.pb.h"

typedef struct pd_outputs {
    uint8_t owner[PD_MAX_PINS]; /* the pin table (pd_pintable.h): PD_OWNER(mode, slot); 0 = free */
    pd_servo_t servo[PD_MAX_SERVOS];
    pd_pwm_t pwm[PD_MAX_PWM];
    pd_pinset_t digital_safe;  /* the safe level of pin N (pd_pinset.h) */
    pd_pinset_t digital_level; /* the current level of pin N */
    uint32_t stepped_at;    /* pd_hal_millis() of the last speed step */
    pd_inputs_t inputs;     /* the input modes' state (pd_inputs.h) */
#if PD_FEATURE_USER
    struct pd_core *core;   /* the device whose table this is: the user hooks' ctx (pd_user.h) */
#endif
} pd_outputs_t;


void pd_outputs_init(pd_outputs_t *out);

/*
 * Several outputs at once, all or nothing: every item is checked (in order,
 * each as its Control would be; a pin twice is STATUS_INVALID_ARGUMENT), then
 * every pin of the set digital_pins in ascending order (as its DigitalControl; a
 * pin also named by an item is STATUS_INVALID_ARGUMENT), before any is applied.
 * On a refusal *bad is Ack.refused_item: the offending item's position counted
 * from 1, the set's pins counted on after the items; 1 for a Pose that sets
 * nothing, 0 for a level outside digital_pins (protocol.md section 7, rule 7).
 */
protoduino_Status pd_outputs_pose(pd_outputs_t *out, void *hal, const protoduino_Pose *msg,
                                  uint8_t *bad);

/* What every configured output drives now (ReadOutputs). */
void pd_outputs_read(const pd_outputs_t *out, protoduino_OutputStates *states);

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

#endif /* PD_OUTPUTS_H */

/*
 * What the input modes share (pd_input_modes.c), and each mode's share of the loop's pass
 * (pd_inputs_poll) and of the report. Each input mode is a file of its own, built only with
 * its feature switch (pd_features.h): pd_digital_input.c (PD_FEATURE_DIGITAL_INPUT, with the
 * interlocks), pd_analog_input.c (PD_FEATURE_ANALOG_INPUT), pd_counter.c (PD_FEATURE_COUNTER).
 * Their Inits and ClearInterlock are declared in pd_inputs.h, their state is pd_inputs_t's.
 */
#ifndef PD_INPUT_MODES_H
#define PD_INPUT_MODES_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_inputs.h"
#include "pd_state.h"

/* Whether any input mode is built. */
#define PD_ANY_INPUT (PD_FEATURE_DIGITAL_INPUT || PD_FEATURE_ANALOG_INPUT || PD_FEATURE_COUNTER)

/* Something changed: a report is due; joining one that is pending counts as coalesced. */
void pd_inputs_mark_dirty(pd_core_t *core);

/* The pin that `mode` holds with `slot`; PD_MAX_PINS if none. */
uint8_t pd_inputs_pin_of(const pd_outputs_t *out, uint8_t mode, uint8_t slot);

/* Whether `pin` is in `set`, a pin past the build's pins counting as in it (refused later, for
 * what it is): a pin set of the board's table read where it is constant, so that it folds. */
__attribute__((always_inline)) static inline bool pd_inputs_pin_can(const pd_pinset_t *set,
                                                                    uint32_t pin)
{
    return pin >= PD_MAX_PINS || pd_pinset_has(set, (uint8_t)pin);
}

/* The checks an input Init shares: the pin can do `mode` (`capable`: pd_inputs_pin_can of the
 * board's pins for it); then the pin table's claim of one of `slots` (*was: the pin had that
 * mode already). */
protoduino_Status pd_inputs_claim(pd_core_t *core, uint8_t pin, uint8_t mode, uint8_t slots,
                                  bool capable, bool *was, uint8_t *slot);

/* Each mode's work of a loop pass, called by pd_inputs_poll when it has any. */
void pd_digital_input_poll(pd_core_t *core, uint32_t now);
void pd_analog_input_poll(pd_core_t *core, uint32_t now);
void pd_counter_poll(pd_core_t *core, uint32_t now);

/* A latched interlock trip told to the host (pd_digital_input.c): behind the report of its
 * edge (pd_inputs_sent), or by the next poll if the report slot emptied otherwise. */
void pd_digital_input_notice(pd_core_t *core);

#endif /* PD_INPUT_MODES_H */

/*
 * Digital outputs: a level per pin and a safe level, kept by pin (bit N of
 * pd_outputs_t.digital_level and .digital_safe), any number of pins at once.
 *
 * A pin mode's share of the outputs (pd_outputs.h): its Init and Control, and
 * its safe and release functions, which the pin-mode table (PD_MODES in
 * pd_outputs.c) calls for the walks over every owned pin. It claims and looks
 * up its pins in the pin table (pd_pintable.h); its state is its member of
 * pd_outputs_t.
 */
#ifndef PD_DIGITAL_H
#define PD_DIGITAL_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_features.h"
#include "protoduino.pb.h"

struct pd_outputs;

protoduino_Status pd_outputs_digital_init(struct pd_outputs *out, void *hal,
                                          const protoduino_DigitalInit *msg);
protoduino_Status pd_outputs_digital_control(struct pd_outputs *out, void *hal,
                                             const protoduino_DigitalControl *msg);

/* A DigitalControl checked, then (if `apply`) driven: the Control's, a Pose item's and
 * a Pose mask's pin's. */
protoduino_Status pd_digital_control(struct pd_outputs *out, void *hal,
                                     const protoduino_DigitalControl *msg, bool apply);

/* The pin-mode table's: one pin to its safe level; one let go (an input, as at power-up). */
void pd_digital_safe(struct pd_outputs *out, void *hal, uint8_t pin, uint8_t slot);
void pd_digital_release(struct pd_outputs *out, void *hal, uint8_t pin, uint8_t slot);

#endif /* PD_DIGITAL_H */

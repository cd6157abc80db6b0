/*
 * PWM outputs: a duty per slot and a safe duty, on the pins with a timer
 * output the clock and the servos do not use.
 *
 * A pin mode's share of the outputs (pd_outputs.h): its Init and Control, and
 * its safe and release functions, which the pin-mode table (PD_MODES in
 * pd_outputs.c) calls for the walks over every owned pin. It claims and looks
 * up its pins in the pin table (pd_pintable.h); its state is its member of
 * pd_outputs_t.
 */
#ifndef PD_PWM_H
#define PD_PWM_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_caps.h" /* first: a board's PD_MAX_PWM before the default below */
#include "pd_features.h"
#include "protoduino.pb.h"

struct pd_outputs;

/* PWM outputs at once (the Uno has four PWM pins it can give: 3, 9, 10, 11). */
#ifndef PD_MAX_PWM
#define PD_MAX_PWM 4
#endif
/* A build without PWM keeps one slot (the code stays simple), not four. */
#if !PD_FEATURE_PWM
#undef PD_MAX_PWM
#define PD_MAX_PWM 1
#endif

typedef struct pd_pwm {
    uint8_t safe; /* duty 0..255 the failsafe, Stop and an interlock drive */
    uint8_t duty; /* the duty driven now */
} pd_pwm_t;

/* Whether a pin of the servos' timer (pd_board_info_t.servo_timer_pins) does PWM. */
bool pd_outputs_timer_pwm(const struct pd_outputs *out, void *hal);

protoduino_Status pd_outputs_pwm_init(struct pd_outputs *out, void *hal,
                                      const protoduino_PwmInit *msg);
protoduino_Status pd_outputs_pwm_control(struct pd_outputs *out, void *hal,
                                         const protoduino_PwmControl *msg);

/* A PwmControl checked, then (if `apply`) driven: the Control's and a Pose item's. */
protoduino_Status pd_pwm_control(struct pd_outputs *out, void *hal,
                                 const protoduino_PwmControl *msg, bool apply);

/* The pin-mode table's: one PWM pin to its safe duty; one let go (an input, as at power-up). */
void pd_pwm_safe(struct pd_outputs *out, void *hal, uint8_t pin, uint8_t slot);
void pd_pwm_release(struct pd_outputs *out, void *hal, uint8_t pin, uint8_t slot);

#endif /* PD_PWM_H */

/*
 * pd_pins.h: turns the level history of the Uno's output pins into the
 * protoduino trace (servo pulse widths and digital levels).
 *
 * A pin's mode is what the firmware configured, which the runner reads from
 * the MCU and passes with each sample: PWM while the firmware's PWM driver runs
 * the pin, servo while a channel of the firmware's servo table drives it, digital
 * otherwise (every level change a line). Only for a program without a servo
 * table the runner can read (not protoduino's firmware) is a servo told from
 * the shape of the pin's waveform (pd_pins.c states that rule).
 *
 * It knows nothing about simavr: the runner feeds it (pin, is_output, level,
 * cycle) samples whenever a port or direction register may have changed, and
 * calls pd_pins_poll() regularly so that deadlines (a high level that lasted
 * too long to be a pulse, a pulse train that stopped) are resolved. Every
 * decision is taken from emulated cycles, never from the wall clock, so the
 * widths are those of the emulated timer and not of the host's scheduling.
 */
#ifndef PD_PINS_H
#define PD_PINS_H

#include <stdint.h>

#define PD_PINS_COUNT 70 /* the most a board has: the Mega's (the Uno's 20: D0..D13, A0..A5) */

/*
 * What the trace can show, in emulated microseconds: the one place these numbers are
 * written. protoduino.simboard.SimBoard's docstring and docs/api.md state them to the
 * package's users, who have no copy of this file (tests/contract/test_docs.py compares).
 */
#define PD_PINS_MAX_PULSE_US 3000UL   /* a longer high is a digital 1, not a pulse */
#define PD_PINS_MAX_PERIOD_US 50000UL /* pulses further apart are not one servo signal */
#define PD_PINS_LOW_WAIT_US 50000UL   /* how long an output low waits for a first pulse */
#define PD_PINS_PWM_STEADY_US 5000UL  /* a PWM pin without an edge this long: duty 0 or 255 */
#define PD_PINS_HYST_US 0.75          /* a smaller change of a servo's width is no change,
                                         unless it rounds to another whole microsecond */

/* pwm_tick for a PWM pin whose timer is disconnected from it while the firmware drives a
 * steady level, as for duty 0 or 255: that duty at once. */
#define PD_PINS_PWM_LEVEL UINT32_MAX

enum pd_pin_mode {
    PD_PIN_MODE_NONE = 0,
    PD_PIN_MODE_DIGITAL,
    PD_PIN_MODE_SERVO,
    PD_PIN_MODE_PWM,
};

/* Called once per trace line: cycle is the emulated time of the change. */
typedef void (*pd_pins_emit_fn)(void *ctx, uint64_t cycle, int pin, enum pd_pin_mode mode,
                                unsigned value);

typedef struct {
    uint8_t level;  /* effective level: output bit set and PORT bit set */
    uint8_t output; /* DDR bit */
    uint8_t high_pending; /* rose, not yet known to be a pulse or a level */
    uint8_t low_out_pending; /* became an output at level 0, not yet classified */
    uint8_t cand;            /* a pulse that differs from the reported value */
    uint8_t servo;           /* pulses are periodic: the pin carries a servo */
    uint64_t rise;
    uint64_t out_since;
    uint64_t cand_rise;
    uint64_t cand_fall;
    double cand_us;
    double servo_us; /* measured width behind the reported servo value */
    uint64_t last_rise;
    uint64_t last_fall;
    /* PWM: the pin carries a timer's waveform (its timer is in a PWM mode). */
    uint8_t pwm;
    uint32_t pwm_tick; /* cycles per timer tick */
    uint8_t pwm_have_rise;
    uint8_t pwm_have_fall;
    int pwm_last_duty; /* the previous period's duty, -1: none */
    uint64_t pwm_rise;
    uint64_t pwm_fall;
    uint64_t pwm_last_at; /* start of the previous period */
    uint64_t pwm_edge;    /* the last edge: a level held longer is duty 0 or 255 */
    int emitted_mode; /* -1: nothing reported yet */
    unsigned emitted_value;
} pd_pin_t;

typedef struct {
    pd_pin_t pin[PD_PINS_COUNT];
    double cycles_per_us;
    uint64_t max_pulse;  /* longer highs are digital levels */
    uint64_t max_period; /* pulses further apart are not one servo signal */
    uint64_t low_wait;   /* how long an output low waits for a first pulse */
    uint64_t pwm_steady; /* a PWM pin without an edge this long is at duty 0 or 255 */
    pd_pins_emit_fn emit;
    void *ctx;
} pd_pins_t;

void pd_pins_init(pd_pins_t *pins, uint32_t frequency, pd_pins_emit_fn emit, void *ctx);

/* A possible change of one pin: is_output = DDR bit, level = the level driven
 * (the PORT bit, or the timer's compare output while it is connected),
 * pwm_tick = 0, or the cycles per tick of the pin's timer while the pin makes
 * PWM (the firmware's PWM driver runs it; for a program that does not say,
 * while its timer runs in a PWM mode), or PD_PINS_PWM_LEVEL; servo = 1 while a channel of the firmware's servo table
 * drives the pin, 0 while none does, -1 when the program has no servo table
 * the runner can read (its waveform decides). */
void pd_pins_sample(pd_pins_t *pins, int pin, int is_output, int port_bit, uint32_t pwm_tick,
                    int servo, uint64_t cycle);

/* The MCU resets at `cycle` (every pin becomes an input): each pin that has a line gets a
 * value-0 line in its mode, even if its value was 0 already, and then has no mode, as
 * the native board releases its pins on a reboot; its next line starts afresh. */
void pd_pins_reset(pd_pins_t *pins, uint64_t cycle);

/* Resolves the deadlines that have passed at `cycle`. */
void pd_pins_poll(pd_pins_t *pins, uint64_t cycle);

#endif

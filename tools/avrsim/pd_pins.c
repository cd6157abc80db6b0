/*
 * pd_pins.c: turn pin activity into servo pulse widths, digital levels and PWM duties.
 *
 * The rules, all in emulated time (the numbers are pd_pins.h's PD_PINS_*_US):
 * - A level is the pin's output state (DDR and PORT bits both set). The
 *   runner samples on every register write; a sample equal to the previous
 *   level is ignored. This is what makes the measurement immune to
 *   simavr 1.6 re-raising every output pin of a port whenever any bit of
 *   that port is written: a re-raise never changes the level.
 * - The mode is what the firmware configured (the runner reads it): an output
 *   that no servo channel drives and the PWM driver does not run is digital,
 *   and every change of its level, or its turning output, is a line at the
 *   cycle it happened (a 1 kHz square wave shows every edge), as the native
 *   board writes every digital write. A pin a servo channel drives gets the
 *   servo rules below, with no guess: its first pulse's width is reported
 *   after the next pulse, and a channel detached (none drives the pin any
 *   more) is a value-0 line, dated to the end of its last pulse, as soon as
 *   the runner sees it (the pin, left an output low, adds no digital line).
 * - The rest of this list up to PWM is how a servo's width is measured, and
 *   for a program with no servo table the runner can read (servo = -1: the
 *   runner's test program, StandardFirmata), the guess that tells a servo from
 *   a digital pin by its waveform:
 * - A high that ends within max_pulse (3 ms) is a pulse; one that lasts
 *   longer is a digital 1, reported at the time it rose.
 * - Pulses whose rising edges are at most max_period (50 ms) apart make a
 *   servo signal. An isolated pulse is reported as a digital 1 then 0.
 * - A servo's value is the width of its pulses in microseconds. A pulse that
 *   differs from the reported width by HYST_US or more, or rounds to another
 *   whole microsecond, becomes a candidate: if the next pulse is back at the
 *   reported width, the candidate was an interrupt-latency outlier and is
 *   dropped; otherwise it is reported, with the time of its own rising edge
 *   (so a change is dated to its first pulse even though the line is written
 *   one frame later). The rounding counts too because a change is reported
 *   from its first pulse: when interrupt latency stretched that one by less
 *   than HYST_US across a whole microsecond, the true pulses after it (two in
 *   a row) correct the value, which would otherwise stay 1 us off for good.
 * - A servo whose pulses stop for more than max_period gets a value-0 line,
 *   dated to the end of its last pulse (as the native board writes 0 when
 *   its pulses stop on a reboot).
 * - A pin that stops being an output (a release) reports value 0 at once. A
 *   reset (pd_pins_reset) gives every pin with a line a value-0 line, and no
 *   mode until its next one, as the native board's reboot does.
 * - A pin that becomes an output at level 0 and shows no pulse within
 *   low_wait (50 ms) is a digital 0. A Servo-library style driver starts a
 *   newly attached channel at the frame after next, up to two 20 ms frames
 *   after the pin became an output.
 * - PWM: an output the firmware's PWM driver runs (the runner reads it; for a
 *   program that does not say, an output whose timer runs in a PWM mode) is a
 *   PWM pin. Its value is the duty 0..255 = round(255 * high / period), measured
 *   from rising edge to rising edge in whole ticks of the timer (the
 *   waveform's own resolution: simavr's compare events land a few cycles
 *   either side of the tick, and a duty such as 129/256 = 128.496/255 would
 *   otherwise flicker between two values), reported once two periods in a row agree
 *   (a period cut by a duty change is dropped) and dated to the first of
 *   them. A PWM pin with no edge for pwm_steady (5 ms) is at duty 0 or 255:
 *   like Arduino's analogWrite, firmware disconnects the timer from the pin
 *   for those two values (the hardware cannot make them in fast PWM) and
 *   drives the level, and a steady level is all a pin can show of them.
 *   When the firmware says it drives such a level (its PWM driver runs the
 *   pin, and the timer is disconnected from it: pwm_tick PD_PINS_PWM_LEVEL),
 *   that duty is a line at once, however briefly it is held.
 */
#include "pd_pins.h"

#include <math.h>
#include <string.h>

static void pd_emit(pd_pins_t *pins, int n, uint64_t cycle, enum pd_pin_mode mode,
                    unsigned value)
{
    pd_pin_t *p = &pins->pin[n];
    if (p->emitted_mode == (int)mode && p->emitted_value == value) {
        return;
    }
    p->emitted_mode = (int)mode;
    p->emitted_value = value;
    pins->emit(pins->ctx, cycle, n, mode, value);
}

static double pd_width_us(const pd_pins_t *pins, uint64_t rise, uint64_t fall)
{
    return (double)(fall - rise) / pins->cycles_per_us;
}

static void pd_emit_servo(pd_pins_t *pins, int n, uint64_t cycle, double us)
{
    pins->pin[n].servo_us = us;
    pd_emit(pins, n, cycle, PD_PIN_MODE_SERVO, (unsigned)lround(us));
}

/* A pulse of width `us` is not the reported width (see the servo rules above). */
static int pd_servo_differs(const pd_pin_t *p, double us)
{
    return fabs(us - p->servo_us) >= PD_PINS_HYST_US || lround(us) != lround(p->servo_us);
}

static void pd_set_cand(pd_pin_t *p, uint64_t rise, uint64_t fall, double us)
{
    p->cand = 1;
    p->cand_rise = rise;
    p->cand_fall = fall;
    p->cand_us = us;
}

/* An isolated pulse on a pin that carries no servo: a quick digital 1 then 0. */
static void pd_cand_as_digital(pd_pins_t *pins, int n)
{
    pd_pin_t *p = &pins->pin[n];
    p->cand = 0;
    pd_emit(pins, n, p->cand_rise, PD_PIN_MODE_DIGITAL, 1);
    pd_emit(pins, n, p->cand_fall, PD_PIN_MODE_DIGITAL, 0);
}

static void pd_servo_stopped(pd_pins_t *pins, int n, uint64_t cycle)
{
    pd_pin_t *p = &pins->pin[n];
    p->servo = 0;
    p->cand = 0;
    pd_emit(pins, n, cycle, PD_PIN_MODE_SERVO, 0);
}

static void pd_pulse(pd_pins_t *pins, int n, uint64_t rise, uint64_t fall)
{
    pd_pin_t *p = &pins->pin[n];
    double us = pd_width_us(pins, rise, fall);

    if (!p->servo) {
        if (p->cand && rise - p->cand_rise <= pins->max_period) {
            /* Two pulses close together: this pin carries a servo. */
            p->servo = 1;
            p->cand = 0;
            pd_emit_servo(pins, n, p->cand_rise, p->cand_us);
            if (pd_servo_differs(p, us)) {
                pd_set_cand(p, rise, fall, us);
            }
        } else {
            if (p->cand) {
                pd_cand_as_digital(pins, n);
            }
            pd_set_cand(p, rise, fall, us);
        }
    } else if (p->cand) {
        if (!pd_servo_differs(p, us)) {
            p->cand = 0; /* the candidate was an outlier */
        } else {
            p->cand = 0;
            pd_emit_servo(pins, n, p->cand_rise, p->cand_us);
            if (pd_servo_differs(p, us)) {
                pd_set_cand(p, rise, fall, us);
            }
        }
    } else if (pd_servo_differs(p, us)) {
        pd_set_cand(p, rise, fall, us);
    }
    p->last_rise = rise;
    p->last_fall = fall;
}

/* A high that lasted longer than any pulse: a digital 1 since it rose. */
static void pd_long_high(pd_pins_t *pins, int n)
{
    pd_pin_t *p = &pins->pin[n];
    p->high_pending = 0;
    if (p->servo) {
        pd_servo_stopped(pins, n, p->last_fall);
    } else if (p->cand) {
        pd_cand_as_digital(pins, n);
    }
    pd_emit(pins, n, p->rise, PD_PIN_MODE_DIGITAL, 1);
}

static void pd_pwm_restart(pd_pin_t *p, uint64_t cycle)
{
    p->pwm_have_rise = 0;
    p->pwm_have_fall = 0;
    p->pwm_last_duty = -1;
    p->pwm_edge = cycle;
}

/* One period measured: reported when the previous one agrees. */
static void pd_pwm_period(pd_pins_t *pins, int n, uint64_t rise, uint64_t fall, uint64_t next)
{
    pd_pin_t *p = &pins->pin[n];
    uint64_t tick = p->pwm_tick ? p->pwm_tick : 1U;
    uint64_t high = (fall - rise + tick / 2U) / tick;
    uint64_t period = (next - rise + tick / 2U) / tick;
    int duty = period ? (int)lround(255.0 * (double)high / (double)period) : 0;
    if (duty == p->pwm_last_duty) {
        pd_emit(pins, n, p->pwm_last_at, PD_PIN_MODE_PWM, (unsigned)duty);
    }
    p->pwm_last_duty = duty;
    p->pwm_last_at = rise;
}

/* A sample of a pin that carries PWM. */
static void pd_pwm_sample(pd_pins_t *pins, int n, uint8_t level, uint64_t cycle)
{
    pd_pin_t *p = &pins->pin[n];
    if (!p->pwm) {
        /* Whatever the pin did before (a level, pulses) ends here. */
        p->pwm = 1;
        p->servo = 0;
        p->cand = 0;
        p->high_pending = 0;
        p->low_out_pending = 0;
        p->level = level;
        pd_pwm_restart(p, cycle);
        return;
    }
    if (level == p->level) {
        return;
    }
    p->level = level;
    p->pwm_edge = cycle;
    if (level) {
        if (p->pwm_have_rise && p->pwm_have_fall) {
            pd_pwm_period(pins, n, p->pwm_rise, p->pwm_fall, cycle);
        }
        p->pwm_rise = cycle;
        p->pwm_have_rise = 1;
        p->pwm_have_fall = 0;
    } else if (p->pwm_have_rise) {
        p->pwm_fall = cycle;
        p->pwm_have_fall = 1;
    }
}

void pd_pins_init(pd_pins_t *pins, uint32_t frequency, pd_pins_emit_fn emit, void *ctx)
{
    memset(pins, 0, sizeof *pins);
    pins->cycles_per_us = (double)frequency / 1e6;
    pins->max_pulse = (uint64_t)frequency * PD_PINS_MAX_PULSE_US / 1000000U;
    pins->max_period = (uint64_t)frequency * PD_PINS_MAX_PERIOD_US / 1000000U;
    pins->low_wait = (uint64_t)frequency * PD_PINS_LOW_WAIT_US / 1000000U;
    pins->pwm_steady = (uint64_t)frequency * PD_PINS_PWM_STEADY_US / 1000000U;
    pins->emit = emit;
    pins->ctx = ctx;
    for (int n = 0; n < PD_PINS_COUNT; n++) {
        pins->pin[n].emitted_mode = -1;
    }
}

/*
 * The firmware's servo table says whether a channel drives the pin (servo 0 or 1):
 * true when the sample is done here, as a digital pin's is, false when a servo's
 * pulses go on to be measured. A pulse under way when its channel was detached
 * ends as that servo's (its channel started it).
 */
static int pd_configured_sample(pd_pins_t *pins, int n, uint8_t output, uint8_t level, int servo,
                                uint64_t cycle)
{
    pd_pin_t *p = &pins->pin[n];
    if (servo && !p->servo) {
        /* Attached: its lines come with its pulses; whatever it reported before is
         * no width of this servo's. */
        p->servo = 1;
        p->cand = 0;
        p->servo_us = -1.0;
        p->last_rise = cycle;
        p->last_fall = cycle;
    } else if (!servo && p->servo && !p->high_pending) {
        p->servo = 0;
        p->cand = 0;
        if (p->emitted_mode == PD_PIN_MODE_SERVO) {
            pd_emit(pins, n, p->last_fall, PD_PIN_MODE_SERVO, 0);
        }
    }
    p->low_out_pending = 0;
    if (p->servo) {
        return 0;
    }
    /* What shows at the pin: a level change, or the pin turning output. A servo's pin
     * stays an output low when its channel is detached: its value-0 line says so. */
    if (output && (!p->output || level != p->level || p->emitted_mode < 0)) {
        pd_emit(pins, n, cycle, PD_PIN_MODE_DIGITAL, level);
    }
    p->output = output;
    p->level = level;
    return 1;
}

void pd_pins_sample(pd_pins_t *pins, int n, int is_output, int port_bit, uint32_t pwm_tick,
                    int servo, uint64_t cycle)
{
    if (n < 0 || n >= PD_PINS_COUNT) {
        return;
    }
    pd_pin_t *p = &pins->pin[n];
    uint8_t output = is_output ? 1U : 0U;
    uint8_t level = (output && port_bit) ? 1U : 0U;

    if (!output && p->output) {
        /* Released: a reset makes every pin an input, and whatever the pin
         * carried stops at once. Report it now, as the native board reports a
         * reboot, rather than after 50 ms without pulses: a host that restores
         * its outputs sooner than that would otherwise leave no trace of the
         * reset at all. */
        p->output = 0;
        p->level = 0;
        p->pwm = 0;
        p->high_pending = 0;
        p->low_out_pending = 0;
        if (p->servo) {
            pd_servo_stopped(pins, n, cycle);
        } else {
            p->cand = 0;
            if (p->emitted_mode >= 0) {
                pd_emit(pins, n, cycle, (enum pd_pin_mode)p->emitted_mode, 0);
            }
        }
        return;
    }
    if (output && pwm_tick == PD_PINS_PWM_LEVEL) {
        /* The PWM driver holds a steady level (duty 0 or 255): that duty, at once. */
        if (!p->pwm) {
            pd_pwm_sample(pins, n, level, cycle);
        }
        p->output = 1;
        p->level = level;
        pd_pwm_restart(p, cycle);
        pd_emit(pins, n, cycle, PD_PIN_MODE_PWM, level ? 255U : 0U);
        return;
    }
    if (output && pwm_tick) {
        p->output = 1;
        p->pwm_tick = pwm_tick;
        pd_pwm_sample(pins, n, level, cycle);
        return;
    }
    if (p->pwm) {
        /* The timer left its PWM mode: the pin is an ordinary output again. */
        p->pwm = 0;
        p->low_out_pending = 0;
    }
    if (servo >= 0 && pd_configured_sample(pins, n, output, level, servo, cycle)) {
        return;
    }
    if (output && !p->output && !level) {
        p->low_out_pending = 1;
        p->out_since = cycle;
    } else if (!output) {
        p->low_out_pending = 0;
    }
    p->output = output;
    if (level == p->level) {
        return; /* a re-raise of the same level (simavr) or a pull-up change */
    }
    p->level = level;
    if (level) {
        p->low_out_pending = 0;
        p->high_pending = 1;
        p->rise = cycle;
    } else if (p->high_pending && cycle - p->rise <= pins->max_pulse) {
        p->high_pending = 0;
        pd_pulse(pins, n, p->rise, cycle);
    } else {
        if (p->high_pending) {
            pd_long_high(pins, n);
        }
        pd_emit(pins, n, cycle, PD_PIN_MODE_DIGITAL, 0);
    }
}

void pd_pins_reset(pd_pins_t *pins, uint64_t cycle)
{
    if (!pins->emit) {
        return; /* not initialised yet */
    }
    for (int n = 0; n < PD_PINS_COUNT; n++) {
        pd_pin_t *p = &pins->pin[n];
        if (p->emitted_mode >= 0) {
            pins->emit(pins->ctx, cycle, n, (enum pd_pin_mode)p->emitted_mode, 0);
        }
        memset(p, 0, sizeof *p);
        p->emitted_mode = -1;
    }
}

void pd_pins_poll(pd_pins_t *pins, uint64_t cycle)
{
    for (int n = 0; n < PD_PINS_COUNT; n++) {
        pd_pin_t *p = &pins->pin[n];
        if (p->pwm) {
            if (cycle - p->pwm_edge > pins->pwm_steady) {
                pd_emit(pins, n, p->pwm_edge, PD_PIN_MODE_PWM, p->level ? 255U : 0U);
                pd_pwm_restart(p, p->pwm_edge);
            }
            continue;
        }
        if (p->high_pending && cycle - p->rise > pins->max_pulse) {
            pd_long_high(pins, n);
        }
        if (p->high_pending) {
            continue;
        }
        if (p->servo && cycle - p->last_rise > pins->max_period) {
            pd_servo_stopped(pins, n, p->last_fall);
        }
        if (!p->servo && p->cand && cycle - p->cand_rise > pins->max_period) {
            pd_cand_as_digital(pins, n);
        }
        if (p->low_out_pending && !p->servo && !p->cand &&
            cycle - p->out_since > pins->low_wait) {
            p->low_out_pending = 0;
            pd_emit(pins, n, p->out_since, PD_PIN_MODE_DIGITAL, 0);
        }
    }
}

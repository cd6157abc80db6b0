#include "pd_outputs.h"

#include <stddef.h>
#include <string.h>

#include "pd_protocol.h"
#include "pd_user.h"

/* The digital masks hold one bit per pin; a slot fits the owner byte's low nibble. */
typedef char pd_assert_pins_fit_mask[(PD_MAX_PINS <= 32) ? 1 : -1];
typedef char pd_assert_servos_fit_slot[(PD_MAX_SERVOS <= PD_MAX_SLOTS) ? 1 : -1];
/* Every PWM output's duty fits OutputStates.pwm_duties. */
typedef char pd_assert_pwm_fit_read[(PD_MAX_PWM <= sizeof(((protoduino_OutputStates *)0)->pwm_duties)) ? 1 : -1];
/* A servo's settings (min_us .. step) are compared as bytes: no padding among them. */
#define PD_SERVO_SETTINGS (offsetof(pd_servo_t, step) + 1u)
typedef char pd_assert_servo_settings_packed[(PD_SERVO_SETTINGS == 7) ? 1 : -1];
static uint8_t servo_slots(void *hal)
{
    uint8_t n = pd_hal_board_info(hal)->max_servos;
    return n < PD_MAX_SERVOS ? n : PD_MAX_SERVOS;
}

static void drive_servo(pd_outputs_t *out, void *hal, uint8_t channel, uint8_t pin, uint16_t us)
{
    pd_servo_t *s = &out->servo[channel];
    if (us == PD_SERVO_SAFE_DETACH) { /* no pulses: at once, whatever the speed limit */
        s->us = s->target_us = us;
        pd_hal_servo_detach(hal, channel, pin);
        return;
    }
    s->target_us = us;
    /* No speed limit, or limp (no known position to move from): there at once;
     * else pd_outputs_step moves it. */
    if (s->step == 0 || s->us == PD_SERVO_SAFE_DETACH) {
        s->us = us;
        pd_hal_servo_write(hal, channel, pin, us);
    }
}

/* A pin's bit in a mask set to `on`; not inlined: the level's and the safe
 * value's updates share it. */
static __attribute__((noinline)) void put_bit(uint32_t *mask, uint8_t pin, bool on)
{
    uint32_t bit = 1UL << pin;
    *mask = on ? (*mask | bit) : (*mask & ~bit);
}

/* Not inlined at its three callers (Control, Init, safe value): 58 B of the
 * Uno's flash for one call per digital write. */
static __attribute__((noinline)) void drive_digital(pd_outputs_t *out, void *hal, uint8_t pin,
                                                    bool level)
{
    put_bit(&out->digital_level, pin, level);
    pd_hal_digital_write(hal, pin, level);
}

static void servo_safe(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    drive_servo(out, hal, slot, pin, out->servo[slot].safe_us);
}

static void digital_safe(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    (void)slot;
    drive_digital(out, hal, pin, (out->digital_safe >> pin) & 1u);
}

static void drive_pwm(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot, uint8_t duty)
{
    out->pwm[slot].duty = duty;
    pd_hal_pwm_write(hal, pin, duty);
}

static void pwm_safe(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    drive_pwm(out, hal, pin, slot, out->pwm[slot].safe);
}

static void pwm_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    (void)out;
    (void)slot;
    pd_hal_pwm_release(hal, pin);
}

/* Inputs have no safe value (the failsafe leaves them reading); released, the
 * pin is an input without pull-up, as at power-up (pd_inputs.c). */
static void input_safe(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    (void)out;
    (void)hal;
    (void)pin;
    (void)slot;
}

static void dinput_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    pd_inputs_release(out, hal, pin, PD_MODE_DIGITAL_INPUT, slot);
}

static void ainput_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    pd_inputs_release(out, hal, pin, PD_MODE_ANALOG_INPUT, slot);
}

static void counter_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    pd_inputs_release(out, hal, pin, PD_MODE_COUNTER, slot);
}

static void servo_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    pd_servo_t *s = &out->servo[slot];
    s->us = s->target_us = 0; /* a free channel is all zero: pd_outputs_step skips it */
    s->step = 0;
    pd_hal_servo_detach(hal, slot, pin);
}

static void digital_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    /* Its bits in digital_safe/digital_level are stale from here on, and unread:
     * both are read only for pins the digital mode owns, and a DigitalInit sets
     * the safe bit and drives the level before anything reads them. */
    (void)out;
    (void)slot;
    pd_hal_digital_release(hal, pin);
}

/*
 * The pin-mode table: one entry per PD_MODE_x but PD_MODE_FREE (which owns no pin),
 *   X(mode, safe, release)
 *   safe:    safe(out, hal, pin, slot), drive one of its pins to the safe value
 *            given at its Init;
 *   release: release(out, hal, pin, slot), let go of one of its pins (the owner
 *            table is cleared by the caller).
 *
 * Why an X-macro expanded into switches and not an array of structs of function
 * pointers in flash: the array (read with memcpy_P, called through pointers) cost
 * 90 B more of the Uno's flash, for the same reason as the command table
 * (pd_dispatch.c): the compiler cannot inline through a pointer.
 */
#define PD_MODES(X)                                                          \
    X(PD_MODE_DIGITAL, digital_safe, digital_release)                        \
    X(PD_MODE_SERVO, servo_safe, servo_release)                              \
    X(PD_MODE_PWM, pwm_safe, pwm_release)                                    \
    X(PD_MODE_DIGITAL_INPUT, input_safe, dinput_release)                     \
    X(PD_MODE_ANALOG_INPUT, input_safe, ainput_release)                      \
    X(PD_MODE_COUNTER, input_safe, counter_release)                          \
    PD_MODES_USER(X)

/* A user service's pins (pd_user.h), by pin, like digital outputs. */
#if PD_FEATURE_USER
static void user_safe(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    (void)slot;
    pd_user_pin_safe(out->core, hal, pin);
}

static void user_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    (void)slot;
    pd_user_pin_release(out->core, out->owner, hal, pin);
}
#define PD_MODES_USER(X) X(PD_MODE_USER, user_safe, user_release)
#else
#define PD_MODES_USER(X)
#endif

#define PD_MODE_ONE(mode, safe_, release_) +1
typedef char pd_assert_every_mode_listed[(0 PD_MODES(PD_MODE_ONE)) == PD_MODE_COUNT - 1 ? 1 : -1];
#undef PD_MODE_ONE

static void mode_safe(uint8_t mode, pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    switch (mode) {
#define PD_MODE_SAFE(mode_, safe_, release_)                                 \
    case mode_:                                                              \
        safe_(out, hal, pin, slot);                                          \
        break;
        PD_MODES(PD_MODE_SAFE)
#undef PD_MODE_SAFE
    default:
        break;
    }
}

static void mode_release(uint8_t mode, pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    switch (mode) {
#define PD_MODE_RELEASE(mode_, safe_, release_)                              \
    case mode_:                                                              \
        release_(out, hal, pin, slot);                                       \
        break;
        PD_MODES(PD_MODE_RELEASE)
#undef PD_MODE_RELEASE
    default:
        break;
    }
}

void pd_outputs_init(pd_outputs_t *out)
{
    memset(out, 0, sizeof(*out));
    pd_inputs_init(&out->inputs);
}

/*
 * min + degrees * range / 180, rounded down, in 16-bit arithmetic: the product
 * reaches 180 * 2200 and would need a 32-bit multiply and divide (libgcc's
 * __udivmodsi4, about 600 cycles per servo write on the Uno). With range =
 * 180 q + r, degrees * range / 180 = degrees * q + degrees * r / 180 exactly,
 * and degrees * r < 180 * 180 fits. The callers have checked degrees <= 180.
 * Not inlined: the Init's and the Control's copies cost 20 B more.
 */
static __attribute__((noinline)) uint16_t degrees_to_us(const pd_servo_t *s, uint16_t degrees)
{
    typedef char fits[((PD_SERVO_LIMIT_MAX_US - PD_SERVO_LIMIT_MIN_US) / 180u *
                           PD_SERVO_MAX_DEGREES + PD_SERVO_LIMIT_MAX_US <= 0xFFFFu &&
                       PD_SERVO_LIMIT_MAX_US - PD_SERVO_LIMIT_MIN_US < 180u * 180u &&
                       PD_SERVO_MAX_DEGREES <= 180u) ? 1 : -1];
    (void)sizeof(fits);
    uint16_t range = (uint16_t)(s->max_us - s->min_us);
    uint16_t q = pd_div180(range);
    uint16_t r = (uint16_t)(range - q * 180u);
    return (uint16_t)(s->min_us + degrees * q + pd_div180((uint16_t)(degrees * r)));
}

bool pd_outputs_timer_pwm(const pd_outputs_t *out, void *hal)
{
    uint32_t pins = pd_hal_board_info(hal)->servo_timer_pins;
    for (uint8_t pin = 0; pins != 0; pin++, pins >>= 1) {
        if ((pins & 1u) && PD_OWNER_MODE(out->owner[pin]) == PD_MODE_PWM &&
            out->owner[pin] != 0) {
            return true;
        }
    }
    return false;
}

/* Not inlined (into respond(), its only caller): 58 B less of the Uno's flash
 * out of line; a ServoInit is not on the write path. */
__attribute__((noinline)) protoduino_Status
pd_outputs_servo_init(pd_outputs_t *out, void *hal, const protoduino_ServoInit *msg)
{
    protoduino_Status status = pd_pins_check(hal, msg->pin);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    uint32_t min_us = msg->min_us ? msg->min_us : PD_SERVO_DEFAULT_MIN_US;
    uint32_t max_us = msg->max_us ? msg->max_us : PD_SERVO_DEFAULT_MAX_US;
    if (min_us < PD_SERVO_LIMIT_MIN_US || max_us > PD_SERVO_LIMIT_MAX_US || min_us >= max_us) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }
    if (msg->max_speed > PD_SERVO_MAX_SPEED) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }
    pd_servo_t limits = {(uint16_t)min_us, (uint16_t)max_us, 0, 0, 0, 0};
    if (msg->which_safe == protoduino_ServoInit_safe_degrees_tag) {
        if (msg->safe.safe_degrees > PD_SERVO_MAX_DEGREES) {
            return protoduino_Status_STATUS_OUT_OF_RANGE;
        }
        limits.safe_us = degrees_to_us(&limits, (uint16_t)msg->safe.safe_degrees);
    } else if (msg->which_safe == protoduino_ServoInit_safe_us_tag) {
        if (msg->safe.safe_us < min_us || msg->safe.safe_us > max_us) {
            return protoduino_Status_STATUS_OUT_OF_RANGE;
        }
        limits.safe_us = (uint16_t)msg->safe.safe_us;
    } else if (msg->which_safe == protoduino_ServoInit_safe_detach_tag && msg->safe.safe_detach) {
        limits.safe_us = PD_SERVO_SAFE_DETACH;
    } else {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }

    /* The speed limit rounds to whole us per frame, at least 1. 16-bit division
     * (max_speed <= PD_SERVO_MAX_SPEED was checked): no 32-bit divide in flash. */
    typedef char speed_fits[(PD_SERVO_MAX_SPEED + 25u <= 0xFFFFu) ? 1 : -1];
    (void)sizeof(speed_fits);
    uint16_t step = (uint16_t)((uint16_t)(msg->max_speed + 25u) / 50u);
    step = msg->max_speed && step == 0 ? 1u : step;

    if (pd_outputs_timer_pwm(out, hal)) {
        return protoduino_Status_STATUS_TIMER_IN_USE; /* the servos' timer makes PWM */
    }
    uint8_t was = out->owner[msg->pin];
    uint8_t channel;
    status = pd_pins_claim(out->owner, hal, msg->pin, PD_MODE_SERVO, servo_slots(hal), &channel);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    limits.step = (uint8_t)step;
    pd_servo_t *now = &out->servo[channel];
    if (was != 0 && memcmp(now, &limits, PD_SERVO_SETTINGS) == 0) {
        /* The same configuration again (a CLI one-shot, a resumed session): the
         * pin keeps what it does, no detour through the safe value. */
        return protoduino_Status_STATUS_OK;
    }
    limits.step = 0; /* an Init jumps to its safe value, limited or not */
    *now = limits;
    drive_servo(out, hal, channel, (uint8_t)msg->pin, limits.safe_us);
    now->step = (uint8_t)step;
    return protoduino_Status_STATUS_OK;
}

/*
 * A ServoControl: checked, then (if `apply`) driven. Not inlined, here and in
 * digital_control: the Control and the Pose share one copy (118 B on the Uno).
 */
static __attribute__((noinline)) protoduino_Status
servo_control(pd_outputs_t *out, void *hal, const protoduino_ServoControl *msg, bool apply)
{
    uint8_t channel;
    protoduino_Status status = pd_pins_owned(out->owner, hal, msg->pin, PD_MODE_SERVO, &channel);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    const pd_servo_t *s = &out->servo[channel];
    uint16_t us;
    if (msg->which_value == protoduino_ServoControl_degrees_tag) {
        if (msg->value.degrees > PD_SERVO_MAX_DEGREES) {
            return protoduino_Status_STATUS_OUT_OF_RANGE;
        }
        us = degrees_to_us(s, (uint16_t)msg->value.degrees);
    } else if (msg->which_value == protoduino_ServoControl_us_tag) {
        /* Refused rather than clamped: a clamped value would be a silent lie. */
        if (msg->value.us < s->min_us || msg->value.us > s->max_us) {
            return protoduino_Status_STATUS_OUT_OF_RANGE;
        }
        us = (uint16_t)msg->value.us;
    } else {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }
    if (apply) {
        drive_servo(out, hal, channel, (uint8_t)msg->pin, us);
    }
    return protoduino_Status_STATUS_OK;
}

protoduino_Status pd_outputs_servo_control(pd_outputs_t *out, void *hal,
                                           const protoduino_ServoControl *msg)
{
    return servo_control(out, hal, msg, true);
}

/* A DigitalControl: checked, then (if `apply`) driven. */
static __attribute__((noinline)) protoduino_Status
digital_control(pd_outputs_t *out, void *hal, const protoduino_DigitalControl *msg, bool apply)
{
    uint8_t slot;
    protoduino_Status status = pd_pins_owned(out->owner, hal, msg->pin, PD_MODE_DIGITAL, &slot);
    if (status == protoduino_Status_STATUS_OK && apply) {
        drive_digital(out, hal, (uint8_t)msg->pin, msg->level);
    }
    return status;
}

protoduino_Status pd_outputs_digital_control(pd_outputs_t *out, void *hal,
                                             const protoduino_DigitalControl *msg)
{
    return digital_control(out, hal, msg, true);
}

protoduino_Status pd_outputs_pwm_init(pd_outputs_t *out, void *hal, const protoduino_PwmInit *msg)
{
    protoduino_Status status = pd_pins_check(hal, msg->pin);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    const pd_board_info_t *info = pd_hal_board_info(hal);
    uint8_t pin = (uint8_t)msg->pin;
    uint32_t bit = 1UL << pin;
    uint8_t was = out->owner[pin];
    if (info->clock_timer_pins & bit) {
        return protoduino_Status_STATUS_TIMER_IN_USE; /* its timer runs the clock */
    }
    if (!(info->pwm_pins & bit)) {
        return protoduino_Status_STATUS_NOT_SUPPORTED; /* no timer output there */
    }
    if (was != 0 && PD_OWNER_MODE(was) != PD_MODE_PWM) {
        return protoduino_Status_STATUS_PIN_IN_USE;
    }
    if ((info->servo_timer_pins & bit) && pd_pins_count(out->owner, PD_MODE_SERVO) > 0) {
        return protoduino_Status_STATUS_TIMER_IN_USE; /* its timer makes the servo pulses */
    }
    if (msg->safe_duty > 255u) {
        return protoduino_Status_STATUS_OUT_OF_RANGE;
    }
    uint8_t slot;
    status = pd_pins_claim(out->owner, hal, pin, PD_MODE_PWM, PD_MAX_PWM, &slot);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    pd_pwm_t *p = &out->pwm[slot];
    if (was != 0 && p->safe == msg->safe_duty) {
        return protoduino_Status_STATUS_OK; /* the same configuration: the duty stays */
    }
    p->safe = (uint8_t)msg->safe_duty;
    drive_pwm(out, hal, pin, slot, p->safe);
    return protoduino_Status_STATUS_OK;
}

/* A PwmControl: checked, then (if `apply`) driven. */
static __attribute__((noinline)) protoduino_Status
pwm_control(pd_outputs_t *out, void *hal, const protoduino_PwmControl *msg, bool apply)
{
    uint8_t slot;
    protoduino_Status status = pd_pins_owned(out->owner, hal, msg->pin, PD_MODE_PWM, &slot);
    if (status == protoduino_Status_STATUS_OK && msg->duty > 255u) {
        status = protoduino_Status_STATUS_OUT_OF_RANGE;
    }
    if (status == protoduino_Status_STATUS_OK && apply) {
        drive_pwm(out, hal, (uint8_t)msg->pin, slot, (uint8_t)msg->duty);
    }
    return status;
}

protoduino_Status pd_outputs_pwm_control(pd_outputs_t *out, void *hal,
                                         const protoduino_PwmControl *msg)
{
    return pwm_control(out, hal, msg, true);
}

/*
 * The apply pass of a Pose item (pd_outputs_pose): 1 a PWM duty of 0, 2 a digital level (the
 * masks' too), 3 any other duty and the servos. A motor driven through a direction pin and a
 * PWM pin (an H-bridge) is never driven the wrong way, whatever order the pose lists them
 * in: stopped before its direction pin changes, started only after it changed (issue 32).
 */
#define PD_POSE_ZERO_DUTIES 1u
#define PD_POSE_LEVELS 2u
#define PD_POSE_LAST 3u

static uint8_t pose_pass(const protoduino_PoseItem *item)
{
    if (item->which_output == protoduino_PoseItem_pwm_tag) {
        return item->output.pwm.duty == 0 ? PD_POSE_ZERO_DUTIES : PD_POSE_LAST;
    }
    return item->which_output == protoduino_PoseItem_digital_tag ? PD_POSE_LEVELS : PD_POSE_LAST;
}

protoduino_Status pd_outputs_pose(pd_outputs_t *out, void *hal, const protoduino_Pose *msg,
                                  uint8_t *bad)
{
    uint32_t seen = 0;

    *bad = 1;
    if (msg->items_count == 0 && msg->digital_pins == 0) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT; /* sets nothing */
    }
    *bad = 0;
    if (msg->digital_levels & ~msg->digital_pins) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT; /* a level for no pin: no output named */
    }
    /* Pass 0 checks every item, then every pin of the mask in ascending order (numbered
     * after the items); passes 1 to 3 apply them (pose_pass says which goes in which),
     * each in that order, the servos held, so that their new widths start at the same
     * frame. */
    for (uint8_t pass = 0; pass <= PD_POSE_LAST; pass++) {
        bool apply = pass != 0;
        uint8_t i = 0;
        for (; i < msg->items_count; i++) {
            const protoduino_PoseItem *item = &msg->items[i];
            protoduino_Status status = protoduino_Status_STATUS_INVALID_ARGUMENT;
            uint32_t pin = 0;
            if (apply && pose_pass(item) != pass) {
                continue;
            }
            /* A mode the build left out: not supported, as its Control would be. */
            if (item->which_output == protoduino_PoseItem_servo_tag) {
                status = PD_FEATURE_SERVO ? servo_control(out, hal, &item->output.servo, apply)
                                          : protoduino_Status_STATUS_NOT_SUPPORTED;
                pin = item->output.servo.pin;
            } else if (item->which_output == protoduino_PoseItem_digital_tag) {
                status = PD_FEATURE_DIGITAL_OUTPUT
                             ? digital_control(out, hal, &item->output.digital, apply)
                             : protoduino_Status_STATUS_NOT_SUPPORTED;
                pin = item->output.digital.pin;
            } else if (item->which_output == protoduino_PoseItem_pwm_tag) {
                status = PD_FEATURE_PWM ? pwm_control(out, hal, &item->output.pwm, apply)
                                        : protoduino_Status_STATUS_NOT_SUPPORTED;
                pin = item->output.pwm.pin;
            }
            if (pass == 0) {
                /* pin < PD_MAX_PINS <= 32 once the item is valid */
                if (status == protoduino_Status_STATUS_OK && ((seen >> pin) & 1u)) {
                    status = protoduino_Status_STATUS_INVALID_ARGUMENT; /* a pin twice */
                }
                if (status != protoduino_Status_STATUS_OK) {
                    *bad = (uint8_t)(i + 1u);
                    return status;
                }
                seen |= 1UL << pin;
            }
        }
        /* The masks, one pin a turn: each exactly as its DigitalControl. The masks
         * shift one place per pin (a variable 32-bit shift is a loop on the AVR);
         * at most 32 turns, and none past the highest pin set. */
        uint32_t pins = pass == 0 || pass == PD_POSE_LEVELS ? msg->digital_pins : 0u;
        uint32_t levels = msg->digital_levels;
        uint32_t bit = 1;
        for (uint8_t pin = 0; pins != 0; pin++, pins >>= 1, levels >>= 1, bit <<= 1) {
            if (!(pins & 1u)) {
                continue;
            }
            protoduino_DigitalControl control = {pin, (levels & 1u) != 0};
            protoduino_Status status = PD_FEATURE_DIGITAL_OUTPUT
                                           ? digital_control(out, hal, &control, apply)
                                           : protoduino_Status_STATUS_NOT_SUPPORTED;
            i++;
            if (pass == 0) {
                if (status == protoduino_Status_STATUS_OK && (seen & bit)) {
                    status = protoduino_Status_STATUS_INVALID_ARGUMENT; /* also an item */
                }
                if (status != protoduino_Status_STATUS_OK) {
                    *bad = i;
                    return status;
                }
            }
        }
        if (pass == 0 || pass == PD_POSE_LAST) {
            pd_hal_servo_hold(hal, pass == 0);
        }
    }
    return protoduino_Status_STATUS_OK;
}

void pd_outputs_read(const pd_outputs_t *out, protoduino_OutputStates *states)
{
    typedef char fits[(sizeof(states->servos.bytes) >= 5u * PD_MAX_SERVOS) ? 1 : -1];
    (void)sizeof(fits);
    uint8_t *b = states->servos.bytes;
    /* `bit` moves one place per pin: a variable 32-bit shift is a loop on the AVR. */
    uint32_t bit = 1;
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++, bit <<= 1) {
        uint8_t owner = out->owner[pin];
        if (owner == 0) {
            continue;
        }
        if (PD_OWNER_MODE(owner) == PD_MODE_SERVO) {
            const pd_servo_t *s = &out->servo[PD_OWNER_SLOT(owner)];
            *b++ = pin;
            *b++ = (uint8_t)s->us;
            *b++ = (uint8_t)(s->us >> 8);
            *b++ = (uint8_t)s->target_us;
            *b++ = (uint8_t)(s->target_us >> 8);
        } else if (PD_OWNER_MODE(owner) == PD_MODE_DIGITAL) {
            states->digital_pins |= bit;
        } else if (PD_OWNER_MODE(owner) == PD_MODE_PWM) {
            states->pwm_pins |= bit;
            states->pwm_duties[states->pwm_duties_count++] = out->pwm[PD_OWNER_SLOT(owner)].duty;
        }
    }
    states->servos.size = (pb_size_t)(b - states->servos.bytes);
    states->digital_levels = out->digital_level & states->digital_pins;
}

void pd_outputs_step(pd_outputs_t *out, void *hal, uint32_t now)
{
    /* One step per servo frame; a late call does not make up a missed one
     * (the speed is a limit: a busy loop may only make a move slower). */
    if ((uint32_t)(now - out->stepped_at) < PD_SERVO_FRAME_MS) {
        return;
    }
    out->stepped_at = now;
    pd_hal_servo_hold(hal, true); /* every moving servo steps at the same frame */
    for (uint8_t ch = 0; ch < PD_MAX_SERVOS; ch++) {
        pd_servo_t *s = &out->servo[ch];
        if (s->us == s->target_us) {
            continue; /* also every unused channel: all zero */
        }
        if (s->us < s->target_us) {
            s->us = s->target_us - s->us <= s->step ? s->target_us : s->us + s->step;
        } else {
            s->us = s->us - s->target_us <= s->step ? s->target_us : s->us - s->step;
        }
        uint8_t pin = 0; /* the channel's pin, from the owner table (moving: it has one) */
        while (pin < PD_MAX_PINS - 1u && out->owner[pin] != PD_OWNER(PD_MODE_SERVO, ch)) {
            pin++;
        }
        pd_hal_servo_write(hal, ch, pin, s->us);
    }
    pd_hal_servo_hold(hal, false);
}

protoduino_Status pd_outputs_digital_init(pd_outputs_t *out, void *hal,
                                          const protoduino_DigitalInit *msg)
{
    uint8_t slot;
    bool was = msg->pin < PD_MAX_PINS && out->owner[msg->pin] != 0;
    protoduino_Status status = pd_pins_claim(out->owner, hal, msg->pin, PD_MODE_DIGITAL, 0, &slot);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    uint8_t pin = (uint8_t)msg->pin;
    uint32_t bit = 1UL << pin;
    if (was && ((out->digital_safe & bit) != 0) == msg->safe_level) {
        return protoduino_Status_STATUS_OK; /* the same configuration: the level stays */
    }
    put_bit(&out->digital_safe, pin, msg->safe_level);
    drive_digital(out, hal, pin, msg->safe_level);
    return protoduino_Status_STATUS_OK;
}

/* Let go of an owned pin through its mode's release; the pin is free again. */
static void release_owned(pd_outputs_t *out, void *hal, uint8_t pin)
{
    uint8_t owner = out->owner[pin];
    mode_release(PD_OWNER_MODE(owner), out, hal, pin, PD_OWNER_SLOT(owner));
    out->owner[pin] = 0;
}

protoduino_Status pd_outputs_release(pd_outputs_t *out, void *hal, uint32_t pin)
{
    protoduino_Status status = pd_pins_check(hal, pin);
    if (status == protoduino_Status_STATUS_OK && out->owner[pin] == 0) {
        status = protoduino_Status_STATUS_NOT_INITIALISED;
    }
    if (status == protoduino_Status_STATUS_OK) {
        release_owned(out, hal, (uint8_t)pin);
    }
    return status;
}

void pd_outputs_release_all(pd_outputs_t *out, void *hal)
{
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        if (out->owner[pin] != 0) { /* an owned pin passed pd_pins_check when it was claimed */
            release_owned(out, hal, pin);
        }
    }
}

void pd_outputs_all_safe(pd_outputs_t *out, void *hal)
{
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t owner = out->owner[pin];
        if (owner != 0) {
            mode_safe(PD_OWNER_MODE(owner), out, hal, pin, PD_OWNER_SLOT(owner));
        }
    }
    pd_hal_outputs_safe(hal);
}

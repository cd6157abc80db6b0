/* Servos, one pin mode (pd_servo.h): limits, a safe width, speed limits stepped per frame. */
#include "pd_servo.h"

#include <stddef.h>
#include <string.h>

#include "pd_outputs.h"
#include "pd_protocol.h"

/* Built only with its feature (pd_features.h): without it, nothing here (its callers test
 * PD_FEATURE_SERVO too). */
#if PD_FEATURE_SERVO

/* A channel fits the owner byte's low nibble. */
typedef char pd_assert_servos_fit_slot[(PD_MAX_SERVOS <= PD_MAX_SLOTS) ? 1 : -1];
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

void pd_servo_safe(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    drive_servo(out, hal, slot, pin, out->servo[slot].safe_us);
}

void pd_servo_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    pd_servo_t *s = &out->servo[slot];
    s->us = s->target_us = 0; /* a free channel is all zero: pd_outputs_step skips it */
    s->step = 0;
    pd_hal_servo_detach(hal, slot, pin);
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

    if (PD_FEATURE_PWM && pd_outputs_timer_pwm(out, hal)) {
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
__attribute__((noinline)) protoduino_Status
pd_servo_control(pd_outputs_t *out, void *hal, const protoduino_ServoControl *msg, bool apply)
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
    return pd_servo_control(out, hal, msg, true);
}

void pd_outputs_step(pd_outputs_t *out, void *hal, uint32_t now)
{
    /* One step per servo frame; a late call does not make up a missed one
     * (the speed is a limit: a busy loop may only make a move slower). The
     * millisecond clock is not the frames' (on the Uno its ticks are 1,024 us,
     * and the loop calls late by its latency): two steps 20 of its ms apart
     * could fall between two frame starts, and one frame carried both (a jump
     * of twice the limit at the pin). So a step also waits for the last one to
     * have reached the pins, but never longer than a frame: a servo timer that
     * makes no frames (none attached to it) must not stop the others' moves. */
    uint32_t since = (uint32_t)(now - out->stepped_at);
    if (since < PD_SERVO_FRAME_MS ||
        (since < 2u * PD_SERVO_FRAME_MS && pd_hal_servo_pending(hal))) {
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

#endif /* PD_FEATURE_SERVO */

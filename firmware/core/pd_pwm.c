/* PWM outputs, one pin mode (pd_pwm.h): a duty and a safe duty per slot. */
#include "pd_pwm.h"

#include "pd_outputs.h"

/* Built only with its feature (pd_features.h): without it, nothing here (its callers test
 * PD_FEATURE_PWM too). */
#if PD_FEATURE_PWM

static void drive_pwm(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot, uint8_t duty)
{
    out->pwm[slot].duty = duty;
    pd_hal_pwm_write(hal, pin, duty);
}

void pd_pwm_safe(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    drive_pwm(out, hal, pin, slot, out->pwm[slot].safe);
}

void pd_pwm_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    (void)out;
    (void)slot;
    pd_hal_pwm_release(hal, pin);
}

bool pd_outputs_timer_pwm(const pd_outputs_t *out, void *hal)
{
    const pd_pinset_t *pins = &pd_hal_board_info(hal)->servo_timer_pins;
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        if (pd_pinset_has(pins, pin) && PD_OWNER_MODE(out->owner[pin]) == PD_MODE_PWM &&
            out->owner[pin] != 0) {
            return true;
        }
    }
    return false;
}

protoduino_Status pd_outputs_pwm_init(pd_outputs_t *out, void *hal, const protoduino_PwmInit *msg)
{
    protoduino_Status status = pd_pins_check(hal, msg->pin);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    const pd_board_info_t *info = pd_hal_board_info(hal);
    uint8_t pin = (uint8_t)msg->pin;
    uint8_t was = out->owner[pin];
    if (pd_pinset_has(&info->clock_timer_pins, pin)) {
        return protoduino_Status_STATUS_TIMER_IN_USE; /* its timer runs the clock */
    }
    if (!pd_pinset_has(&info->pwm_pins, pin)) {
        return protoduino_Status_STATUS_NOT_SUPPORTED; /* no timer output there */
    }
    if (was != 0 && PD_OWNER_MODE(was) != PD_MODE_PWM) {
        return protoduino_Status_STATUS_PIN_IN_USE;
    }
    if (pd_pinset_has(&info->servo_timer_pins, pin) && pd_pins_count(out->owner, PD_MODE_SERVO) > 0) {
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
__attribute__((noinline)) protoduino_Status
pd_pwm_control(pd_outputs_t *out, void *hal, const protoduino_PwmControl *msg, bool apply)
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
    return pd_pwm_control(out, hal, msg, true);
}

#endif /* PD_FEATURE_PWM */

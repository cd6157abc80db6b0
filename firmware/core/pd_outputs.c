#include "pd_outputs.h"

#include <string.h>

#include "pd_protocol.h"

/* The digital masks hold one bit per pin. */
typedef char pd_assert_pins_fit_mask[(PD_MAX_PINS <= 32) ? 1 : -1];
typedef char pd_assert_servos_fit_mode[(PD_MAX_SERVOS <= 250) ? 1 : -1];

void pd_outputs_init(pd_outputs_t *out)
{
    memset(out, 0, sizeof(*out));
}

/* Pin checks shared by every Init and Control, in the contract's order. */
static protoduino_Status check_pin(void *hal, uint32_t pin)
{
    const pd_board_info_t *info = pd_hal_board_info(hal);
    uint8_t num_pins = info->num_pins < PD_MAX_PINS ? info->num_pins : PD_MAX_PINS;

    if (pin >= num_pins) {
        return protoduino_Status_STATUS_INVALID_PIN;
    }
    if (info->reserved_pins & (1UL << pin)) {
        return protoduino_Status_STATUS_RESERVED_PIN;
    }
    return protoduino_Status_STATUS_OK;
}

static void drive_servo(pd_outputs_t *out, void *hal, uint8_t channel, uint16_t us)
{
    pd_hal_servo_write(hal, channel, out->servo[channel].pin, us);
}

static void drive_digital(pd_outputs_t *out, void *hal, uint8_t pin, bool level)
{
    uint32_t bit = 1UL << pin;
    out->digital_level = level ? (out->digital_level | bit) : (out->digital_level & ~bit);
    pd_hal_digital_write(hal, pin, level);
}

static uint16_t degrees_to_us(const pd_servo_t *s, uint32_t degrees)
{
    return (uint16_t)(s->min_us + degrees * (uint32_t)(s->max_us - s->min_us) / 180u);
}

protoduino_Status pd_outputs_servo_init(pd_outputs_t *out, void *hal,
                                        const protoduino_ServoInit *msg)
{
    protoduino_Status status = check_pin(hal, msg->pin);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    uint32_t min_us = msg->min_us ? msg->min_us : PD_SERVO_DEFAULT_MIN_US;
    uint32_t max_us = msg->max_us ? msg->max_us : PD_SERVO_DEFAULT_MAX_US;
    if (min_us < PD_SERVO_LIMIT_MIN_US || max_us > PD_SERVO_LIMIT_MAX_US || min_us >= max_us) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }
    pd_servo_t limits = {0, (uint16_t)min_us, (uint16_t)max_us, 0};
    if (msg->which_safe == protoduino_ServoInit_safe_degrees_tag) {
        if (msg->safe.safe_degrees > PD_SERVO_MAX_DEGREES) {
            return protoduino_Status_STATUS_OUT_OF_RANGE;
        }
        limits.safe_us = degrees_to_us(&limits, msg->safe.safe_degrees);
    } else if (msg->which_safe == protoduino_ServoInit_safe_us_tag) {
        if (msg->safe.safe_us < min_us || msg->safe.safe_us > max_us) {
            return protoduino_Status_STATUS_OUT_OF_RANGE;
        }
        limits.safe_us = (uint16_t)msg->safe.safe_us;
    } else {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }

    uint8_t pin = (uint8_t)msg->pin;
    uint8_t mode = out->pin_mode[pin];
    uint8_t channel;
    if (mode == PD_PIN_DIGITAL) {
        return protoduino_Status_STATUS_PIN_IN_USE;
    }
    if (mode >= PD_PIN_SERVO) {
        channel = (uint8_t)(mode - PD_PIN_SERVO); /* re-init: new limits, same slot */
    } else {
        uint8_t max_servos = pd_hal_board_info(hal)->max_servos;
        if (max_servos > PD_MAX_SERVOS) {
            max_servos = PD_MAX_SERVOS;
        }
        if (out->servo_count >= max_servos) {
            return protoduino_Status_STATUS_NO_FREE_RESOURCE;
        }
        channel = out->servo_count++;
        out->pin_mode[pin] = (uint8_t)(PD_PIN_SERVO + channel);
    }
    limits.pin = pin;
    out->servo[channel] = limits;
    drive_servo(out, hal, channel, limits.safe_us);
    return protoduino_Status_STATUS_OK;
}

protoduino_Status pd_outputs_servo_control(pd_outputs_t *out, void *hal,
                                           const protoduino_ServoControl *msg)
{
    protoduino_Status status = check_pin(hal, msg->pin);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    uint8_t mode = out->pin_mode[msg->pin];
    if (mode < PD_PIN_SERVO) {
        return protoduino_Status_STATUS_NOT_INITIALISED;
    }
    uint8_t channel = (uint8_t)(mode - PD_PIN_SERVO);
    const pd_servo_t *s = &out->servo[channel];
    uint16_t us;
    if (msg->which_value == protoduino_ServoControl_degrees_tag) {
        if (msg->value.degrees > PD_SERVO_MAX_DEGREES) {
            return protoduino_Status_STATUS_OUT_OF_RANGE;
        }
        us = degrees_to_us(s, msg->value.degrees);
    } else if (msg->which_value == protoduino_ServoControl_us_tag) {
        /* Refused rather than clamped: a clamped value would be a silent lie. */
        if (msg->value.us < s->min_us || msg->value.us > s->max_us) {
            return protoduino_Status_STATUS_OUT_OF_RANGE;
        }
        us = (uint16_t)msg->value.us;
    } else {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }
    drive_servo(out, hal, channel, us);
    return protoduino_Status_STATUS_OK;
}

protoduino_Status pd_outputs_digital_init(pd_outputs_t *out, void *hal,
                                          const protoduino_DigitalInit *msg)
{
    protoduino_Status status = check_pin(hal, msg->pin);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    uint8_t pin = (uint8_t)msg->pin;
    if (out->pin_mode[pin] >= PD_PIN_SERVO) {
        return protoduino_Status_STATUS_PIN_IN_USE;
    }
    uint32_t bit = 1UL << pin;
    out->pin_mode[pin] = PD_PIN_DIGITAL;
    out->digital_safe = msg->safe_level ? (out->digital_safe | bit) : (out->digital_safe & ~bit);
    drive_digital(out, hal, pin, msg->safe_level);
    return protoduino_Status_STATUS_OK;
}

protoduino_Status pd_outputs_digital_control(pd_outputs_t *out, void *hal,
                                             const protoduino_DigitalControl *msg)
{
    protoduino_Status status = check_pin(hal, msg->pin);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    if (out->pin_mode[msg->pin] != PD_PIN_DIGITAL) {
        return protoduino_Status_STATUS_NOT_INITIALISED;
    }
    drive_digital(out, hal, (uint8_t)msg->pin, msg->level);
    return protoduino_Status_STATUS_OK;
}

void pd_outputs_all_safe(pd_outputs_t *out, void *hal)
{
    for (uint8_t ch = 0; ch < out->servo_count; ch++) {
        drive_servo(out, hal, ch, out->servo[ch].safe_us);
    }
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        if (out->pin_mode[pin] == PD_PIN_DIGITAL) {
            drive_digital(out, hal, pin, (out->digital_safe >> pin) & 1u);
        }
    }
    pd_hal_outputs_safe(hal);
}

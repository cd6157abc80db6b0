/* Digital outputs, one pin mode (pd_digital.h): a level and a safe level by pin. */
#include "pd_digital.h"

#include "pd_outputs.h"

/* Built only with its feature (pd_features.h): without it, nothing here (its callers test
 * PD_FEATURE_DIGITAL_OUTPUT too). */
#if PD_FEATURE_DIGITAL_OUTPUT

/* A pin in a set or not; not inlined: the level's and the safe value's updates share it. */
static __attribute__((noinline)) void put_bit(pd_pinset_t *set, uint8_t pin, bool on)
{
    pd_pinset_put(set, pin, on);
}

/* Not inlined at its three callers (Control, Init, safe value): 58 B of the
 * Uno's flash for one call per digital write. */
static __attribute__((noinline)) void drive_digital(pd_outputs_t *out, void *hal, uint8_t pin,
                                                    bool level)
{
    put_bit(&out->digital_level, pin, level);
    pd_hal_digital_write(hal, pin, level);
}

void pd_digital_safe(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    (void)slot;
    drive_digital(out, hal, pin, pd_pinset_has(&out->digital_safe, pin));
}

void pd_digital_release(pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    /* Its bits in digital_safe/digital_level are stale from here on, and unread:
     * both are read only for pins the digital mode owns, and a DigitalInit sets
     * the safe bit and drives the level before anything reads them. */
    (void)out;
    (void)slot;
    pd_hal_digital_release(hal, pin);
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
    if (was && pd_pinset_has(&out->digital_safe, pin) == msg->safe_level) {
        return protoduino_Status_STATUS_OK; /* the same configuration: the level stays */
    }
    put_bit(&out->digital_safe, pin, msg->safe_level);
    drive_digital(out, hal, pin, msg->safe_level);
    return protoduino_Status_STATUS_OK;
}

/* A DigitalControl: checked, then (if `apply`) driven. */
__attribute__((noinline)) protoduino_Status
pd_digital_control(pd_outputs_t *out, void *hal, const protoduino_DigitalControl *msg, bool apply)
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
    return pd_digital_control(out, hal, msg, true);
}

#endif /* PD_FEATURE_DIGITAL_OUTPUT */

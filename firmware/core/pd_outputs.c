/* The outputs as a whole (pd_outputs.h): the pin-mode table's walks, Pose, ReadOutputs. */
#include "pd_outputs.h"

#include <stdint.h>
#include <string.h>

#include "pd_encode.h"
#include "pd_protocol.h"
#include "pd_user.h"

/* Every PWM output's duty fits OutputStates.pwm_duties. */
typedef char pd_assert_pwm_fit_read[(PD_MAX_PWM <= sizeof(((protoduino_OutputStates *)0)->pwm_duties)) ? 1 : -1];

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

/*
 * The pin-mode table: one entry per PD_MODE_x but PD_MODE_FREE (which owns no pin),
 *   X(mode, feature, safe, release)
 *   feature: the PD_FEATURE_x switch it is built with (pd_features.h): without it, the mode
 *            owns no pin and its functions are not built (its file compiles to nothing), so
 *            the walks never call them;
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
#define PD_MODES(X)                                                                    \
    X(PD_MODE_DIGITAL, PD_FEATURE_DIGITAL_OUTPUT, pd_digital_safe, pd_digital_release) \
    X(PD_MODE_SERVO, PD_FEATURE_SERVO, pd_servo_safe, pd_servo_release)                \
    X(PD_MODE_PWM, PD_FEATURE_PWM, pd_pwm_safe, pd_pwm_release)                        \
    X(PD_MODE_DIGITAL_INPUT, PD_FEATURE_DIGITAL_INPUT, input_safe, dinput_release)     \
    X(PD_MODE_ANALOG_INPUT, PD_FEATURE_ANALOG_INPUT, input_safe, ainput_release)       \
    X(PD_MODE_COUNTER, PD_FEATURE_COUNTER, input_safe, counter_release)                \
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
#define PD_MODES_USER(X) X(PD_MODE_USER, 1, user_safe, user_release)
#else
#define PD_MODES_USER(X)
#endif

#define PD_MODE_ONE(mode, feature_, safe_, release_) +1
typedef char pd_assert_every_mode_listed[(0 PD_MODES(PD_MODE_ONE)) == PD_MODE_COUNT - 1 ? 1 : -1];
#undef PD_MODE_ONE

static void mode_safe(uint8_t mode, pd_outputs_t *out, void *hal, uint8_t pin, uint8_t slot)
{
    switch (mode) {
#define PD_MODE_SAFE(mode_, feature_, safe_, release_)                       \
    case mode_:                                                              \
        if (feature_) {                                                      \
            safe_(out, hal, pin, slot);                                      \
        }                                                                    \
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
#define PD_MODE_RELEASE(mode_, feature_, safe_, release_)                    \
    case mode_:                                                              \
        if (feature_) {                                                      \
            release_(out, hal, pin, slot);                                   \
        }                                                                    \
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
    pd_pinset_t seen = {{0}};
    uint8_t pins_size = (uint8_t)msg->digital_pins.size;
    uint8_t levels_size = (uint8_t)msg->digital_levels.size;

    *bad = 1;
    if (pins_size > sizeof(msg->digital_pins.bytes) ||
        levels_size > sizeof(msg->digital_levels.bytes)) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT; /* not from nanopb's decoder */
    }
    uint8_t any = 0;
    for (uint8_t i = 0; i < pins_size; i++) {
        any |= msg->digital_pins.bytes[i];
    }
    if (msg->items_count == 0 && any == 0) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT; /* sets nothing */
    }
    *bad = 0;
    for (uint8_t i = 0; i < levels_size; i++) {
        uint8_t pins = i < pins_size ? msg->digital_pins.bytes[i] : 0u;
        if (msg->digital_levels.bytes[i] & (uint8_t)~pins) {
            return protoduino_Status_STATUS_INVALID_ARGUMENT; /* a level for no pin: no output named */
        }
    }
    /* Pass 0 checks every item, then every pin of the set in ascending order (numbered
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
                status = PD_FEATURE_SERVO
                             ? pd_servo_control(out, hal, &item->output.servo, apply)
                             : protoduino_Status_STATUS_NOT_SUPPORTED;
                pin = item->output.servo.pin;
            } else if (item->which_output == protoduino_PoseItem_digital_tag) {
                status = PD_FEATURE_DIGITAL_OUTPUT
                             ? pd_digital_control(out, hal, &item->output.digital, apply)
                             : protoduino_Status_STATUS_NOT_SUPPORTED;
                pin = item->output.digital.pin;
            } else if (item->which_output == protoduino_PoseItem_pwm_tag) {
                status = PD_FEATURE_PWM ? pd_pwm_control(out, hal, &item->output.pwm, apply)
                                        : protoduino_Status_STATUS_NOT_SUPPORTED;
                pin = item->output.pwm.pin;
            }
            if (pass == 0) {
                /* pin < PD_MAX_PINS once the item is valid */
                if (status == protoduino_Status_STATUS_OK && pd_pinset_has(&seen, (uint8_t)pin)) {
                    status = protoduino_Status_STATUS_INVALID_ARGUMENT; /* a pin twice */
                }
                if (status != protoduino_Status_STATUS_OK) {
                    *bad = (uint8_t)(i + 1u);
                    return status;
                }
                pd_pinset_put(&seen, (uint8_t)pin, true);
            }
        }
        /* The set, one pin a turn: each exactly as its DigitalControl (a pin the board
         * does not have is refused there), a byte at a time. */
        if (pass != 0 && pass != PD_POSE_LEVELS) {
            pins_size = 0;
        } else {
            pins_size = (uint8_t)msg->digital_pins.size;
        }
        for (uint8_t at = 0; at < pins_size; at++) {
            uint8_t pins = msg->digital_pins.bytes[at];
            uint8_t levels = at < levels_size ? msg->digital_levels.bytes[at] : 0u;
            for (uint8_t pin = (uint8_t)(at * 8u); pins != 0; pin++, pins >>= 1, levels >>= 1) {
                if (!(pins & 1u)) {
                    continue;
                }
                protoduino_DigitalControl control = {pin, (levels & 1u) != 0};
                protoduino_Status status = PD_FEATURE_DIGITAL_OUTPUT
                                               ? pd_digital_control(out, hal, &control, apply)
                                               : protoduino_Status_STATUS_NOT_SUPPORTED;
                i++;
                if (pass == 0) {
                    if (status == protoduino_Status_STATUS_OK && pd_pinset_has(&seen, pin)) {
                        status = protoduino_Status_STATUS_INVALID_ARGUMENT; /* also an item */
                    }
                    if (status != protoduino_Status_STATUS_OK) {
                        *bad = i;
                        return status;
                    }
                }
            }
        }
        if (pass == 0 || pass == PD_POSE_LAST) {
            pd_hal_servo_hold(hal, pass == 0);
        }
    }
    return protoduino_Status_STATUS_OK;
}

/* OutputStates.servos: 5 B a servo, in pin order (pd_encode_servos_fn). */
static uint8_t *pd_outputs_servos(const void *outputs, uint8_t *b)
{
    const pd_outputs_t *out = outputs;
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t owner = out->owner[pin];
        if (owner != 0 && PD_OWNER_MODE(owner) == PD_MODE_SERVO) {
            const pd_servo_t *s = &out->servo[PD_OWNER_SLOT(owner)];
            *b++ = pin;
            *b++ = (uint8_t)s->us;
            *b++ = (uint8_t)(s->us >> 8);
            *b++ = (uint8_t)s->target_us;
            *b++ = (uint8_t)(s->target_us >> 8);
        }
    }
    return b;
}

void pd_outputs_read(const pd_outputs_t *out, protoduino_OutputStates *states)
{
    typedef char fits[(sizeof(states->digital_pins.bytes) >= PD_PINSET_BYTES) ? 1 : -1];
    (void)sizeof(fits);
    /* The servos' bytes: the encoder writes them from the table (pd_outputs_servos). */
    pd_encode_servos_set(&states->servos, pd_outputs_servos, out);
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t owner = out->owner[pin];
        if (owner == 0) {
            continue;
        }
        if (PD_OWNER_MODE(owner) == PD_MODE_DIGITAL) {
            pd_pinbytes_add(states->digital_pins.bytes, &states->digital_pins.size, pin);
            if (pd_pinset_has(&out->digital_level, pin)) {
                pd_pinbytes_add(states->digital_levels.bytes, &states->digital_levels.size, pin);
            }
        } else if (PD_OWNER_MODE(owner) == PD_MODE_PWM) {
            pd_pinbytes_add(states->pwm_pins.bytes, &states->pwm_pins.size, pin);
            states->pwm_duties[states->pwm_duties_count++] = out->pwm[PD_OWNER_SLOT(owner)].duty;
        }
    }
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

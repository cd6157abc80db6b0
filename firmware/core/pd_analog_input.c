/* Analog inputs, one input mode (pd_input_modes.h): round-robin sampling, threshold, heartbeat. */
#include "pd_input_modes.h"

/* Built only with its feature (pd_features.h): without it, nothing here (its callers test
 * PD_FEATURE_ANALOG_INPUT too). */
#if PD_FEATURE_ANALOG_INPUT

protoduino_Status pd_inputs_analog_init(pd_core_t *core, const protoduino_AnalogInputInit *msg)
{
    pd_inputs_t *in = &core->outputs.inputs;
    uint32_t interval = msg->interval_ms ? msg->interval_ms : PD_ANALOG_DEFAULT_INTERVAL_MS;
    uint32_t heartbeat = msg->heartbeat_ms ? msg->heartbeat_ms : PD_ANALOG_DEFAULT_HEARTBEAT_MS;
    bool was = false;
    uint8_t slot;
    protoduino_Status status = protoduino_Status_STATUS_INVALID_ARGUMENT;
    if (interval <= PD_ANALOG_MAX_MS && heartbeat <= PD_ANALOG_MAX_MS &&
        msg->threshold <= PD_ANALOG_MAX_COUNTS) {
        const pd_pinset_t *analog_pins = &pd_hal_board_info(core->hal)->analog_pins;
        status = pd_inputs_claim(core, msg->pin, PD_MODE_ANALOG_INPUT, PD_MAX_ANALOG_INPUTS,
                                 pd_inputs_pin_can(analog_pins, msg->pin), &was, &slot);
    } else if (msg->pin >= pd_hal_board_info(core->hal)->num_pins) {
        status = protoduino_Status_STATUS_INVALID_PIN; /* the pin is checked first */
    }
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    pd_ainput_t *a = &in->analog[slot];
    if (!was) {
        pd_hal_input_config(core->hal, msg->pin, false);
    }
    in->analog_on = (uint8_t)(in->analog_on | (1u << slot));
    a->interval = (uint16_t)interval;
    /* In 16 bits (both are at most 60000): no 32-bit division in the Uno's flash. */
    uint16_t periods = (uint16_t)(((uint16_t)heartbeat + (uint16_t)interval - 1u) / (uint16_t)interval);
    a->heartbeat = periods > 255u ? 255u : (uint8_t)periods;
    a->heartbeat_left = a->heartbeat;
    a->threshold = msg->threshold;
    a->sent = PD_ANALOG_UNSENT; /* the first sample is reported whatever it is */
    /* On the grid of its period (inputs of one period are due together, so their
     * samples share a report), the last grid point before now: sampled at once. */
    uint16_t now16 = (uint16_t)pd_hal_millis(core->hal);
    a->sampled_at = (uint16_t)(now16 - now16 % (uint16_t)interval - (uint16_t)interval);
    return protoduino_Status_STATUS_OK; /* a conversion under way for it still counts */
}

/* A finished conversion of `slot`: stored; due for a report if it moved past the
 * threshold, is the first since the Init, or its heartbeat came. */
static void analog_sampled(pd_inputs_t *in, uint8_t slot, uint16_t counts)
{
    pd_ainput_t *a = &in->analog[slot];
    a->value = counts;
    uint16_t moved = counts > a->sent ? (uint16_t)(counts - a->sent) : (uint16_t)(a->sent - counts);
    if (a->heartbeat_left > 0) {
        a->heartbeat_left--;
    }
    if (a->sent == PD_ANALOG_UNSENT || moved > a->threshold || a->heartbeat_left == 0) {
        in->analog_dirty = (uint8_t)(in->analog_dirty | (1u << slot));
        in->analog_fresh = 1;
    }
}

/* The next input whose period is up, round-robin after `after` (so that no
 * input starves another when the converter cannot keep up); PD_INPUTS_NO_SLOT if none. */
static uint8_t analog_due(pd_inputs_t *in, uint8_t after, uint16_t now16)
{
    uint8_t slot = after;
    for (uint8_t n = 0; n < PD_MAX_ANALOG_INPUTS; n++) {
        slot = (uint8_t)(slot + 1u >= PD_MAX_ANALOG_INPUTS ? 0u : slot + 1u);
        pd_ainput_t *a = &in->analog[slot];
        if (a->interval != 0 && (uint16_t)(now16 - a->sampled_at) >= a->interval) {
            return slot;
        }
    }
    return PD_INPUTS_NO_SLOT;
}

/*
 * One conversion at a time, started as soon as the previous one is done: the
 * due inputs are sampled one after the other, and the samples of one round
 * (every input due, once) travel in one report, marked when the round ends (no
 * input due, or the next due one was sampled in this round already). A
 * converter that is done at once (the simulated board's) takes a whole round
 * in one pass.
 */
void pd_analog_input_poll(pd_core_t *core, uint32_t now)
{
    pd_outputs_t *out = &core->outputs;
    pd_inputs_t *in = &out->inputs;
    uint16_t now16 = (uint16_t)now;
    for (uint8_t n = 0; n <= PD_MAX_ANALOG_INPUTS; n++) {
        uint8_t last = in->adc_last;
        if (in->adc_slot != PD_INPUTS_NO_SLOT) {
            uint16_t counts;
            if (!pd_hal_analog_done(core->hal, &counts)) {
                return;
            }
            last = in->adc_slot;
            in->adc_last = last;
            in->adc_slot = PD_INPUTS_NO_SLOT;
            if (in->analog[last].interval != 0) { /* not released meanwhile */
                analog_sampled(in, last, counts);
            }
            in->analog_round = (uint8_t)(in->analog_round | (1u << last));
        }
        uint8_t slot = analog_due(in, last, now16);
        if (slot == PD_INPUTS_NO_SLOT || ((in->analog_round >> slot) & 1u)) {
            in->analog_round = 0; /* the round is over: its samples go together */
            if (in->analog_fresh) {
                in->analog_fresh = 0;
                pd_inputs_mark_dirty(core);
            }
        }
        if (slot == PD_INPUTS_NO_SLOT) {
            return;
        }
        uint8_t pin = pd_inputs_pin_of(out, PD_MODE_ANALOG_INPUT, slot);
        pd_ainput_t *a = &in->analog[slot];
        /* The period is kept from the schedule, not from when the loop came by;
         * fallen behind by a whole period or more, back onto the grid. */
        uint16_t late = (uint16_t)(now16 - a->sampled_at - a->interval);
        a->sampled_at = late < a->interval ? (uint16_t)(a->sampled_at + a->interval)
                                           : (uint16_t)(now16 - now16 % a->interval);
        if (pin >= PD_MAX_PINS) {
            continue; /* cannot happen: a slot with an interval belongs to a pin */
        }
        in->adc_slot = slot;
        pd_hal_analog_start(core->hal, pin);
    }
}

#endif /* PD_FEATURE_ANALOG_INPUT */

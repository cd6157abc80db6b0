/* Pulse counters, one input mode (pd_input_modes.h): a count reported at most every interval. */
#include "pd_input_modes.h"

/* Built only with its feature (pd_features.h): without it, nothing here (its callers test
 * PD_FEATURE_COUNTER too). */
#if PD_FEATURE_COUNTER

protoduino_Status pd_inputs_counter_init(pd_core_t *core, const protoduino_CounterInit *msg)
{
    pd_inputs_t *in = &core->outputs.inputs;
    uint32_t interval = msg->interval_ms ? msg->interval_ms : PD_COUNTER_DEFAULT_INTERVAL_MS;
    bool was = false;
    uint8_t slot;
    protoduino_Status status = protoduino_Status_STATUS_INVALID_ARGUMENT;
    if ((uint8_t)msg->edge <= protoduino_Edge_EDGE_BOTH && interval <= PD_ANALOG_MAX_MS) {
        const pd_pinset_t *counter_pins = &pd_hal_board_info(core->hal)->counter_pins;
        status = pd_inputs_claim(core, msg->pin, PD_MODE_COUNTER, PD_MAX_COUNTERS,
                                 pd_inputs_pin_can(counter_pins, msg->pin), &was, &slot);
    } else if (msg->pin >= pd_hal_board_info(core->hal)->num_pins) {
        status = protoduino_Status_STATUS_INVALID_PIN;
    }
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    pd_counter_t *c = &in->counter[slot];
    in->counter_on = (uint8_t)(in->counter_on | (1u << slot));
    pd_hal_input_config(core->hal, msg->pin, msg->pull_up);
    pd_hal_counter_start(core->hal, msg->pin, (uint8_t)msg->edge); /* counts from 0 */
    c->sent = 0;
    c->interval = (uint16_t)interval;
    c->reported_at = (uint16_t)(pd_hal_millis(core->hal) - interval);
    in->counter_dirty = (uint8_t)(in->counter_dirty | (1u << slot)); /* the 0 after the Ack */
    pd_inputs_mark_dirty(core);
    return protoduino_Status_STATUS_OK;
}

void pd_counter_poll(pd_core_t *core, uint32_t now)
{
    pd_outputs_t *out = &core->outputs;
    pd_inputs_t *in = &out->inputs;
    for (uint8_t slot = 0; slot < PD_MAX_COUNTERS; slot++) {
        pd_counter_t *c = &in->counter[slot];
        if (c->interval == 0 || ((in->counter_dirty >> slot) & 1u) ||
            (uint16_t)((uint16_t)now - c->reported_at) < c->interval) {
            continue;
        }
        uint8_t pin = pd_inputs_pin_of(out, PD_MODE_COUNTER, slot);
        if (pin < PD_MAX_PINS && pd_hal_counter_read(core->hal, pin) != c->sent) {
            in->counter_dirty = (uint8_t)(in->counter_dirty | (1u << slot));
            pd_inputs_mark_dirty(core);
        }
    }
}

#endif /* PD_FEATURE_COUNTER */

/*
 * The inputs' share of the pin table (pd_outputs): their state at power-up and
 * a pin's release. Below the device value: pd_outputs calls these as it frees
 * a pin, while the rest of the inputs (pd_inputs.c) acts on the whole device
 * and calls pd_outputs, so they live apart (tests/c/test_include_graph.py).
 */
#include <string.h>

#include "pd_hal.h"
#include "pd_inputs.h"
#include "pd_outputs.h"

void pd_inputs_init(pd_inputs_t *in)
{
    memset(in, 0, sizeof(*in));
    in->adc_slot = PD_INPUTS_NO_SLOT;
}

void pd_inputs_release(pd_outputs_t *outputs, void *hal, uint8_t pin, uint8_t mode, uint8_t slot)
{
    pd_inputs_t *in = &outputs->inputs;
    if (mode == PD_MODE_DIGITAL_INPUT) {
        pd_pinset_put(&in->trip_mask, pin, false);
        pd_pinset_put(&in->dpins, pin, false);
    } else if (mode == PD_MODE_ANALOG_INPUT) {
        in->analog_on = (uint8_t)(in->analog_on & ~(1u << slot));
        /* Interval 0: not sampled; a conversion under way ends unused (pd_analog_input_poll). */
        memset(&in->analog[slot], 0, sizeof(in->analog[slot]));
        in->analog_dirty = (uint8_t)(in->analog_dirty & ~(1u << slot));
    } else if (mode == PD_MODE_COUNTER) {
        in->counter_on = (uint8_t)(in->counter_on & ~(1u << slot));
        pd_hal_counter_stop(hal, pin);
        memset(&in->counter[slot], 0, sizeof(in->counter[slot]));
        in->counter_dirty = (uint8_t)(in->counter_dirty & ~(1u << slot));
    }
    pd_hal_input_release(hal, pin);
}

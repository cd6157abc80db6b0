/* The inputs as a whole (pd_inputs.h): the loop's pass over the input modes and the
 * InputReport. Each mode in its own file (pd_input_modes.h): pd_digital_input.c,
 * pd_analog_input.c, pd_counter.c; what they share in pd_input_modes.c. */
#include "pd_inputs.h"

#include "pd_input_modes.h"

typedef char pd_assert_analog_dirty_fits[(PD_MAX_ANALOG_INPUTS <= 8u) ? 1 : -1];
typedef char pd_assert_counter_dirty_fits[(PD_MAX_COUNTERS <= 8u) ? 1 : -1];
typedef char pd_assert_report_fits[(PD_MAX_ANALOG_INPUTS <= sizeof(((protoduino_InputReport *)0)->analog_values) /
                                                                 sizeof(uint16_t) &&
                                    PD_MAX_COUNTERS <= sizeof(((protoduino_InputReport *)0)->counter_counts) /
                                                           sizeof(uint32_t)) ? 1 : -1];

/* --- polling, reports, release -------------------------------------------- */

/* Not inlined into the main loop, for the same reason as pd_digital_input_notice. */
__attribute__((noinline)) void pd_inputs_poll(pd_core_t *core, uint32_t now)
{
    /* The loop passes after every byte sent or received: what has nothing to do
     * must cost next to nothing (a servo write's cycles on the Uno). */
    pd_inputs_t *in = &core->outputs.inputs;
    bool tick = (uint8_t)now != in->tick; /* analog periods and counter intervals are in ms */
    in->tick = (uint8_t)now;
#if PD_FEATURE_DIGITAL_INPUT
    if (in->notice && !((core->report_pending >> PD_INPUTS_SLOT) & 1u)) {
        pd_digital_input_notice(core); /* the report slot emptied without the report */
    }
    if (pd_pinset_any(&in->dpins)) {
        pd_digital_input_poll(core, now);
    }
#endif
#if PD_FEATURE_ANALOG_INPUT
    if (in->adc_slot != PD_INPUTS_NO_SLOT || (tick && in->analog_on != 0)) {
        pd_analog_input_poll(core, now);
    }
#endif
#if PD_FEATURE_COUNTER
    if (tick && in->counter_on != 0) {
        pd_counter_poll(core, now);
    }
#endif
    (void)core;
    (void)now;
    (void)tick;
    (void)in;
}

bool pd_inputs_report(pd_core_t *core, uint8_t slot, protoduino_ArduinoOut *msg)
{
    (void)slot;
    pd_outputs_t *out = &core->outputs;
    pd_inputs_t *in = &out->inputs;
    protoduino_InputReport *r = &msg->data.input_report;
    msg->which_data = protoduino_ArduinoOut_input_report_tag;
    /* When the values were taken: the newest change's time (nothing changed since, or it
     * would be newer), or now if the report carries a count (read now, below). */
    r->time_ms = in->taken;
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t owner = out->owner[pin];
        uint8_t mode = PD_OWNER_MODE(owner);
        uint8_t s = PD_OWNER_SLOT(owner);
        if (owner == 0) {
            continue;
        }
        if (mode == PD_MODE_DIGITAL_INPUT) {
            pd_pinbytes_add(r->digital_pins.bytes, &r->digital_pins.size, pin);
            if (pd_pinset_has(&in->level, pin)) {
                pd_pinbytes_add(r->digital_levels.bytes, &r->digital_levels.size, pin);
            }
        } else if (mode == PD_MODE_ANALOG_INPUT && ((in->analog_dirty >> s) & 1u)) {
            pd_pinbytes_add(r->analog_pins.bytes, &r->analog_pins.size, pin);
            r->analog_values[r->analog_values_count++] = in->analog[s].value;
        } else if (mode == PD_MODE_COUNTER && ((in->counter_dirty >> s) & 1u)) {
            pd_pinbytes_add(r->counter_pins.bytes, &r->counter_pins.size, pin);
            r->counter_counts[r->counter_counts_count++] = pd_hal_counter_read(core->hal, pin);
            r->time_ms = pd_hal_millis(core->hal);
        }
    }
    r->coalesced = in->coalesced;
    return (r->digital_pins.size | r->analog_pins.size | r->counter_pins.size) != 0;
}

void pd_inputs_sent(pd_core_t *core, const protoduino_ArduinoOut *msg)
{
    pd_outputs_t *out = &core->outputs;
    pd_inputs_t *in = &out->inputs;
    const protoduino_InputReport *r = &msg->data.input_report;
    uint16_t now16 = (uint16_t)pd_hal_millis(core->hal);
    uint8_t a = 0;
    uint8_t c = 0;
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t s = PD_OWNER_SLOT(out->owner[pin]);
        if (pd_pinbytes_has(r->analog_pins.bytes, r->analog_pins.size, pin)) {
            in->analog[s].sent = r->analog_values[a++];
            in->analog[s].heartbeat_left = in->analog[s].heartbeat;
        } else if (pd_pinbytes_has(r->counter_pins.bytes, r->counter_pins.size, pin)) {
            in->counter[s].sent = r->counter_counts[c++];
            in->counter[s].reported_at = now16;
        }
    }
    in->analog_dirty = 0;
    in->counter_dirty = 0;
    in->coalesced = 0;
#if PD_FEATURE_DIGITAL_INPUT
    if (in->notice) {
        pd_digital_input_notice(core); /* right behind the report of its edge */
    }
#endif
}

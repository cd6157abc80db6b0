/* What the input modes share (pd_input_modes.h): a report due, a slot's pin, an Init's claim.
 * Below pd_inputs.c, which calls the modes' polls: the modes call down to here, never up. */
#include "pd_input_modes.h"

#if PD_ANY_INPUT
void pd_inputs_mark_dirty(pd_core_t *core)
{
    pd_inputs_t *in = &core->outputs.inputs;
    in->taken = pd_hal_millis(core->hal);
    if ((core->report_pending >> PD_INPUTS_SLOT) & 1u) {
        if (in->coalesced != UINT16_MAX) {
            in->coalesced++;
        }
    }
    pd_state_report(core, PD_INPUTS_SLOT);
}

#if PD_FEATURE_ANALOG_INPUT || PD_FEATURE_COUNTER
uint8_t pd_inputs_pin_of(const pd_outputs_t *out, uint8_t mode, uint8_t slot)
{
    uint8_t owner = PD_OWNER(mode, slot);
    uint8_t pin = 0;
    while (pin < PD_MAX_PINS && out->owner[pin] != owner) {
        pin++;
    }
    return pin;
}
#endif

protoduino_Status pd_inputs_claim(pd_core_t *core, uint8_t pin, uint8_t mode, uint8_t slots,
                                 bool capable, bool *was, uint8_t *slot)
{
    pd_outputs_t *out = &core->outputs;
    const pd_board_info_t *board = pd_hal_board_info(core->hal);
    if (pin < PD_MAX_PINS) {
        *was = out->owner[pin] != 0 && PD_OWNER_MODE(out->owner[pin]) == mode;
        if (pin < board->num_pins && !capable &&
            !pd_pinset_has(&board->reserved_pins, pin)) {
            return protoduino_Status_STATUS_NOT_SUPPORTED;
        }
    }
    return pd_pins_claim(out->owner, core->hal, pin, mode, slots, slot);
}
#endif /* PD_ANY_INPUT */

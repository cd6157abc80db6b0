/* The pin table (pd_pintable.h): which mode owns each pin; it knows no mode. */
#include "pd_pintable.h"

typedef char pd_assert_modes_fit_owner[(PD_MODE_COUNT <= (1u << (8u - PD_SLOT_BITS))) ? 1 : -1];

protoduino_Status pd_pins_check(void *hal, uint32_t pin)
{
    const pd_board_info_t *info = pd_hal_board_info(hal);
    uint8_t num_pins = info->num_pins < PD_MAX_PINS ? info->num_pins : PD_MAX_PINS;

    if (pin >= num_pins) {
        return protoduino_Status_STATUS_INVALID_PIN;
    }
    if (pd_pinset_has(&info->reserved_pins, (uint8_t)pin)) {
        return protoduino_Status_STATUS_RESERVED_PIN;
    }
    return protoduino_Status_STATUS_OK;
}

protoduino_Status pd_pins_claim(uint8_t *owner, void *hal, uint32_t pin, uint8_t mode,
                                uint8_t slots, uint8_t *slot)
{
    protoduino_Status status = pd_pins_check(hal, pin);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    if (mode != PD_MODE_ANALOG_INPUT &&
        pd_pinset_has(&pd_hal_board_info(hal)->analog_only_pins, (uint8_t)pin)) {
        return protoduino_Status_STATUS_NOT_SUPPORTED; /* no digital I/O at the pin */
    }
    uint8_t was = owner[pin];
    if (was != 0) {
        if (PD_OWNER_MODE(was) != mode) {
            return protoduino_Status_STATUS_PIN_IN_USE;
        }
        *slot = PD_OWNER_SLOT(was); /* re-init: new settings, same slot */
        return protoduino_Status_STATUS_OK;
    }
    uint8_t free_slot = 0;
    if (slots > 0) {
        /* The lowest slot no pin of this mode holds. */
        pd_slots_t used = 0;
        for (uint8_t p = 0; p < PD_MAX_PINS; p++) {
            if (owner[p] != 0 && PD_OWNER_MODE(owner[p]) == mode) {
                used |= (pd_slots_t)((pd_slots_t)1u << PD_OWNER_SLOT(owner[p]));
            }
        }
        while (free_slot < slots && ((used >> free_slot) & 1u)) {
            free_slot++;
        }
        if (free_slot >= slots) {
            return protoduino_Status_STATUS_NO_FREE_RESOURCE;
        }
    }
    owner[pin] = PD_OWNER(mode, free_slot);
    *slot = free_slot;
    return protoduino_Status_STATUS_OK;
}

protoduino_Status pd_pins_owned(const uint8_t *owner, void *hal, uint32_t pin, uint8_t mode,
                                uint8_t *slot)
{
    /* The common case first, on the path from a command's last byte to its pin: an
     * output commanded in the mode it was set up in. Only a pin that passed
     * pd_pins_check is ever owned (pd_pins_claim), so pd_pins_check (a 32-bit mask
     * shifted by the pin: a loop on the AVR) only has to name what is wrong otherwise. */
    if (pin < PD_MAX_PINS) {
        uint8_t was = owner[pin];
        if (was != 0 && PD_OWNER_MODE(was) == mode) {
            *slot = PD_OWNER_SLOT(was);
            return protoduino_Status_STATUS_OK;
        }
    }
    protoduino_Status status = pd_pins_check(hal, pin);
    return status != protoduino_Status_STATUS_OK ? status
                                                 : protoduino_Status_STATUS_NOT_INITIALISED;
}

uint8_t pd_pins_count(const uint8_t *owner, uint8_t mode)
{
    uint8_t n = 0;
    for (uint8_t p = 0; p < PD_MAX_PINS; p++) {
        if (owner[p] != 0 && PD_OWNER_MODE(owner[p]) == mode) {
            n++;
        }
    }
    return n;
}

/* Digital inputs, one input mode (pd_input_modes.h): debounce, interlocks and their trips. */
#include "pd_input_modes.h"

#include "pd_out.h"

/* Built only with its feature (pd_features.h): without it, nothing here (its callers test
 * PD_FEATURE_DIGITAL_INPUT too). */
#if PD_FEATURE_DIGITAL_INPUT

protoduino_Status pd_inputs_digital_init(pd_core_t *core, const protoduino_DigitalInputInit *msg)
{
    pd_inputs_t *in = &core->outputs.inputs;
    if (msg->debounce_ms > PD_MAX_DEBOUNCE_MS || (uint8_t)msg->interlock > protoduino_Trip_TRIP_HIGH) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }
    bool was = false;
    uint8_t slot;
    /* Every pin of the board but the reserved ones reads as a digital input. */
    protoduino_Status status = pd_inputs_claim(core, msg->pin, PD_MODE_DIGITAL_INPUT,
                                               PD_MAX_DIGITAL_INPUTS, true, &was, &slot);
    if (status != protoduino_Status_STATUS_OK) {
        return status;
    }
    uint8_t pin = msg->pin;
    uint8_t w = PD_PINSET_WORD(pin); /* pin's word and bit in the sets (pd_pinset.h) */
    uint32_t bit = PD_PINSET_BIT(pin);
    pd_hal_input_config(core->hal, pin, msg->pull_up);
    in->digital[slot].debounce = (uint8_t)msg->debounce_ms;
    /* The level now, as it reads: a host knows it at once (the report after the Ack). */
    bool level = (pd_hal_digital_read_all(core->hal).w[w] & bit) != 0;
    in->dpins.w[w] |= bit;
    in->raw.w[w] = level ? (in->raw.w[w] | bit) : (in->raw.w[w] & ~bit);
    in->level.w[w] = level ? (in->level.w[w] | bit) : (in->level.w[w] & ~bit);
    in->digital[slot].since = (uint8_t)pd_hal_millis(core->hal);
    in->trip_mask.w[w] &= ~bit;
    in->trip_level.w[w] &= ~bit;
    if (msg->interlock != protoduino_Trip_TRIP_NONE) {
        in->trip_mask.w[w] |= bit;
        if (msg->interlock == protoduino_Trip_TRIP_HIGH) {
            in->trip_level.w[w] |= bit;
        }
        if (level == (msg->interlock == protoduino_Trip_TRIP_HIGH)) {
            /* Already at its trip level (a bumper pressed as it is configured): it
             * trips in the loop's next pass, right after this Init's Ack, without
             * waiting for its debounce (the level has held for who knows how long). */
            in->level.w[w] ^= bit;
            in->digital[slot].since = (uint8_t)(in->digital[slot].since - in->digital[slot].debounce);
        }
    }
    (void)was;
    pd_inputs_mark_dirty(core);
    return protoduino_Status_STATUS_OK;
}

/* The interlock on `pin` reached its trip level: every output safe at once and latched;
 * the host hears of it once the report of the edge went out (pd_digital_input_notice). */
static void trip(pd_core_t *core, uint8_t pin)
{
    pd_inputs_t *in = &core->outputs.inputs;
    pd_outputs_all_safe(&core->outputs, core->hal);
    in->latched = (uint8_t)(pin + 1u);
    in->notice = 1;
}

/*
 * The latched trip becomes the device's failsafe state (a safe state of its own: a new
 * epoch; the timer runs on) and the host is told, once the InputReport carrying the
 * tripped level (pd_digital_input_poll marks it with the trip) went out: until then the trip is
 * in no message (pd_out_failsafe_state leaves an untold latch out of the state Acks
 * carry), so a host's view of the input is never older than the FAILSAFE event it
 * hears (issue 32). Called right behind that report (pd_inputs_sent), or by the next
 * poll if the report slot was emptied otherwise. A notice dropped while IDLE or for want
 * of room is told by a Ping's Ack. A latch a new session released is forgotten untold.
 * Not inlined: its ArduinoOut would sit in the main loop's frame, under every command's
 * decode (the Uno's deepest stack), for good.
 */
__attribute__((noinline)) void pd_digital_input_notice(pd_core_t *core)
{
    pd_inputs_t *in = &core->outputs.inputs;
    in->notice = 0;
    if (in->latched != 0) {
        pd_failsafe_interlock(&core->failsafe, (uint8_t)(in->latched - 1u));
        pd_out_send_failsafe(core);
    }
}

/* Whether an interlock input is at its trip level now (debounced). */
static bool tripped(const pd_inputs_t *in)
{
    uint32_t at = 0;
    for (uint8_t w = 0; w < PD_PINSET_WORDS; w++) {
        at |= (in->level.w[w] ^ ~in->trip_level.w[w]) & in->trip_mask.w[w];
    }
    return at != 0;
}

protoduino_Status pd_inputs_clear_interlock(pd_core_t *core, uint8_t epoch, bool *cleared)
{
    pd_inputs_t *in = &core->outputs.inputs;
    *cleared = false;
    /* Still at its trip level, or a host that has not seen the latest safe state
     * (a ClearInterlock written before a later trip and held up on the way, or a
     * trip not told yet). */
    if (tripped(in) || (in->latched != 0 && (in->notice || epoch != core->failsafe.epoch))) {
        return protoduino_Status_STATUS_INTERLOCK_ACTIVE;
    }
    *cleared = in->latched != 0;
    in->latched = 0;
    if (*cleared && !core->failsafe.fired) {
        core->failsafe.active = false; /* the host saw it and cleared it: the flag too */
    }
    return protoduino_Status_STATUS_OK;
}

/*
 * Every pass of the loop (an interlock reacts within one), so it costs little
 * while nothing changes: one read of every pin, and the per-pin work only for
 * a pin whose level changed or whose new level is still being debounced.
 */
void pd_digital_input_poll(pd_core_t *core, uint32_t now)
{
    pd_outputs_t *out = &core->outputs;
    pd_inputs_t *in = &out->inputs;
    pd_pinset_t levels = pd_hal_digital_read_all(core->hal);
    uint8_t now8 = (uint8_t)now;
    for (uint8_t w = 0; w < PD_PINSET_WORDS; w++) {
        uint32_t pins = in->dpins.w[w];
        uint32_t read = levels.w[w] & pins;
        uint32_t work = ((read ^ in->raw.w[w]) | (in->raw.w[w] ^ in->level.w[w])) & pins;
        uint32_t bit = 1;
        for (uint8_t pin = (uint8_t)(w * 32u); work != 0; pin++, bit <<= 1) {
            if (!(work & bit)) {
                continue;
            }
            work &= ~bit;
            pd_dinput_t *d = &in->digital[PD_OWNER_SLOT(out->owner[pin])];
            bool raw = (read & bit) != 0;
            if (raw != ((in->raw.w[w] & bit) != 0)) {
                in->raw.w[w] ^= bit;
                d->since = now8;
            }
            if (raw != ((in->level.w[w] & bit) != 0) &&
                (uint8_t)(now8 - d->since) >= d->debounce) {
                in->level.w[w] ^= bit;
                if ((in->trip_mask.w[w] & bit) && raw == ((in->trip_level.w[w] & bit) != 0) &&
                    !in->latched) {
                    trip(core, pin);
                }
                pd_inputs_mark_dirty(core);
            }
        }
    }
}

#endif /* PD_FEATURE_DIGITAL_INPUT */

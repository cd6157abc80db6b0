#include "pd_inputs.h"

#include <string.h>

#include "pd_out.h"
#include "pd_state.h"

typedef char pd_assert_analog_dirty_fits[(PD_MAX_ANALOG_INPUTS <= 8u) ? 1 : -1];
typedef char pd_assert_counter_dirty_fits[(PD_MAX_COUNTERS <= 8u) ? 1 : -1];
typedef char pd_assert_report_fits[(PD_MAX_ANALOG_INPUTS <= sizeof(((protoduino_InputReport *)0)->analog_values) /
                                                                 sizeof(uint16_t) &&
                                    PD_MAX_COUNTERS <= sizeof(((protoduino_InputReport *)0)->counter_counts) /
                                                           sizeof(uint32_t)) ? 1 : -1];

#define NO_SLOT PD_INPUTS_NO_SLOT

#define PD_ANY_INPUT (PD_FEATURE_DIGITAL_INPUT || PD_FEATURE_ANALOG_INPUT || PD_FEATURE_COUNTER)

#if PD_ANY_INPUT
/* Something changed: a report is due; joining one that is pending counts as coalesced. */
static void mark_dirty(pd_core_t *core)
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
/* The pin that `mode` holds with `slot`; PD_MAX_PINS if none. */
static uint8_t pin_of(const pd_outputs_t *out, uint8_t mode, uint8_t slot)
{
    uint8_t owner = PD_OWNER(mode, slot);
    uint8_t pin = 0;
    while (pin < PD_MAX_PINS && out->owner[pin] != owner) {
        pin++;
    }
    return pin;
}
#endif

/* Whether `pin` is in `set`, a pin past the build's pins counting as in it (refused later, for
 * what it is): a pin set of the board's table read where it is constant, so that it folds. */
__attribute__((always_inline)) static inline bool pin_can(const pd_pinset_t *set, uint32_t pin)
{
    return pin >= PD_MAX_PINS || pd_pinset_has(set, (uint8_t)pin);
}

/* The checks an input Init shares: the pin can do `mode` (`capable`: pin_can of the board's
 * pins for it). */
static protoduino_Status claim_input(pd_core_t *core, uint8_t pin, uint8_t mode, uint8_t slots,
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

/* --- digital inputs and interlocks --------------------------------------- */

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
    protoduino_Status status =
        claim_input(core, msg->pin, PD_MODE_DIGITAL_INPUT, PD_MAX_DIGITAL_INPUTS, true, &was,
                    &slot);
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
    mark_dirty(core);
    return protoduino_Status_STATUS_OK;
}

/* The interlock on `pin` reached its trip level: every output safe at once and latched;
 * the host hears of it once the report of the edge went out (send_notice). */
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
 * tripped level (poll_digital marks it with the trip) went out: until then the trip is
 * in no message (pd_out_failsafe_state leaves an untold latch out of the state Acks
 * carry), so a host's view of the input is never older than the FAILSAFE event it
 * hears (issue 32). Called right behind that report (pd_inputs_sent), or by the next
 * poll if the report slot was emptied otherwise. A notice dropped while IDLE or for want
 * of room is told by a Ping's Ack. A latch a new session released is forgotten untold.
 * Not inlined: its ArduinoOut would sit in the main loop's frame, under every command's
 * decode (the Uno's deepest stack), for good.
 */
static __attribute__((noinline)) void send_notice(pd_core_t *core)
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
static void poll_digital(pd_core_t *core, uint32_t now)
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
                mark_dirty(core);
            }
        }
    }
}

#else

protoduino_Status pd_inputs_digital_init(pd_core_t *core, const protoduino_DigitalInputInit *msg)
{
    (void)core;
    (void)msg;
    return protoduino_Status_STATUS_NOT_SUPPORTED;
}

protoduino_Status pd_inputs_clear_interlock(pd_core_t *core, uint8_t epoch, bool *cleared)
{
    (void)core;
    (void)epoch;
    *cleared = false;
    return protoduino_Status_STATUS_NOT_SUPPORTED;
}

#endif /* PD_FEATURE_DIGITAL_INPUT */

/* --- analog inputs -------------------------------------------------------- */

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
        status = claim_input(core, msg->pin, PD_MODE_ANALOG_INPUT, PD_MAX_ANALOG_INPUTS,
                             pin_can(&pd_hal_board_info(core->hal)->analog_pins, msg->pin), &was,
                             &slot);
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
 * input starves another when the converter cannot keep up); NO_SLOT if none. */
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
    return NO_SLOT;
}

/*
 * One conversion at a time, started as soon as the previous one is done: the
 * due inputs are sampled one after the other, and the samples of one round
 * (every input due, once) travel in one report, marked when the round ends (no
 * input due, or the next due one was sampled in this round already). A
 * converter that is done at once (the simulated board's) takes a whole round
 * in one pass.
 */
static void poll_analog(pd_core_t *core, uint32_t now)
{
    pd_outputs_t *out = &core->outputs;
    pd_inputs_t *in = &out->inputs;
    uint16_t now16 = (uint16_t)now;
    for (uint8_t n = 0; n <= PD_MAX_ANALOG_INPUTS; n++) {
        uint8_t last = in->adc_last;
        if (in->adc_slot != NO_SLOT) {
            uint16_t counts;
            if (!pd_hal_analog_done(core->hal, &counts)) {
                return;
            }
            last = in->adc_slot;
            in->adc_last = last;
            in->adc_slot = NO_SLOT;
            if (in->analog[last].interval != 0) { /* not released meanwhile */
                analog_sampled(in, last, counts);
            }
            in->analog_round = (uint8_t)(in->analog_round | (1u << last));
        }
        uint8_t slot = analog_due(in, last, now16);
        if (slot == NO_SLOT || ((in->analog_round >> slot) & 1u)) {
            in->analog_round = 0; /* the round is over: its samples go together */
            if (in->analog_fresh) {
                in->analog_fresh = 0;
                mark_dirty(core);
            }
        }
        if (slot == NO_SLOT) {
            return;
        }
        uint8_t pin = pin_of(out, PD_MODE_ANALOG_INPUT, slot);
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

#else

protoduino_Status pd_inputs_analog_init(pd_core_t *core, const protoduino_AnalogInputInit *msg)
{
    (void)core;
    (void)msg;
    return protoduino_Status_STATUS_NOT_SUPPORTED;
}

#endif /* PD_FEATURE_ANALOG_INPUT */

/* --- pulse counters ------------------------------------------------------- */

#if PD_FEATURE_COUNTER

protoduino_Status pd_inputs_counter_init(pd_core_t *core, const protoduino_CounterInit *msg)
{
    pd_inputs_t *in = &core->outputs.inputs;
    uint32_t interval = msg->interval_ms ? msg->interval_ms : PD_COUNTER_DEFAULT_INTERVAL_MS;
    bool was = false;
    uint8_t slot;
    protoduino_Status status = protoduino_Status_STATUS_INVALID_ARGUMENT;
    if ((uint8_t)msg->edge <= protoduino_Edge_EDGE_BOTH && interval <= PD_ANALOG_MAX_MS) {
        status = claim_input(core, msg->pin, PD_MODE_COUNTER, PD_MAX_COUNTERS,
                             pin_can(&pd_hal_board_info(core->hal)->counter_pins, msg->pin), &was,
                             &slot);
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
    mark_dirty(core);
    return protoduino_Status_STATUS_OK;
}

static void poll_counters(pd_core_t *core, uint32_t now)
{
    pd_outputs_t *out = &core->outputs;
    pd_inputs_t *in = &out->inputs;
    for (uint8_t slot = 0; slot < PD_MAX_COUNTERS; slot++) {
        pd_counter_t *c = &in->counter[slot];
        if (c->interval == 0 || ((in->counter_dirty >> slot) & 1u) ||
            (uint16_t)((uint16_t)now - c->reported_at) < c->interval) {
            continue;
        }
        uint8_t pin = pin_of(out, PD_MODE_COUNTER, slot);
        if (pin < PD_MAX_PINS && pd_hal_counter_read(core->hal, pin) != c->sent) {
            in->counter_dirty = (uint8_t)(in->counter_dirty | (1u << slot));
            mark_dirty(core);
        }
    }
}

#else

protoduino_Status pd_inputs_counter_init(pd_core_t *core, const protoduino_CounterInit *msg)
{
    (void)core;
    (void)msg;
    return protoduino_Status_STATUS_NOT_SUPPORTED;
}

#endif /* PD_FEATURE_COUNTER */

/* --- polling, reports, release -------------------------------------------- */

/* Not inlined into the main loop, for the same reason as trip(). */
__attribute__((noinline)) void pd_inputs_poll(pd_core_t *core, uint32_t now)
{
    /* The loop passes after every byte sent or received: what has nothing to do
     * must cost next to nothing (a servo write's cycles on the Uno). */
    pd_inputs_t *in = &core->outputs.inputs;
    bool tick = (uint8_t)now != in->tick; /* analog periods and counter intervals are in ms */
    in->tick = (uint8_t)now;
#if PD_FEATURE_DIGITAL_INPUT
    if (in->notice && !((core->report_pending >> PD_INPUTS_SLOT) & 1u)) {
        send_notice(core); /* the report slot emptied without the report */
    }
    if (pd_pinset_any(&in->dpins)) {
        poll_digital(core, now);
    }
#endif
#if PD_FEATURE_ANALOG_INPUT
    if (in->adc_slot != NO_SLOT || (tick && in->analog_on != 0)) {
        poll_analog(core, now);
    }
#endif
#if PD_FEATURE_COUNTER
    if (tick && in->counter_on != 0) {
        poll_counters(core, now);
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
        send_notice(core); /* right behind the report of its edge */
    }
#endif
}

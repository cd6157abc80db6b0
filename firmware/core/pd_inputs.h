/*
 * Inputs (docs/protocol.md section 7, "Inputs"): digital inputs with debounce
 * and interlocks, analog inputs with a threshold and a heartbeat, pulse
 * counters, and the InputReport that carries their values.
 *
 * Reports are "freshness over completeness": each input keeps its newest
 * value and a dirty bit; one report slot of the core (PD_INPUTS_SLOT) is
 * pending while any bit is set, and the report is built when it can go out
 * (pd_core.c, send_report), so it always carries the newest values, and every
 * change that joined a report already pending counts as coalesced.
 *
 * The pins belong to the pin table (pd_pintable.h) like the outputs' pins:
 * an input Init claims its pin with pd_pins_claim(), Release/ReleaseAll let go
 * of it through the pin-mode table (pd_outputs.c). The state lives in pd_outputs_t.inputs so
 * that the table's release functions reach it.
 */
#ifndef PD_INPUTS_H
#define PD_INPUTS_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_features.h"
#include "pd_pinset.h"
#include "protoduino.pb.h"

struct pd_core;
struct pd_outputs;

/* The core's report slot for InputReport (pd_state.h, PD_REPORT_SLOTS). */
#define PD_INPUTS_SLOT 0u

/* Slots per input mode (each slot a few bytes of the Uno's RAM). */
#define PD_MAX_DIGITAL_INPUTS (PD_FEATURE_DIGITAL_INPUT ? 8u : 1u)
#define PD_MAX_ANALOG_INPUTS (PD_FEATURE_ANALOG_INPUT ? 6u : 1u)
#define PD_MAX_COUNTERS (PD_FEATURE_COUNTER ? 2u : 1u)

/* Analog defaults (protoduino.proto, AnalogInputInit) and bounds. */
#define PD_ANALOG_DEFAULT_INTERVAL_MS 10u
#define PD_ANALOG_DEFAULT_HEARTBEAT_MS 1000u
#define PD_ANALOG_MAX_MS 60000u
#define PD_ANALOG_MAX_COUNTS 1023u
/* Counter default report interval. */
#define PD_COUNTER_DEFAULT_INTERVAL_MS 20u
#define PD_MAX_DEBOUNCE_MS 255u

typedef struct pd_dinput {
    uint8_t debounce; /* ms a new level must hold */
    uint8_t since;    /* low byte of the ms the raw level last changed */
} pd_dinput_t;

typedef struct pd_ainput {
    uint16_t interval;   /* sampling period, ms */
    uint16_t threshold;  /* counts */
    uint16_t value;      /* the newest sample */
    uint16_t sent;       /* the value last reported; PD_ANALOG_UNSENT: none since the Init */
    uint16_t sampled_at; /* low 16 bits of the ms the last sample was due */
    /* The heartbeat in sampling periods (heartbeat_ms / interval_ms rounded up,
     * 1..255), and the periods left until it is due: 2 B where a time would be 4. */
    uint8_t heartbeat;
    uint8_t heartbeat_left;
} pd_ainput_t;
#define PD_ANALOG_UNSENT 0xFFFFu

typedef struct pd_counter {
    uint32_t sent;        /* the count last reported */
    uint16_t interval;    /* reports at most this often, ms */
    uint16_t reported_at; /* low 16 bits of the ms of the last report */
} pd_counter_t;

/* No slot: pd_inputs_t.adc_slot when no conversion is under way. */
#define PD_INPUTS_NO_SLOT 0xFFu

typedef struct pd_inputs {
    pd_dinput_t digital[PD_MAX_DIGITAL_INPUTS];
    pd_ainput_t analog[PD_MAX_ANALOG_INPUTS];
    pd_counter_t counter[PD_MAX_COUNTERS];
    /* Pin sets (pd_pinset.h), pin N for digital input N: */
    pd_pinset_t dpins;      /* the digital inputs */
    pd_pinset_t level;      /* its debounced level */
    pd_pinset_t raw;        /* the level read last */
    pd_pinset_t trip_mask;  /* it is an interlock */
    pd_pinset_t trip_level; /* it trips at a high level (else low) */
    uint8_t analog_dirty;  /* bit slot: a value to report */
    uint8_t counter_dirty; /* bit slot: a count to report */
    uint8_t adc_slot;      /* the analog slot being converted; PD_INPUTS_NO_SLOT: none */
    uint8_t adc_last;      /* the analog slot converted last (round-robin) */
    uint8_t analog_fresh;  /* samples due for a report since the last round's end */
    uint8_t analog_round;  /* bit slot: sampled in this round */
    uint8_t latched;       /* an interlock tripped: its pin + 1; 0: none */
    uint8_t notice;        /* that trip is not told yet (pd_digital_input.c, pd_digital_input_notice) */
    uint8_t analog_on;     /* bit slot: an analog input is configured there */
    uint8_t counter_on;    /* bit slot: a counter is configured there */
    uint8_t tick;          /* low byte of the millisecond the timed work last ran */
    uint16_t coalesced;    /* changes that joined a pending report, since the last sent */
    uint32_t taken;        /* pd_hal_millis() of the newest change due for a report */
} pd_inputs_t;

void pd_inputs_init(pd_inputs_t *in);

protoduino_Status pd_inputs_digital_init(struct pd_core *core, const protoduino_DigitalInputInit *msg);
protoduino_Status pd_inputs_analog_init(struct pd_core *core, const protoduino_AnalogInputInit *msg);
protoduino_Status pd_inputs_counter_init(struct pd_core *core, const protoduino_CounterInit *msg);

/* ClearInterlock carrying the failsafe epoch its host has seen: OK once no
 * interlock input is at its trip level and a latch there is of that epoch (then
 * the latch is gone and *cleared says whether there was one), else
 * INTERLOCK_ACTIVE. */
protoduino_Status pd_inputs_clear_interlock(struct pd_core *core, uint8_t epoch, bool *cleared);

/* Every loop pass: read the inputs, debounce, trip interlocks, sample, mark dirty. */
void pd_inputs_poll(struct pd_core *core, uint32_t now);

/*
 * Whether any input is configured: pd_core_poll calls pd_inputs_poll only then.
 * The loop passes after every byte sent or received, and the call alone (its
 * register saves) cost a board without inputs 2,000 cycles per servo write.
 */
static inline bool pd_inputs_active(const pd_inputs_t *in)
{
    return pd_pinset_any(&in->dpins) || (in->analog_on | in->counter_on) != 0 ||
           in->adc_slot != 0xFFu;
}

/* Fill the InputReport with the newest values (the core's report callback for PD_INPUTS_SLOT). */
bool pd_inputs_report(struct pd_core *core, uint8_t slot, protoduino_ArduinoOut *out);

/* That report went out: what it carried is what the host has (thresholds, intervals, dirty bits). */
void pd_inputs_sent(struct pd_core *core, const protoduino_ArduinoOut *out);

/* The pin-mode table's release of an input pin (pd_outputs.c). */
void pd_inputs_release(struct pd_outputs *outputs, void *hal, uint8_t pin, uint8_t mode,
                       uint8_t slot);

#endif /* PD_INPUTS_H */

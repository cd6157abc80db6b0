/*
 * The device as one value: link, the command being received, dedupe window,
 * outputs, inputs and failsafe, with no globals, so that the unit tests and
 * the fuzzer can instantiate as many as they like. Data only (and the one
 * inline that marks a report due): every module that acts on the whole device
 * (pd_out, pd_inputs, pd_dispatch, pd_core) includes this, below all of them;
 * what runs when is pd_core's.
 */
#ifndef PD_STATE_H
#define PD_STATE_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_dedupe.h"
#include "pd_failsafe.h"
#include "pd_hal.h"
#include "pd_link.h"
#include "pd_outputs.h"
#include "pd_user.h"
#include "protoduino.pb.h"

struct pd_core;

/*
 * A report source: fill `out` with the newest value of report slot `slot`,
 * or return false if there is nothing to send after all. Called only when the
 * message can go out at once, so a value is read when it is sent: a newer
 * value replaces one that has not left yet, by construction.
 */
typedef bool (*pd_report_fn)(struct pd_core *core, uint8_t slot, protoduino_ArduinoOut *out);

/* The message a report source built went out (NULL: nothing to do). */
typedef void (*pd_report_sent_fn)(struct pd_core *core, const protoduino_ArduinoOut *out);

/* Report slots: one bit each in pd_core_t.report_pending. */
#define PD_REPORT_SLOTS 8u

typedef struct pd_core {
    void *hal; /* handed back to every pd_hal_* call */
    /* Both big-endian, as on the wire: RESET_ACK copies one, RESET compares the
     * other, and the Uno has no 32-bit shifts to spare. */
    uint8_t boot_id[4]; /* this power-up's, from the HAL */
    uint8_t session[4]; /* the host session that owns the outputs; 0: none since power-up */
    pd_link_t link;
    protoduino_ArduinoIn in; /* the current frame's command, decoded as its payload completes */
    bool in_decoded;         /* `in` holds the current frame's command, decoded: until it ends */
    pd_dedupe_t dedupe;
    pd_outputs_t outputs;
    pd_failsafe_t failsafe;
    uint16_t decode_errors; /* COMMAND payloads that did not decode, since boot (wraps at 2^16) */
    pd_report_fn report;     /* NULL: no reports (pd_core_init: the inputs' InputReport) */
    pd_report_sent_fn report_sent;
    uint8_t report_pending;  /* bit N: slot N has a value to send */
    uint8_t report_since;    /* low byte of the ms report_pending stopped being 0 */
    /* The line rate (docs/protocol.md 5, *Line rate*): the RESET_ACK flag bit of the
     * rate the line runs at (0: the opening rate), and while a switch is not yet
     * confirmed by a frame at the new rate, the low 16 bits of the ms it was made
     * at in baud_at (baud_unconfirmed set). 4 B of the Uno's RAM. */
    uint8_t baud;
    bool baud_unconfirmed;
    uint16_t baud_at;
#if PD_FEATURE_USER
    pd_user_state_t user;    /* the user service's reports (pd_user.h) */
#endif
} pd_core_t;

/* Report slot `slot` has a new value: sent (pd_core_t.report builds it) when the line allows. */
static inline void pd_state_report(pd_core_t *core, uint8_t slot)
{
    if (core->report_pending == 0) {
        core->report_since = (uint8_t)pd_hal_millis(core->hal);
    }
    core->report_pending = (uint8_t)(core->report_pending | (1u << slot));
}

#endif /* PD_STATE_H */

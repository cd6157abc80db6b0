/*
 * The device as one value: link, dedupe window, outputs and failsafe, with no
 * globals, so the unit tests and the fuzzer can instantiate as many as they
 * like. The platform's main loop calls pd_core_init() once at power-up, then
 * offers received bytes with pd_core_rx()/pd_core_rx_byte() (keeping those it
 * did not take for the next pass) and calls pd_core_poll() often (at least
 * every few milliseconds: the failsafe, the inputs and reports run there).
 */
#ifndef PD_CORE_H
#define PD_CORE_H

#include <stddef.h>
#include <stdint.h>

#include "pd_dispatch.h"
#include "pd_failsafe.h"
#include "pd_hal.h"
#include "pd_link.h"
#include "pd_outputs.h"
#include "pd_protocol.h"
#include "pd_user.h"

/* Reported in DeviceInfo.firmware_version; follows the Python package's version. */
#define PD_FIRMWARE_VERSION "0.1.0"

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
    pd_dedupe_t dedupe;
    pd_outputs_t outputs;
    pd_failsafe_t failsafe;
    uint16_t decode_errors; /* COMMAND payloads that did not decode, since boot (wraps at 2^16) */
    pd_report_fn report;     /* NULL: no reports (pd_core_init: the inputs' InputReport) */
    pd_report_sent_fn report_sent;
    uint8_t report_pending;  /* bit N: slot N has a value to send */
    uint8_t report_since;    /* low byte of the ms report_pending stopped being 0 */
#if PD_FEATURE_USER
    pd_user_state_t user;    /* the user service's reports (pd_user.h) */
#endif
} pd_core_t;

/* Power-up state: nothing configured, link IDLE; sends EVENT BOOT. */
void pd_core_init(pd_core_t *core, void *hal);

/* Offer one byte; false: not taken (its frame's replies would not fit yet), offer it again. */
static inline bool pd_core_rx_byte(pd_core_t *core, uint8_t byte)
{
    return pd_link_rx_byte(core, byte);
}

/* Offer `len` bytes; returns how many were taken (the rest: offer again later). */
size_t pd_core_rx(pd_core_t *core, const uint8_t *data, size_t len);

/* Periodic work: the failsafe timer, speed steps, the inputs (pd_inputs_poll), at most one report. */
void pd_core_poll(pd_core_t *core);

/* Report slot `slot` has a new value: send it (pd_core_t.report builds it) when the line allows. */
static inline void pd_core_report(pd_core_t *core, uint8_t slot)
{
    if (core->report_pending == 0) {
        core->report_since = (uint8_t)pd_hal_millis(core->hal);
    }
    core->report_pending = (uint8_t)(core->report_pending | (1u << slot));
}

/*
 * A report gives way to a command frame arriving (its Ack goes first), but not
 * for longer than this: a host that keeps the line busy with commands must still
 * hear its inputs (freshness), and the command then waits for one report. About
 * a short command's time on the line: with 20 ms, six analog inputs at 200 Hz
 * lost a sample now and then (coalesced) to a host sending Pings back to back
 * (199.4 values/s per channel, bench part 7); with 2 ms, 199.4 to 200 (2 to 5
 * samples in 3,600 coalesced), and the Ping's round trip the same (1.17x its idle
 * value). A complete frame held for transmit room is never passed (link.rx_held).
 */
#define PD_REPORT_MAX_WAIT_MS 2u

/* Every configured output to its safe value, flag set, event sent (Stop, timeout). */
void pd_core_enter_safe(pd_core_t *core, protoduino_FailsafeCause cause);

/*
 * A RESET carrying `session`: the same session keeps its outputs and its
 * failsafe timer; another one releases every output and starts afresh.
 * Returns whether the session was resumed.
 */
bool pd_core_open_session(pd_core_t *core, const uint8_t session[4]);

#endif /* PD_CORE_H */

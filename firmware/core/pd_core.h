/*
 * The device's top: the one place that decides what runs. The platform's
 * main loop calls pd_core_init() once at power-up, then offers received bytes
 * with pd_core_rx()/pd_core_rx_byte() (keeping those it did not take for the
 * next pass) and calls pd_core_poll() often (at least every few milliseconds:
 * the failsafe, the inputs and reports run there).
 *
 * Received bytes go to the link, which says what each one did
 * (pd_link_event_t); the core acts on it: decodes a command's payload as soon
 * as it is in, runs the command once its packet passed the checks
 * (pd_dispatch), opens the session a RESET carries. Every call goes down from
 * here; nothing below calls back up (tests/c/test_include_graph.py).
 */
#ifndef PD_CORE_H
#define PD_CORE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "pd_state.h"

/*
 * The opening line rate, a build option (make -C firmware avr BAUD=..., or the
 * Arduino library's pd_config.h): the rate after power-up and the one the line
 * returns to when a switch is not confirmed (docs/protocol.md 5, *Line rate*).
 */
#if defined(ARDUINO) || defined(PD_CONFIG_H_WANTED)
#include "pd_config.h"
#endif
#ifndef PD_BAUD
#define PD_BAUD ((uint32_t)PD_OPENING_BAUDRATE)
#endif

/* Power-up state: nothing configured, link IDLE; sends EVENT BOOT. */
void pd_core_init(pd_core_t *core, void *hal);

/* Offer one byte; false: not taken (its frame's replies would not fit yet), offer it again. */
bool pd_core_rx_byte(pd_core_t *core, uint8_t byte);

/* Offer `len` bytes; returns how many were taken (the rest: offer again later). */
size_t pd_core_rx(pd_core_t *core, const uint8_t *data, size_t len);

/* Periodic work: the failsafe timer, speed steps, the inputs (pd_inputs_poll), at most one report. */
void pd_core_poll(pd_core_t *core);

/* Whether a report waits for pd_core_poll to send it (when the transmit queue has room): a
 * platform that polls on news need not poll for a drained queue otherwise (the Uno's loop). */
static inline bool pd_core_report_waiting(const pd_core_t *core)
{
    return core->report_pending != 0;
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
 * A RESET carrying `session` and the host's next message id: the same session
 * keeps its outputs, its failsafe timer and its dedupe window; another one
 * releases every output and starts afresh (the window too). Either way the
 * window's newest id becomes the one before `next_id`. Returns whether the
 * session was resumed.
 */
bool pd_core_open_session(pd_core_t *core, const uint8_t session[4], uint8_t next_id);

#endif /* PD_CORE_H */

/*
 * The failsafe timer (docs/protocol.md section 7). Rule: there is never a
 * commanded output without a running timer.
 *
 * - The timer counts from the last liveness message of the session (a Ping
 *   when the liveness source is LIVENESS_PING, a Heartbeat always), or from
 *   the handshake that opened the session. A RESET of the same session is not
 *   a sign of life from the application (a host that cannot hear the device
 *   re-handshakes forever) and does not feed it.
 * - When it runs out the outputs go safe, once per silence (`fired`).
 * - A Stop only enters the safe state; it does not stop the timer, which
 *   still fires at its deadline (a Control after the Stop is protected too).
 * - Once it ran out, Controls are refused (STATUS_FAILSAFE_EXPIRED) until the
 *   next liveness message: a value set then would have no timer behind it.
 *
 * Pure bookkeeping on a millisecond clock handed in by the caller, so the unit
 * tests run it on a fake clock; pd_core.c does the driving and reporting.
 */
#ifndef PD_FAILSAFE_H
#define PD_FAILSAFE_H

#include <stdbool.h>
#include <stdint.h>

typedef struct pd_failsafe {
    uint32_t alive_ms;   /* the last liveness message, or the session's start */
    uint32_t timeout_ms; /* this session's timeout */
    bool fired;          /* the timer ran out in this silence: outputs went safe */
    bool active;         /* the safe state was entered (timeout or Stop), no liveness since */
    bool heartbeat_only; /* LIVENESS_HEARTBEAT: a Ping does not feed the timer */
} pd_failsafe_t;

/* A new session (or power-up): default timeout and source, timer from now. */
void pd_failsafe_init(pd_failsafe_t *fs, uint32_t now_ms);

/* A liveness message: restart the timer, clear the flag. Returns whether it was set. */
bool pd_failsafe_alive(pd_failsafe_t *fs, uint32_t now_ms);

/* The timer has run out (wrap-safe: compares elapsed time, never absolute times). */
bool pd_failsafe_expired(const pd_failsafe_t *fs, uint32_t now_ms);

/* The timer has run out and the safe state was not yet entered for this silence. */
bool pd_failsafe_due(const pd_failsafe_t *fs, uint32_t now_ms);

/* The timer ran out and the outputs went safe. */
void pd_failsafe_fire(pd_failsafe_t *fs);

/* Stop: the flag is set, the timer keeps running. */
void pd_failsafe_stop(pd_failsafe_t *fs);

#endif /* PD_FAILSAFE_H */

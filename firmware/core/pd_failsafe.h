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
 * - Every entry into the safe state (timeout or Stop) advances `epoch`, which
 *   the Failsafe event carries. A liveness message counts only if it carries
 *   the current epoch: a host sends back the latest it saw, so a Ping written
 *   before the failsafe fired and held up on the way (a stalled network, a
 *   paused ser2net) can never restart the timer or clear the flag after it.
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
    uint8_t epoch;       /* safe states entered since power-up, modulo 256 */
    uint8_t cause;       /* the latest one's FailsafeCause */
    uint8_t pin;         /* an interlock's input pin (cause INTERLOCK) */
} pd_failsafe_t;

/* A new session (or power-up): default timeout and source, timer from now.
 * The epoch and cause are kept (they count since power-up: the caller zeroes
 * them once at power-up). */
void pd_failsafe_init(pd_failsafe_t *fs, uint32_t now_ms);

/* A liveness message carrying `epoch`: if that is the current epoch, restart
 * the timer and clear the flag. Returns PD_ALIVE_STALE (an older epoch: nothing
 * changed), PD_ALIVE_OK, or PD_ALIVE_CLEARED (the flag was set). */
enum { PD_ALIVE_STALE = 0, PD_ALIVE_OK = 1, PD_ALIVE_CLEARED = 2 };
uint8_t pd_failsafe_alive(pd_failsafe_t *fs, uint32_t now_ms, uint8_t epoch);

/* ConfigureFailsafe: restart the timer unless it already fired (a configuration
 * carries no epoch, so it never clears an expired failsafe). */
void pd_failsafe_restart(pd_failsafe_t *fs, uint32_t now_ms);

/* The timer has run out (wrap-safe: compares elapsed time, never absolute times). */
bool pd_failsafe_expired(const pd_failsafe_t *fs, uint32_t now_ms);

/* The timer has run out and the safe state was not yet entered for this silence. */
bool pd_failsafe_due(const pd_failsafe_t *fs, uint32_t now_ms);

/* The timer ran out and the outputs went safe: a new epoch. */
void pd_failsafe_fire(pd_failsafe_t *fs);

/* Stop: the flag is set, the timer keeps running; a new epoch. */
void pd_failsafe_stop(pd_failsafe_t *fs);

/* An interlock on `pin` tripped: as a Stop, with its own cause and pin. */
void pd_failsafe_interlock(pd_failsafe_t *fs, uint8_t pin);

#endif /* PD_FAILSAFE_H */

/*
 * The failsafe timer (docs/protocol.md section 7): FAILSAFE_TIMEOUT after the last
 * sign of a live host (a Ping, or the handshake / boot when no Ping came yet)
 * every configured output goes to its safe value, once per silence. Pure
 * bookkeeping on a millisecond clock handed in by the caller, so the unit
 * tests can run it on a fake clock; pd_core.c does the driving and reporting.
 */
#ifndef PD_FAILSAFE_H
#define PD_FAILSAFE_H

#include <stdbool.h>
#include <stdint.h>

typedef struct pd_failsafe {
    uint32_t alive_ms; /* when the host last showed it was alive */
    bool active;       /* the safe state was entered and no Ping cleared it yet */
} pd_failsafe_t;

void pd_failsafe_init(pd_failsafe_t *fs, uint32_t now_ms);

/* Restart the timer; the flag is left alone (only a Ping clears it). */
void pd_failsafe_restart(pd_failsafe_t *fs, uint32_t now_ms);

/* A Ping: restart the timer and clear the flag. Returns whether it was set. */
bool pd_failsafe_ping(pd_failsafe_t *fs, uint32_t now_ms);

/*
 * True when the timer has run out and the safe state was not yet entered for
 * this silence. Wrap-safe: compares elapsed time, never absolute times.
 */
bool pd_failsafe_due(const pd_failsafe_t *fs, uint32_t now_ms);

/* Mark the safe state as entered (timeout or Stop). */
void pd_failsafe_set(pd_failsafe_t *fs);

#endif /* PD_FAILSAFE_H */

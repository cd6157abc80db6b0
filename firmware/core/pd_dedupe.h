/*
 * Exactly once (docs/protocol.md section 7): the commands already executed,
 * so that a retransmission is answered again and never run twice.
 */
#ifndef PD_DEDUPE_H
#define PD_DEDUPE_H

#include <stdint.h>

#include "pd_protocol.h"

/*
 * The last PD_DEDUPE_WINDOW (message_id, status) pairs of executed commands.
 * Idempotent commands (PD_CMD_IDEMPOTENT in the command table: Ping, GetInfo)
 * are neither looked up nor recorded: they change nothing, so
 * answering a repeat in full is harmless (and a repeated Ping must still count
 * as liveness), and keeping them out leaves the whole window to commands that
 * move outputs, which are the ones a duplicate could hurt. The window survives
 * a RESET (a retransmission may straddle a new handshake); a reboot clears it.
 */
typedef struct pd_dedupe {
    uint32_t id[PD_DEDUPE_WINDOW];
    /* Two statuses a byte (every Status is below 16): 8 B of the Uno's RAM. */
    uint8_t status[(PD_DEDUPE_WINDOW + 1u) / 2u];
    uint8_t next;  /* slot the next entry overwrites */
    uint8_t count; /* valid entries, up to PD_DEDUPE_WINDOW */
} pd_dedupe_t;

void pd_dedupe_init(pd_dedupe_t *dd);
/* Stored status of `id`, or -1 if it is not in the window. */
int pd_dedupe_find(const pd_dedupe_t *dd, uint32_t id);
void pd_dedupe_add(pd_dedupe_t *dd, uint32_t id, uint8_t status);

#endif /* PD_DEDUPE_H */

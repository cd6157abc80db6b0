/*
 * Exactly once (docs/protocol.md section 7): the commands already executed,
 * so that a retransmission is answered again and never run twice.
 */
#ifndef PD_DEDUPE_H
#define PD_DEDUPE_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_protocol.h"

/*
 * Message ids are per session and sequential, 1..PD_MAX_MESSAGE_ID, wrapping
 * to 1 (section 7, *Message ids*). `newest` is N, the newest id received: an id
 * Y is newer when ahead(N, Y) = (Y - N) mod 127 is 1..PD_ID_AHEAD_MAX, and a
 * repeat only when it is in the window and back(N, Y) = (N - Y) mod 127 is
 * below PD_DEDUPE_WINDOW. An entry that falls that far back is dropped as N
 * moves, so an id met again after a wrap never finds its old entry.
 *
 * The window holds up to PD_DEDUPE_WINDOW (message_id, status) pairs of
 * executed commands, never one id twice. Idempotent commands (PD_CMD_IDEMPOTENT
 * in the command table: Ping, GetInfo) are neither looked up nor recorded: they
 * change nothing, so answering a repeat in full is harmless (and a repeated
 * Ping must still count as liveness), and keeping them out leaves the whole
 * window to commands that move outputs, which are the ones a duplicate could
 * hurt. A RESET sets N from its NEXT_ID; a resumed session keeps the window
 * (a retransmission may straddle a new handshake), a new one clears it, and
 * so does a reboot.
 */
typedef struct pd_dedupe {
    uint8_t id[PD_DEDUPE_WINDOW]; /* 0: a free slot (0 is never a message id) */
    /* Two statuses a byte (every Status is below 16): 8 B of the Uno's RAM. */
    uint8_t status[(PD_DEDUPE_WINDOW + 1u) / 2u];
    uint8_t next;   /* slot the next entry overwrites */
    uint8_t newest; /* N */
} pd_dedupe_t;

void pd_dedupe_init(pd_dedupe_t *dd);
/* A RESET of this version: N is the id before `next_id` (1..127); `clear` for a new session. */
void pd_dedupe_sync(pd_dedupe_t *dd, uint8_t next_id, bool clear);
/*
 * Split in two so that only the first stands between a command's delimiter and
 * its pin: pd_dedupe_lookup before the command runs, pd_dedupe_done once it ran
 * and its Ack is on its way (respond() in pd_dispatch.c). Nothing reads the
 * window between the two, so the pair decides as one call at either end would.
 *
 * A command with id `id` (1..127) arrived: its stored status if it is a repeat
 * (see above), else -1. Changes nothing.
 */
int pd_dedupe_lookup(const pd_dedupe_t *dd, uint8_t id);
/*
 * The command with id `id` (1..127) was answered: N moves to it if it is newer
 * (every id does that, section 7: idempotent commands and undecodable payloads
 * too), dropping the entries that fall too far behind; then, if `status` is 0
 * or more, the command is recorded as executed with that status (replacing a
 * stale entry of the same id). -1: not recorded (an idempotent command, a
 * payload that did not decode). Never called for a repeat (it moves nothing).
 */
void pd_dedupe_done(pd_dedupe_t *dd, uint8_t id, int status);

#endif /* PD_DEDUPE_H */

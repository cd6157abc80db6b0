/*
 * The application layer (docs/protocol.md section 7): decode one ArduinoIn with
 * nanopb, execute it, answer exactly one Ack; the dedupe window; events.
 */
#ifndef PD_DISPATCH_H
#define PD_DISPATCH_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "pd_protocol.h"
#include "protoduino.pb.h"

struct pd_core;

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

/*
 * One command being run: what its handler sees. The handler fills ack->result
 * (its which_result is preset from the table) and may set `then`, which runs
 * after the Ack was sent (a notice that must follow it, e.g. Failsafe).
 */
typedef struct pd_cmd {
    const protoduino_ArduinoIn *in;
    protoduino_Ack *ack;
    void (*then)(struct pd_core *core);
} pd_cmd_t;

/* A command table entry's flags and result (pd_dispatch.c, where they are described). */
typedef struct pd_command {
    uint8_t flags;
    uint8_t result;
} pd_command_t;

/* A COMMAND packet's payload, received while ACTIVE. */
/*
 * Decode a COMMAND payload into core->in. The link calls it as soon as the
 * payload's last byte has arrived, before the CRC and the delimiter (3 byte
 * times, 280 us at 115200 baud), so that nanopb's share of a frame's work
 * overlaps the wire instead of delaying the Ack. Nothing is executed here.
 * Returns whether the payload decoded.
 */
bool pd_dispatch_decode(struct pd_core *core, const uint8_t *payload, size_t len);

/* core->in back to all zeros, as pd_dispatch_decode requires (at start-up and
 * after every frame whose payload it decoded). */
void pd_dispatch_clear(struct pd_core *core);

/* Run and answer the checked COMMAND in core->in (`decoded`: what pd_dispatch_decode said). */
void pd_dispatch_command(struct pd_core *core, bool decoded);

/* Send one ArduinoOut as a DATA packet (only while ACTIVE). */
bool pd_dispatch_send(struct pd_core *core, const protoduino_ArduinoOut *msg);

/*
 * Send an unsolicited message (a report) if the transmit queue has room for it
 * and for a reply (PD_TX_RESERVE: on the Uno, if it is empty) and, if `yield`,
 * no command frame is being received (pd_link.h). Returns whether it was queued.
 */
bool pd_dispatch_send_spare(struct pd_core *core, const protoduino_ArduinoOut *msg, bool yield);

/* ArduinoOut.failsafe: the failsafe state now (active, cause, epoch). */
bool pd_dispatch_send_failsafe(struct pd_core *core);

#endif /* PD_DISPATCH_H */

/*
 * The application layer (docs/protocol.md section 7): decode one ArduinoIn with
 * nanopb, execute it, answer exactly one Ack, exactly once (pd_dedupe). The
 * core calls it; it calls only down: the outputs, the inputs, and pd_out to
 * send its answers.
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

/*
 * Decode a COMMAND payload into core->in. The core calls it as soon as the
 * link has the payload's last byte (PD_LINK_PAYLOAD), before the CRC and the
 * delimiter (3 byte times, 280 us at 115200 baud), so that nanopb's share of a
 * frame's work overlaps the wire instead of delaying the Ack. Nothing is
 * executed here. Returns whether the payload decoded.
 */
bool pd_dispatch_decode(struct pd_core *core, const uint8_t *payload, size_t len);

/*
 * pd_dispatch_decode's two ways, into `in`. _short takes a payload of the usual
 * shape (the message id, then one command, each tag and length one byte) and
 * decodes the command alone, a pin mode's Control by its generated decoder
 * (generated/pd_fastdec.h), any other by nanopb with its own descriptor: 1 decoded, 0 not,
 * -1 another shape. _full is nanopb's decode of the whole ArduinoIn, for every
 * other payload. Where _short takes a payload, both leave `in` and the answer
 * the same (the unit tests and fuzz_dispatch.c compare them).
 */
int pd_dispatch_decode_short(protoduino_ArduinoIn *in, const uint8_t *payload, size_t len);
bool pd_dispatch_decode_full(protoduino_ArduinoIn *in, const uint8_t *payload, size_t len);

/* Run and answer the checked COMMAND in core->in (`decoded`: what pd_dispatch_decode said). */
void pd_dispatch_command(struct pd_core *core, bool decoded);

#endif /* PD_DISPATCH_H */

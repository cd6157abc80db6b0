/*
 * The link layer (docs/protocol.md sections 2, 5 and 6): the streaming
 * receiver, packet checks, the IDLE/ACTIVE state machine with RESET/RESET_ACK,
 * SEQ accounting, link events, and the transmit path. It knows nothing above
 * it: it is given bytes and a HAL, and returns what happened (pd_link_event_t);
 * the core decides what runs.
 *
 * Receive recovery policy, the same as the host's framing.py: bytes are
 * collected until a 0x00; an empty frame is ignored; anything else is checked
 * (COBS, length, CRC, type), and dropped and counted by reason if it fails.
 * The work is done as the bytes arrive: each one is COBS-decoded into rx_buf
 * (pd_cobs_rx_byte) and advances the CRC, and as soon as a COMMAND's payload
 * is all in the link says so (PD_LINK_PAYLOAD), while the CRC and the
 * delimiter are still on the wire, so that the core has it decoded by then;
 * at the delimiter only the checks and the command remain (the round trip's
 * share of the device). Nothing runs unchecked: the command is run only on
 * PD_LINK_COMMAND, once the whole packet passed. More than
 * PD_MAX_ENCODED_FRAME bytes without a 0x00 is an overflow: the buffer is
 * discarded, EVENT RX_OVERFLOW is sent and everything up to the next 0x00 is
 * skipped. So a corrupted frame never damages the next one, and no timer is
 * needed.
 *
 * Transmit: a frame is built on the stack, encoded into a bounded buffer and
 * handed to the HAL's transmit queue whole, in the order the core produces
 * them; the platform drains the queue in the background (pd_hal.h). Replies
 * (Acks, CONTROL, the notices that follow an Ack) go in at once. A received
 * frame is only acted upon while the queue has room for everything it can
 * make the device send (PD_TX_RESERVE): otherwise its delimiter is left
 * unconsumed (PD_LINK_HELD), the bytes wait in the platform's receive buffer
 * (which the host's flow control keeps from overflowing) and the loop goes
 * on. Unsolicited reports go in only when room beyond that reserve remains
 * (pd_link_send_spare), so they never hold up a reply by more than one short
 * frame. DATA is sent only while ACTIVE; CONTROL always.
 */
#ifndef PD_LINK_H
#define PD_LINK_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "pd_cobs.h"
#include "pd_encode.h"
#include "pd_protocol.h"
#include "protoduino.pb.h"

/* Largest payload the device sends: one ArduinoOut (CONTROL payloads are <= 11 B). */
#define PD_TX_MAX_PAYLOAD PD_ENCODE_MAX
/* The longest packet the device stores: a COMMAND with the largest ArduinoIn
 * nanopb can decode (every field bounded in protoduino.options). A longer packet
 * cannot carry a valid command, so it is dropped as a length error as soon as its
 * frame ends (docs/protocol.md section 3). Sized so rather than to MAX_PAYLOAD:
 * the 117 bytes this saves on the Uno are stack, which a Pose's decode next to
 * its reply needs (with a 260-byte buffer the stack reached the static data). */
#define PD_RX_PACKET_MAX (PD_MIN_PACKET + protoduino_ArduinoIn_size)
#define PD_TX_RAW_MAX (PD_MIN_PACKET + PD_TX_MAX_PAYLOAD)
/* Encoded frame plus an optional leading 0x00 and the delimiter. */
#define PD_TX_FRAME_BYTES(payload) (PD_COBS_MAX_ENCODED(PD_MIN_PACKET + (payload)) + 2u)
#define PD_TX_FRAME_MAX PD_TX_FRAME_BYTES(PD_TX_MAX_PAYLOAD)
/* A CONTROL frame (payloads are <= 6 B: RESET_ACK) and a notice (Failsafe, DecodeError: <= 12 B). */
#define PD_TX_CONTROL_MAX PD_TX_FRAME_BYTES(6u)
#define PD_TX_NOTICE_MAX PD_TX_FRAME_BYTES(12u)
/*
 * The most one received frame can make the device send: the largest Ack
 * alone, or an Ack and the notice that follows it (a Failsafe after a Stop, a
 * liveness message or a ClearInterlock: of their Acks only a Ping's is large,
 * its echo and its failsafe state), or a DecodeError and its Ack (smaller).
 * A frame is acted upon only when the transmit queue has this much room; every
 * platform's queue holds more. An EVENT DESYNC sent before the Ack is not
 * counted (every byte of the Uno's ring is RAM): after a desync, which a clean
 * line never causes, an Ack may not fit and is retransmitted.
 */
#define PD_TX_LIVENESS_ACK_MAX (2u + 8u + 66u + 2u + protoduino_Failsafe_size)
#define PD_TX_RESERVE                                                        \
    PD_ENCODE_MAX2(PD_TX_FRAME_MAX, PD_TX_FRAME_BYTES(PD_TX_LIVENESS_ACK_MAX) + PD_TX_NOTICE_MAX)
/*
 * A platform's transmit queue holds at least the reserve (checked at compile
 * time by each platform). A report goes in only when the queue has room for it
 * and for a reply, and no command frame is arriving (pd_link_send_spare):
 * on the Uno, whose queue is the reserve, into an empty queue. So a reply
 * waits behind one report at most, the one on the line, and the queue keeps
 * no room beside the reserve for reports (every byte of it is the Uno's RAM).
 */

/*
 * Diagnostic counters; they wrap, nothing depends on them. No message carries
 * them to the host, so the Uno build leaves them out (PD_STATS=0) to save RAM;
 * the unit tests and the simulated board keep them.
 */
#ifndef PD_STATS
#ifdef __AVR__
#define PD_STATS 0
#else
#define PD_STATS 1
#endif
#endif
#if PD_STATS
#define PD_STAT_ADD(link, counter, n) ((link)->stats.counter = (uint16_t)((link)->stats.counter + (n)))
#else
#define PD_STAT_ADD(link, counter, n) ((void)(n))
#endif
#define PD_STAT_INC(link, counter) PD_STAT_ADD(link, counter, 1u)

typedef struct pd_link_stats {
    uint16_t packets;      /* valid packets received */
    uint16_t drop_cobs;    /* frame was not valid COBS */
    uint16_t drop_length;  /* packet shorter than 5 bytes or LEN disagrees */
    uint16_t drop_crc;
    uint16_t drop_type;
    uint16_t rx_overflow;  /* frames longer than PD_MAX_ENCODED_FRAME */
    uint16_t seq_lost;     /* packets lost according to SEQ gaps <= 50 */
    uint16_t seq_desync;   /* SEQ jumps > 50 (or backwards) */
    uint16_t not_active;   /* COMMANDs dropped before the handshake */
    uint16_t ignored;      /* DATA, RESET_ACK, EVENT or unknown CONTROL from the host */
    uint16_t tx_frames;    /* frames the HAL accepted */
    uint16_t tx_failed;    /* frames the HAL refused, or DATA while IDLE */
} pd_link_stats_t;

typedef struct pd_link {
    uint8_t rx_buf[PD_RX_PACKET_MAX]; /* the packet, decoded as it arrives */
    uint16_t rx_len;  /* encoded bytes of the current frame so far */
    uint16_t rx_out;  /* decoded bytes so far (may pass rx_buf's size: then too long) */
    uint16_t rx_crc;  /* CRC-16 over the decoded bytes so far */
    pd_cobs_rx_t rx_cobs; /* the current frame's COBS decoder */
    bool rx_skipping; /* after an overflow, until the next 0x00 */
    bool rx_held;     /* the current frame is complete, held until its replies fit */
    bool active;      /* IDLE until the first RESET */
    bool tx_flush;    /* send a lone 0x00 before the next frame */
    uint8_t tx_seq;   /* SEQ of the next frame we send */
    uint8_t rx_seq;   /* SEQ we expect next */
#if PD_STATS
    pd_link_stats_t stats;
#endif
} pd_link_t;

void pd_link_init(pd_link_t *link);

/*
 * What one received byte did. The values from PD_LINK_COMMAND on end a frame
 * (the receiver has restarted): whatever the core kept of it (a decoded
 * command) is done with.
 */
typedef enum pd_link_event {
    PD_LINK_NONE = 0, /* taken; the frame goes on (or there was none: noise, an empty frame) */
    PD_LINK_END,      /* pd_link_rx_byte only (its others: NONE, PAYLOAD), NOT taken: a
                       * delimiter or the byte past the longest frame; hand it to
                       * pd_link_rx_end */
    PD_LINK_HELD,     /* NOT taken: a delimiter completing a frame while the transmit queue has
                       * less than PD_TX_RESERVE of room; offer it again later */
    PD_LINK_PAYLOAD,  /* taken; a COMMAND's payload is all in (pd_link_payload), unchecked:
                       * decode it now, run it only on PD_LINK_COMMAND */
    PD_LINK_COMMAND,  /* a checked COMMAND while ACTIVE: run and answer it */
    PD_LINK_RESET,    /* a RESET of this version: the link is ACTIVE with SEQ restarted; open
                       * the session it carries (pd_link_session), then pd_link_reset_ack */
    PD_LINK_HANDLED,  /* a valid packet the link dealt with itself: CONTROL, DATA (ignored), a
                       * RESET of another version or a COMMAND while IDLE (both answered) */
    PD_LINK_BAUD,     /* a BAUD_SET while ACTIVE (docs/protocol.md 5, *Line rate*): the core
                       * answers it (pd_link_baud_ack) and may switch the rate */
    PD_LINK_DROPPED,  /* an error: not valid COBS, a length, CRC or TYPE error (counted) */
    PD_LINK_OVERFLOW  /* an error: no 0x00 in PD_MAX_ENCODED_FRAME bytes; EVENT RX_OVERFLOW
                       * sent, the rest skipped up to the next 0x00 */
} pd_link_event_t;

/* Whether `event` ended the frame. */
#define PD_LINK_ENDED(event) ((event) >= PD_LINK_COMMAND)

/*
 * Offer one received byte. Most bytes are only decoded and stored; the one
 * that ends a frame, a delimiter or one past the longest frame, may make the
 * link answer, so it goes on to pd_link_rx_end with the platform's HAL
 * (PD_LINK_END). Two calls rather than a HAL argument for every byte: on the
 * Uno, loading it for each one was 9 of its cycles a byte.
 */
pd_link_event_t pd_link_rx_byte(pd_link_t *link, uint8_t byte);

/* The byte pd_link_rx_byte returned PD_LINK_END for; `hal` is the platform's (pd_hal.h). */
pd_link_event_t pd_link_rx_end(pd_link_t *link, void *hal, uint8_t byte);

/* The COMMAND payload of PD_LINK_PAYLOAD and PD_LINK_COMMAND, valid until the next byte. */
static inline const uint8_t *pd_link_payload(const pd_link_t *link)
{
    return link->rx_buf + PD_HEADER_SIZE;
}

static inline uint8_t pd_link_payload_len(const pd_link_t *link)
{
    return link->rx_buf[1];
}

/* The session a PD_LINK_RESET carries (4 bytes, big-endian), valid until the next byte. */
static inline const uint8_t *pd_link_session(const pd_link_t *link)
{
    return link->rx_buf + PD_HEADER_SIZE + 2u;
}

/* The message id the host transmits next (1..127), from the same RESET (version 5). */
static inline uint8_t pd_link_next_id(const pd_link_t *link)
{
    return link->rx_buf[PD_HEADER_SIZE + 6u];
}

/* Answer PD_LINK_RESET: RESET_ACK with this power-up's id, whether the session resumed
 * and the line rates the board can switch to (pd_hal_baud_rates). */
void pd_link_reset_ack(pd_link_t *link, void *hal, const uint8_t boot_id[4], bool resumed);

/* The rate a PD_LINK_BAUD asks for (4 bytes, big-endian), valid until the next byte. */
static inline const uint8_t *pd_link_baud(const pd_link_t *link)
{
    return link->rx_buf + PD_HEADER_SIZE + 1u;
}

/* Answer PD_LINK_BAUD: BAUD_ACK with `rate` (4 bytes, big-endian; all 0: refused). */
bool pd_link_baud_ack(pd_link_t *link, void *hal, const uint8_t rate[4]);

/*
 * The buffer a frame is built in, in place: the lone 0x00 that may go first,
 * COBS's first code byte, the packet (its payload at PD_TX_PAYLOAD_AT) and the
 * delimiter. COBS encodes the packet over itself one byte to the left (each
 * byte is read before the encoder writes there, as no frame reaches a full
 * 254-byte block), so no second buffer holds the encoded frame: on the Uno
 * that buffer was 119 B of the stack under every reply, the deepest point.
 */
#define PD_TX_PACKET_AT 2u
#define PD_TX_PAYLOAD_AT (PD_TX_PACKET_AT + PD_HEADER_SIZE)
#define PD_TX_BUF (PD_TX_PACKET_AT + PD_TX_RAW_MAX + 1u)

/*
 * Send one packet whose payload (`len` bytes) already sits at
 * buf + PD_TX_PAYLOAD_AT, in a buffer of PD_TX_BUF bytes (which it overwrites).
 * Returns whether the HAL took the whole frame. DATA is refused while IDLE.
 */
bool pd_link_send(pd_link_t *link, void *hal, uint8_t type, uint8_t *buf, size_t len);

/*
 * The same for an unsolicited DATA packet (a report): sent only if the
 * transmit queue has room for it and for a reply (PD_TX_RESERVE: on the Uno,
 * if it is empty), no complete frame is held for room and, if `yield`, no
 * frame is being received. Returns whether it was queued.
 */
bool pd_link_send_spare(pd_link_t *link, void *hal, uint8_t *buf, size_t len, bool yield);

/*
 * Whether pd_link_send_spare would refuse any report now (a frame held, one
 * arriving if `yield`, less room than a reply's): checked before a report is
 * built and encoded, so that a command arriving does not wait behind that work.
 */
bool pd_link_spare_blocked(const pd_link_t *link, void *hal, bool yield);

/* CONTROL EVENT with the given code (allowed in any state). */
bool pd_link_send_event(pd_link_t *link, void *hal, uint8_t event);

#endif /* PD_LINK_H */

#include "pd_link.h"

#include <string.h>

#include "pd_crc.h"
#include "pd_hal.h"
#include "pd_packet.h"
#include "pd_schema.h"

typedef char pd_assert_tx_fits_len[(PD_TX_MAX_PAYLOAD <= PD_MAX_PAYLOAD) ? 1 : -1];
/* The notices PD_TX_RESERVE counts on fit PD_TX_NOTICE_MAX. */
typedef char pd_assert_notice_fits[(protoduino_Failsafe_size + 2u <= 12u &&
                                    protoduino_DecodeError_size + 2u <= 12u) ? 1 : -1];

/* The receiver's state at the start of a frame. Not inlined: LTO copied it
 * to its callers (init, delimiter, overflow): 24 B of the Uno's flash. */
static __attribute__((noinline)) void rx_restart(pd_link_t *link)
{
    link->rx_len = 0;
    link->rx_out = 0;
    link->rx_crc = PD_CRC16_INIT;
    pd_cobs_rx_start(&link->rx_cobs);
    link->rx_held = false;
}

void pd_link_init(pd_link_t *link)
{
    memset(link, 0, sizeof(*link));
    rx_restart(link);
    /* docs/protocol.md section 2: flush the receiver before our first frame. */
    link->tx_flush = true;
}

bool pd_link_send(pd_link_t *link, void *hal, uint8_t type, uint8_t *buf, size_t len)
{
    /* No full COBS block (254 bytes) in any frame: the in-place encoding's
     * condition (PD_TX_BUF), and PD_TX_FRAME_BYTES's size. */
    typedef char no_full_block[(PD_TX_RAW_MAX < 254u &&
                                PD_TX_BUF == PD_TX_FRAME_MAX) ? 1 : -1];
    (void)sizeof(no_full_block);
    uint8_t *raw = buf + PD_TX_PACKET_AT;
    size_t raw_len;
    if (type != PD_PACKET_CONTROL && !link->active) {
        PD_STAT_INC(link, tx_failed);
        return false;
    }
    if (pd_packet_build(type, link->tx_seq, raw + PD_HEADER_SIZE, len, raw, PD_TX_RAW_MAX,
                        &raw_len) != PD_PACKET_OK) {
        PD_STAT_INC(link, tx_failed);
        return false;
    }
    /* Encoded over the packet, one byte to its left (PD_TX_BUF says why that is safe). */
    size_t enc = pd_cobs_encode(raw, raw_len, buf + 1, PD_TX_BUF - 2u);
    if (enc == 0) {
        PD_STAT_INC(link, tx_failed);
        return false;
    }
    buf[1 + enc] = 0;
    uint8_t *frame = buf + 1;
    uint16_t frame_len = (uint16_t)(enc + 1u);
    if (link->tx_flush) {
        *--frame = 0;
        frame_len++;
    }
    if (!pd_hal_write(hal, frame, frame_len)) {
        /* Keep the SEQ (section 6) and flush whatever part of it went out. */
        PD_STAT_INC(link, tx_failed);
        link->tx_flush = true;
        return false;
    }
    link->tx_flush = false;
    link->tx_seq++;
    PD_STAT_INC(link, tx_frames);
    return true;
}

bool pd_link_spare_blocked(const pd_link_t *link, void *hal, bool yield)
{
    return link->rx_held || (yield && link->rx_len > 0) || pd_hal_tx_room(hal) < PD_TX_RESERVE;
}

bool pd_link_send_spare(pd_link_t *link, void *hal, uint8_t *buf, size_t len, bool yield)
{
    /* PD_TX_FRAME_BYTES(len) without its division: at the largest payload its
     * COBS term n / 254 is 0 (checked here), so it is 0 for every len <= that;
     * the division would be a libgcc call on the AVR, in flash and per report. */
    typedef char no_cobs_block[(PD_TX_FRAME_BYTES(PD_TX_MAX_PAYLOAD) ==
                                PD_MIN_PACKET + PD_TX_MAX_PAYLOAD + 3u) ? 1 : -1];
    (void)sizeof(no_cobs_block);
    size_t frame = PD_MIN_PACKET + len + 3u;
    /* A command frame under way is answered first: its Ack must not queue behind this
     * (`yield`: for a while), and a complete one held for room (rx_held) always goes
     * first, or a stream of reports taking every emptied queue would starve it. And
     * one report at a time, into a queue with room for a reply (on the Uno: an empty
     * one): a reply never waits behind more than the report on the line. */
    uint16_t room = pd_hal_tx_room(hal);
    if (len == 0 || link->rx_held || (yield && link->rx_len > 0) || room < frame ||
        room < PD_TX_RESERVE) {
        return false;
    }
    return pd_link_send(link, hal, PD_PACKET_DATA, buf, len);
}

/*
 * Out of line: its frame buffer (PD_TX_BUF) would otherwise join the frame of
 * the receive loop (pd_core_rx_byte), which is on the stack under every
 * command's decode and reply; on the Uno that was 115 of the stack's bytes at
 * its deepest point (a Pose's decode), which came within 34 B of the static data.
 */
static __attribute__((noinline)) bool send_control(pd_link_t *link, void *hal,
                                                   const uint8_t *payload, size_t len)
{
    uint8_t buf[PD_TX_BUF];
    memcpy(buf + PD_TX_PAYLOAD_AT, payload, len);
    return pd_link_send(link, hal, PD_PACKET_CONTROL, buf, len);
}

bool pd_link_send_event(pd_link_t *link, void *hal, uint8_t event)
{
    const uint8_t payload[2] = {PD_CONTROL_EVENT, event};
    return send_control(link, hal, payload, sizeof(payload));
}

static void put_be32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)(v >> 16);
    p[2] = (uint8_t)(v >> 8);
    p[3] = (uint8_t)v;
}

/*
 * RESET_ACK (protocol.md section 5): CODE, VERSION, SCHEMA_ID and, to a host of
 * this version (`boot_id` given), the boot id and the session flags; to another
 * version the short form every version can read, so that the host names the
 * mismatch.
 */
static void send_reset_ack(pd_link_t *link, void *hal, const uint8_t *boot_id, uint8_t flags)
{
    uint8_t ack[PD_RESET_ACK_SIZE];
    uint8_t ack_len = PD_RESET_ACK_V1_SIZE;

    ack[0] = PD_CONTROL_RESET_ACK;
    ack[1] = PD_PROTOCOL_VERSION;
    put_be32(ack + 2, PD_SCHEMA_ID);
    if (boot_id != NULL) {
        memcpy(ack + 6, boot_id, 4);
        ack[10] = flags;
        ack_len = PD_RESET_ACK_SIZE;
    }
    send_control(link, hal, ack, ack_len);
}

void pd_link_reset_ack(pd_link_t *link, void *hal, const uint8_t boot_id[4], bool resumed)
{
    uint8_t flags = pd_hal_baud_rates(hal);
    send_reset_ack(link, hal, boot_id, resumed ? (uint8_t)(flags | PD_RESET_ACK_RESUMED) : flags);
}

bool pd_link_baud_ack(pd_link_t *link, void *hal, const uint8_t rate[4])
{
    const uint8_t ack[PD_BAUD_SIZE] = {PD_CONTROL_BAUD_ACK, rate[0], rate[1], rate[2], rate[3]};
    return send_control(link, hal, ack, sizeof(ack));
}

/*
 * RESET, answered whatever our state: clear the link state. Ours: become
 * ACTIVE, and the core opens or resumes the session and answers
 * (PD_LINK_RESET). Of another version: answer at once and stay IDLE: a host
 * that speaks another protocol commands nothing here.
 */
static pd_link_event_t handle_reset(pd_link_t *link, void *hal, const pd_packet_t *pkt)
{
    link->tx_seq = 0;
    link->rx_seq = 1;
    link->tx_flush = true; /* the host may hold a partial frame from before */
    /* Ours: 7 bytes, VERSION 5, a NEXT_ID in 1..127 (pd_link_next_id). */
    link->active = pkt->len == PD_RESET_SIZE && pkt->payload[1] == PD_PROTOCOL_VERSION &&
                   (uint8_t)(pkt->payload[6] - 1u) < PD_MAX_MESSAGE_ID;
    if (link->active) {
        return PD_LINK_RESET;
    }
    send_reset_ack(link, hal, NULL, 0);
    return PD_LINK_HANDLED;
}

static void count_seq(pd_link_t *link, void *hal, uint8_t seq)
{
    uint8_t d = (uint8_t)(seq - link->rx_seq);

    link->rx_seq = (uint8_t)(seq + 1u);
    if (d == 0) {
        return;
    }
    if (d <= PD_SEQ_DESYNC_THRESHOLD) {
        PD_STAT_ADD(link, seq_lost, d);
    } else {
        PD_STAT_INC(link, seq_desync);
        pd_link_send_event(link, hal, PD_EVENT_DESYNC);
    }
}

/* The frame in rx_buf, complete: checked, and what it asks for. */
static pd_link_event_t handle_frame(pd_link_t *link, void *hal)
{
    pd_packet_t pkt;

    if (!pd_cobs_rx_complete(&link->rx_cobs)) {
        PD_STAT_INC(link, drop_cobs); /* the last code byte points past the frame's end */
        return PD_LINK_DROPPED;
    }
    if (link->rx_out > sizeof(link->rx_buf)) {
        PD_STAT_INC(link, drop_length); /* longer than any command: not stored whole */
        return PD_LINK_DROPPED;
    }
    switch (pd_packet_check(link->rx_buf, link->rx_out, link->rx_crc, &pkt)) {
    case PD_PACKET_OK:
        break;
    case PD_PACKET_ERR_CRC:
        PD_STAT_INC(link, drop_crc);
        return PD_LINK_DROPPED;
    case PD_PACKET_ERR_TYPE:
        PD_STAT_INC(link, drop_type);
        return PD_LINK_DROPPED;
    default:
        PD_STAT_INC(link, drop_length);
        return PD_LINK_DROPPED;
    }
    PD_STAT_INC(link, packets);

    if (pkt.type == PD_PACKET_CONTROL && pkt.len >= 2 && pkt.payload[0] == PD_CONTROL_RESET) {
        /* Answered whatever our state; our VERSION goes back, the host judges. */
        return handle_reset(link, hal, &pkt);
    }
    if (link->active) {
        /* The packet is processed whatever its SEQ says (section 6). */
        count_seq(link, hal, pkt.seq);
    }
    if (pkt.type == PD_PACKET_COMMAND) {
        if (!link->active) {
            PD_STAT_INC(link, not_active);
            pd_link_send_event(link, hal, PD_EVENT_NOT_ACTIVE);
            return PD_LINK_HANDLED;
        }
        /* Its payload went out with PD_LINK_PAYLOAD: a packet that passed the
         * check had rx_out pass through PD_HEADER_SIZE + LEN, one byte at a
         * time, with its TYPE and LEN stored. */
        return PD_LINK_COMMAND;
    }
    if (pkt.type == PD_PACKET_CONTROL && link->active && pkt.len == PD_BAUD_SIZE &&
        pkt.payload[0] == PD_CONTROL_BAUD_SET) {
        return PD_LINK_BAUD; /* the rate is the core's to decide */
    }
    PD_STAT_INC(link, ignored);
    return PD_LINK_HANDLED;
}

/* One decoded byte: stored (while it fits) and into the CRC. */
static void rx_put(pd_link_t *link, uint8_t byte)
{
    if (link->rx_out < sizeof(link->rx_buf)) {
        link->rx_buf[link->rx_out] = byte;
        link->rx_crc = pd_crc16_byte(link->rx_crc, byte);
    }
    link->rx_out++; /* past the buffer: the length check drops the packet */
}

pd_link_event_t pd_link_rx_byte(pd_link_t *link, uint8_t byte)
{
    if (byte == 0 || link->rx_len >= PD_MAX_ENCODED_FRAME) {
        return PD_LINK_END; /* while skipping, rx_len stays 0 */
    }
    if (link->rx_skipping) {
        return PD_LINK_NONE;
    }
    link->rx_len++;
    /* Streaming COBS (PROTOCOL.md section 2), one call of rx_put (inlined: it
     * runs per byte), not one per case: 76 B of the Uno's flash. */
    if (!pd_cobs_rx_byte(&link->rx_cobs, &byte)) {
        return PD_LINK_NONE;
    }
    rx_put(link, byte);
    /* The payload a COMMAND's header announces is all in (the CRC and the
     * delimiter, 3 byte times, are still to come): the core decodes it now.
     * Whether the header told the truth, the packet check at the delimiter
     * decides. Checked only when a byte was stored, so rx_out reaches the
     * value once per frame. */
    if (link->rx_out == PD_HEADER_SIZE + (uint16_t)link->rx_buf[1] &&
        link->rx_out <= sizeof(link->rx_buf) - 2u && link->rx_buf[0] == PD_PACKET_COMMAND) {
        return PD_LINK_PAYLOAD;
    }
    return PD_LINK_NONE;
}

pd_link_event_t pd_link_rx_end(pd_link_t *link, void *hal, uint8_t byte)
{
    if (byte != 0) {
        /* One byte more than the longest frame. */
        rx_restart(link);
        link->rx_skipping = true;
        PD_STAT_INC(link, rx_overflow);
        pd_link_send_event(link, hal, PD_EVENT_RX_OVERFLOW);
        return PD_LINK_OVERFLOW;
    }
    pd_link_event_t event = PD_LINK_NONE;
    if (link->rx_skipping) {
        link->rx_skipping = false;
    } else if (link->rx_len > 0) {
        if (pd_hal_tx_room(hal) < PD_TX_RESERVE) {
            link->rx_held = true; /* no report may take the room it waits for */
            return PD_LINK_HELD;  /* its replies would not fit: later */
        }
        event = handle_frame(link, hal);
    }
    /* rx_buf is kept: the command and the session in it are read after this returns. */
    rx_restart(link);
    return event;
}

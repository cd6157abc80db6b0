#include "pd_link.h"

#include <string.h>

#include "pd_core.h"
#include "pd_crc.h"
#include "pd_dispatch.h"
#include "pd_packet.h"
#include "pd_schema.h"

typedef char pd_assert_tx_fits_len[(PD_TX_MAX_PAYLOAD <= PD_MAX_PAYLOAD) ? 1 : -1];
/* The notices PD_TX_RESERVE counts on fit PD_TX_NOTICE_MAX. */
typedef char pd_assert_notice_fits[(protoduino_Failsafe_size + 2u <= 12u &&
                                    protoduino_DecodeError_size + 2u <= 12u) ? 1 : -1];

/* The receiver's state at the start of a frame. Not inlined: LTO copied it
 * to its three callers (init, delimiter, overflow): 24 B of the Uno's flash. */
static __attribute__((noinline)) void rx_restart(pd_link_t *link)
{
    link->rx_len = 0;
    link->rx_out = 0;
    link->rx_crc = PD_CRC16_INIT;
    link->rx_left = 0;
    link->rx_zero = false;
    link->rx_decoded = false;
    link->rx_in_used = false;
    link->rx_held = false;
}

/* The end of a frame, handled or dropped: core->in back to zeros for the next
 * decode (pd_dispatch_clear says why here), and the receiver restarted. */
static void rx_finish(pd_core_t *core)
{
    if (core->link.rx_in_used) {
        pd_dispatch_clear(core);
    }
    rx_restart(&core->link);
}

void pd_link_init(pd_link_t *link)
{
    memset(link, 0, sizeof(*link));
    rx_restart(link);
    /* docs/protocol.md section 2: flush the receiver before our first frame. */
    link->tx_flush = true;
}

bool pd_link_send(pd_core_t *core, uint8_t type, uint8_t *buf, size_t len)
{
    /* No full COBS block (254 bytes) in any frame: the in-place encoding's
     * condition (PD_TX_BUF), and PD_TX_FRAME_BYTES's size. */
    typedef char no_full_block[(PD_TX_RAW_MAX < 254u &&
                                PD_TX_BUF == PD_TX_FRAME_MAX) ? 1 : -1];
    (void)sizeof(no_full_block);
    pd_link_t *link = &core->link;
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
    if (!pd_hal_write(core->hal, frame, frame_len)) {
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

/*
 * Out of line: its frame buffer (PD_TX_BUF) would otherwise join the frame
 * of pd_link_rx_byte, which is on the stack under every command's decode and
 * reply; on the Uno that was 115 of the stack's bytes at its deepest point (a
 * Pose's decode), which came within 34 B of the static data.
 */
static __attribute__((noinline)) bool send_control(pd_core_t *core, const uint8_t *payload,
                                                   size_t len)
{
    uint8_t buf[PD_TX_BUF];
    memcpy(buf + PD_TX_PAYLOAD_AT, payload, len);
    return pd_link_send(core, PD_PACKET_CONTROL, buf, len);
}

bool pd_link_send_event(pd_core_t *core, uint8_t event)
{
    const uint8_t payload[2] = {PD_CONTROL_EVENT, event};
    return send_control(core, payload, sizeof(payload));
}

static void put_be32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)(v >> 16);
    p[2] = (uint8_t)(v >> 8);
    p[3] = (uint8_t)v;
}

/*
 * RESET (protocol.md section 5). Ours: clear the link state, open or resume
 * the session, answer RESET_ACK with the boot id, become ACTIVE. Of another
 * version: answer with the short RESET_ACK every version can read (code,
 * VERSION, SCHEMA_ID), so that the host names the mismatch, and stay IDLE:
 * a host that speaks another protocol commands nothing here.
 */
static void handle_reset(pd_core_t *core, const uint8_t *payload, uint8_t len)
{
    pd_link_t *link = &core->link;
    uint8_t ack[PD_RESET_ACK_SIZE];
    uint8_t ack_len = PD_RESET_ACK_V1_SIZE;

    ack[0] = PD_CONTROL_RESET_ACK;
    ack[1] = PD_PROTOCOL_VERSION;
    put_be32(ack + 2, PD_SCHEMA_ID);
    link->tx_seq = 0;
    link->rx_seq = 1;
    link->tx_flush = true; /* the host may hold a partial frame from before */
    if (len == PD_RESET_SIZE && payload[1] == PD_PROTOCOL_VERSION) {
        memcpy(ack + 6, core->boot_id, 4);
        ack[10] = pd_core_open_session(core, payload + 2) ? PD_RESET_ACK_RESUMED : 0u;
        ack_len = PD_RESET_ACK_SIZE;
        link->active = true;
    } else {
        link->active = false;
    }
    send_control(core, ack, ack_len);
}

static void count_seq(pd_core_t *core, uint8_t seq)
{
    pd_link_t *link = &core->link;
    uint8_t d = (uint8_t)(seq - link->rx_seq);

    link->rx_seq = (uint8_t)(seq + 1u);
    if (d == 0) {
        return;
    }
    if (d <= PD_SEQ_DESYNC_THRESHOLD) {
        PD_STAT_ADD(link, seq_lost, d);
    } else {
        PD_STAT_INC(link, seq_desync);
        pd_link_send_event(core, PD_EVENT_DESYNC);
    }
}

static void handle_frame(pd_core_t *core)
{
    pd_link_t *link = &core->link;
    pd_packet_t pkt;

    if (link->rx_left != 0) {
        PD_STAT_INC(link, drop_cobs); /* the last code byte points past the frame's end */
        return;
    }
    if (link->rx_out > sizeof(link->rx_buf)) {
        PD_STAT_INC(link, drop_length); /* longer than any command: not stored whole */
        return;
    }
    switch (pd_packet_check(link->rx_buf, link->rx_out, link->rx_crc, &pkt)) {
    case PD_PACKET_OK:
        break;
    case PD_PACKET_ERR_CRC:
        PD_STAT_INC(link, drop_crc);
        return;
    case PD_PACKET_ERR_TYPE:
        PD_STAT_INC(link, drop_type);
        return;
    default:
        PD_STAT_INC(link, drop_length);
        return;
    }
    PD_STAT_INC(link, packets);

    if (pkt.type == PD_PACKET_CONTROL && pkt.len >= 2 && pkt.payload[0] == PD_CONTROL_RESET) {
        /* Answered whatever our state; our VERSION goes back, the host judges. */
        handle_reset(core, pkt.payload, pkt.len);
        return;
    }
    if (link->active) {
        /* The packet is processed whatever its SEQ says (section 6). */
        count_seq(core, pkt.seq);
    }
    if (pkt.type == PD_PACKET_COMMAND) {
        if (!link->active) {
            PD_STAT_INC(link, not_active);
            pd_link_send_event(core, PD_EVENT_NOT_ACTIVE);
            return;
        }
        /* Decoded already: a packet that passed the check had rx_out pass through
         * PD_HEADER_SIZE + LEN, one byte at a time, with its TYPE and LEN stored. */
        pd_dispatch_command(core, link->rx_decoded);
        return;
    }
    PD_STAT_INC(link, ignored);
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

bool pd_link_rx_byte(pd_core_t *core, uint8_t byte)
{
    pd_link_t *link = &core->link;

    if (byte == 0) {
        if (link->rx_skipping) {
            link->rx_skipping = false;
        } else if (link->rx_len > 0) {
            if (pd_hal_tx_room(core->hal) < PD_TX_RESERVE) {
                link->rx_held = true; /* no report may take the room it waits for */
                return false; /* its replies would not fit: later */
            }
            handle_frame(core);
        }
        rx_finish(core);
        return true;
    }
    if (link->rx_skipping) {
        return true;
    }
    if (link->rx_len >= PD_MAX_ENCODED_FRAME) {
        rx_finish(core);
        link->rx_skipping = true;
        PD_STAT_INC(link, rx_overflow);
        pd_link_send_event(core, PD_EVENT_RX_OVERFLOW);
        return true;
    }
    link->rx_len++;
    /* Streaming COBS (PROTOCOL.md section 2): a code byte starts a block of
     * code - 1 data bytes; every block but a full one (0xFF) and the last
     * implies a 0x00, emitted here once the next block shows it was not the last. */
    /* One call of rx_put (inlined: it runs per byte), not one per case: 76 B of
     * the Uno's flash. */
    bool put = true;
    if (link->rx_left == 0) {
        put = link->rx_zero; /* the previous block's implied 0x00, if any */
        link->rx_left = (uint8_t)(byte - 1u);
        link->rx_zero = byte != 0xFFu;
        byte = 0;
    } else {
        link->rx_left--;
    }
    if (put) {
        rx_put(link, byte);
    }
    /* The payload a COMMAND's header announces is all in (the CRC and the
     * delimiter, 3 byte times, are still to come): decode it now. Whether the
     * header told the truth, the packet check at the delimiter decides. Checked
     * only when a byte was stored, so rx_out reaches the value once per frame. */
    if (put && link->rx_out == PD_HEADER_SIZE + (uint16_t)link->rx_buf[1] &&
        link->rx_out <= sizeof(link->rx_buf) - 2u && link->rx_buf[0] == PD_PACKET_COMMAND) {
        link->rx_in_used = true;
        link->rx_decoded = pd_dispatch_decode(core, link->rx_buf + PD_HEADER_SIZE, link->rx_buf[1]);
    }
    return true;
}

/* The link state machine: BOOT, RESET/RESET_ACK, NOT_ACTIVE, SEQ, overflow, TX rules; and the
 * link alone, without a core: what each received byte did (pd_link_event_t). */
#include <string.h>

#include <pb_encode.h>

#include "pd_cobs.h"
#include "pd_packet.h"
#include "pd_schema.h"
#include "pd_test.h"
#include "test_util.h"

static void test_boot_event(void)
{
    tdev_t d;
    t_boot(&d);
    CHECK_EQ(fake_count(&d.hal), 1);
    const fake_frame_t *f = fake_frame(&d.hal, 0);
    CHECK_EQ(f->type, PD_PACKET_CONTROL);
    CHECK_EQ(f->seq, 0);
    CHECK_EQ(f->len, 2);
    CHECK_EQ(f->payload[0], PD_CONTROL_EVENT);
    CHECK_EQ(f->payload[1], PD_EVENT_BOOT);
    CHECK(f->flushed); /* a lone 0x00 before the first frame */
    CHECK(!d.core.link.active);
}

static void test_reset_ack(void)
{
    tdev_t d;
    t_boot(&d);
    fake_clear(&d.hal);
    t_send_reset(&d, PD_PROTOCOL_VERSION);
    CHECK_EQ(fake_count(&d.hal), 1);
    const fake_frame_t *f = fake_frame(&d.hal, 0);
    const uint32_t boot = d.hal.boots; /* the fake's boot id */
    const uint8_t expect[11] = {PD_CONTROL_RESET_ACK, PD_PROTOCOL_VERSION,
                                (uint8_t)(PD_SCHEMA_ID >> 24), (uint8_t)(PD_SCHEMA_ID >> 16),
                                (uint8_t)(PD_SCHEMA_ID >> 8), (uint8_t)PD_SCHEMA_ID,
                                (uint8_t)(boot >> 24), (uint8_t)(boot >> 16),
                                (uint8_t)(boot >> 8), (uint8_t)boot,
                                0 /* a new session */};
    CHECK_EQ(f->type, PD_PACKET_CONTROL);
    CHECK_EQ(f->seq, 0);
    CHECK_EQ(f->len, 11);
    CHECK(memcmp(f->payload, expect, 11) == 0);
    const uint8_t session[4] = {(uint8_t)(T_SESSION >> 24), (uint8_t)(T_SESSION >> 16),
                                (uint8_t)(T_SESSION >> 8), (uint8_t)T_SESSION};
    CHECK(memcmp(d.core.session, session, 4) == 0);
    CHECK(d.core.link.active);
    /* The next frame we send carries SEQ 1. */
    protoduino_ArduinoIn in = m_info(5);
    t_send_in(&d, &in);
    CHECK_EQ(fake_frame(&d.hal, 1)->seq, 1);
}

static void test_reset_other_version_still_answered(void)
{
    tdev_t d;
    t_boot(&d);
    fake_clear(&d.hal);
    t_send_reset(&d, 1); /* a version 1 host: CODE VERSION */
    CHECK_EQ(fake_count(&d.hal), 1);
    /* The short form every version parses: CODE VERSION SCHEMA_ID; the host judges. */
    CHECK_EQ(fake_frame(&d.hal, 0)->len, PD_RESET_ACK_V1_SIZE);
    CHECK_EQ(fake_frame(&d.hal, 0)->payload[0], PD_CONTROL_RESET_ACK);
    CHECK_EQ(fake_frame(&d.hal, 0)->payload[1], PD_PROTOCOL_VERSION);
    CHECK(!d.core.link.active); /* and it commands nothing here */
    protoduino_ArduinoIn in = m_digital_init(9, 13, true);
    t_send_in(&d, &in);
    CHECK_EQ(t_events(&d, PD_EVENT_NOT_ACTIVE), 1);
    CHECK_EQ(d.hal.digital[13], -1);
}

static void test_reset_of_another_version_leaves_the_session(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_digital_init(1, 13, true);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    const uint8_t other[PD_RESET_SIZE] = {PD_CONTROL_RESET, PD_PROTOCOL_VERSION + 1, 0, 0, 0, 9, 1};
    t_send_packet(&d, PD_PACKET_CONTROL, 0, other, sizeof(other));
    CHECK(!d.core.link.active);
    CHECK_EQ(d.hal.digital[13], 1); /* not released: no session was opened */
    t_send_reset(&d, PD_PROTOCOL_VERSION);
    CHECK_EQ(fake_frame(&d.hal, fake_count(&d.hal) - 1)->payload[10], PD_RESET_ACK_RESUMED);
}

static void test_new_session_releases_same_session_resumes(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_deg(1, 9, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    in = m_digital_init(2, 13, true);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    in = m_servo_deg(3, 9, 0);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    /* The same session again (a watchdog re-handshake, a reconnect): all kept. */
    fake_clear(&d.hal);
    t_send_reset_session(&d, T_SESSION);
    CHECK_EQ(fake_frame(&d.hal, 0)->len, PD_RESET_ACK_SIZE);
    CHECK_EQ(fake_frame(&d.hal, 0)->payload[10], PD_RESET_ACK_RESUMED);
    CHECK_EQ(d.hal.servo_us[9], 544);
    CHECK_EQ(d.hal.digital[13], 1);
    /* Another session: every output released, the pins free for any mode. */
    fake_clear(&d.hal);
    t_send_reset_session(&d, 0xABCDEF01u);
    CHECK_EQ(fake_frame(&d.hal, 0)->payload[10], 0);
    CHECK_EQ(d.hal.servo_us[9], 0); /* no pulses */
    CHECK_EQ(d.hal.digital[13], -1); /* an input */
    CHECK_EQ(d.core.outputs.owner[9], 0);
    CHECK_EQ(pd_pins_count(d.core.outputs.owner, PD_MODE_SERVO), 0);
    in = m_digital_init(4, 9, false);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    /* Session 0 is never resumed (it means "none" on the device). */
    fake_clear(&d.hal);
    t_send_reset_session(&d, 0);
    CHECK_EQ(fake_frame(&d.hal, 0)->payload[10], 0);
    t_send_reset_session(&d, 0);
    CHECK_EQ(fake_frame(&d.hal, 1)->payload[10], 0);
}

static void test_boot_id_differs_per_boot(void)
{
    tdev_t d;
    t_boot(&d);
    uint8_t first[4];
    memcpy(first, d.core.boot_id, 4);
    pd_core_init(&d.core, &d.hal);
    CHECK(memcmp(d.core.boot_id, first, 4) != 0);
}

static void test_reset_without_version_ignored(void)
{
    tdev_t d;
    t_boot(&d);
    fake_clear(&d.hal);
    const uint8_t payload[1] = {PD_CONTROL_RESET};
    t_send_packet(&d, PD_PACKET_CONTROL, 0, payload, 1);
    CHECK_EQ(fake_count(&d.hal), 0);
    CHECK(!d.core.link.active);
    CHECK_EQ(d.core.link.stats.ignored, 1);
}

static void test_command_before_reset_not_active(void)
{
    tdev_t d;
    t_boot(&d);
    fake_clear(&d.hal);
    protoduino_ArduinoIn in = m_digital_init(9, 13, true);
    t_send_in(&d, &in);
    CHECK_EQ(t_events(&d, PD_EVENT_NOT_ACTIVE), 1);
    CHECK_EQ(t_acks(&d, 9, NULL), 0);
    CHECK_EQ(d.hal.digital[13], -1); /* nothing executed */
    CHECK_EQ(d.core.link.stats.not_active, 1);
    /* After the handshake the same command works. */
    t_send_reset(&d, PD_PROTOCOL_VERSION);
    fake_clear(&d.hal);
    t_send_in(&d, &in);
    CHECK_EQ(t_status(&d, 9), protoduino_Status_STATUS_OK);
    CHECK_EQ(d.hal.digital[13], 1);
}

static void test_reset_again_resets_seq_keeps_outputs(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_deg(1, 9, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    in = m_servo_deg(2, 9, 0);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    CHECK_EQ(d.hal.servo_us[9], 544);
    for (int i = 0; i < 5; i++) {
        in = m_info((uint32_t)(10 + i));
        t_send_in(&d, &in);
    }
    fake_clear(&d.hal);
    unsigned writes = d.hal.servo_writes[9];
    t_send_reset(&d, PD_PROTOCOL_VERSION);
    CHECK_EQ(fake_count(&d.hal), 1);
    CHECK_EQ(fake_frame(&d.hal, 0)->seq, 0);
    CHECK(fake_frame(&d.hal, 0)->flushed);
    CHECK_EQ(d.hal.servo_us[9], 544);
    CHECK_EQ(d.hal.servo_writes[9], writes); /* outputs untouched */
    CHECK_EQ(pd_pins_count(d.core.outputs.owner, PD_MODE_SERVO), 1); /* configuration kept */
    in = m_info(30);
    t_send_in(&d, &in);
    CHECK_EQ(fake_frame(&d.hal, 1)->seq, 1);
    CHECK_EQ(d.core.link.stats.seq_lost, 0);
    CHECK_EQ(d.core.link.stats.seq_desync, 0);
}

static void test_seq_in_order_and_lost(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_info(1);
    t_send_in(&d, &in); /* SEQ 1: in order */
    CHECK_EQ(d.core.link.stats.seq_lost, 0);
    d.host_seq = (uint8_t)(d.host_seq + 3); /* 3 packets "lost" */
    in = m_info(2);
    fake_clear(&d.hal);
    t_send_in(&d, &in);
    CHECK_EQ(d.core.link.stats.seq_lost, 3);
    CHECK_EQ(d.core.link.stats.seq_desync, 0);
    CHECK_EQ(t_status(&d, 2), protoduino_Status_STATUS_OK);
    CHECK_EQ(t_events(&d, PD_EVENT_DESYNC), 0);
    /* A gap of exactly SEQ_DESYNC_THRESHOLD is still loss. */
    d.host_seq = (uint8_t)(d.host_seq + PD_SEQ_DESYNC_THRESHOLD);
    in = m_info(3);
    t_send_in(&d, &in);
    CHECK_EQ(d.core.link.stats.seq_lost, 3 + PD_SEQ_DESYNC_THRESHOLD);
    CHECK_EQ(d.core.link.stats.seq_desync, 0);
}

static void test_seq_desync_event_and_still_processed(void)
{
    tdev_t d;
    t_active(&d);
    d.host_seq = (uint8_t)(d.host_seq + PD_SEQ_DESYNC_THRESHOLD + 1);
    protoduino_ArduinoIn in = m_digital_init(4, 13, false);
    t_send_in(&d, &in);
    CHECK_EQ(d.core.link.stats.seq_desync, 1);
    CHECK_EQ(t_events(&d, PD_EVENT_DESYNC), 1);
    CHECK_EQ(t_status(&d, 4), protoduino_Status_STATUS_OK);
    CHECK_EQ(d.hal.digital[13], 0);
    /* The event (CONTROL) goes out before the Ack. */
    CHECK_EQ(fake_frame(&d.hal, 0)->type, PD_PACKET_CONTROL);
    /* Then the receiver expects SEQ + 1 again: no further counts. */
    in = m_info(5);
    t_send_in(&d, &in);
    CHECK_EQ(d.core.link.stats.seq_desync, 1);
    /* A step backwards is a desync too. */
    d.host_seq = (uint8_t)(d.host_seq - 2);
    in = m_info(6);
    t_send_in(&d, &in);
    CHECK_EQ(d.core.link.stats.seq_desync, 2);
}

static void test_seq_wraps(void)
{
    tdev_t d;
    t_active(&d);
    for (int i = 0; i < 300; i++) {
        protoduino_ArduinoIn in = m_info((uint32_t)(i + 1));
        t_send_in(&d, &in);
    }
    CHECK_EQ(d.core.link.stats.seq_lost, 0);
    CHECK_EQ(d.core.link.stats.seq_desync, 0);
    /* Our own SEQ wraps too: 300 acks after RESET_ACK(0) end at (300) mod 256. */
    const fake_frame_t *last = fake_frame(&d.hal, fake_count(&d.hal) - 1u);
    CHECK_EQ(last->seq, 300 % 256);
}

static void test_overflow_event_and_recovery(void)
{
    tdev_t d;
    t_active(&d);
    uint8_t junk[PD_MAX_ENCODED_FRAME + 40];
    memset(junk, 0x55, sizeof(junk));
    const uint8_t delimiter = 0;
    /* Exactly MAX_ENCODED_FRAME bytes is still a frame (a bad one here). */
    t_feed(&d, junk, PD_MAX_ENCODED_FRAME);
    t_feed(&d, &delimiter, 1);
    CHECK_EQ(d.core.link.stats.rx_overflow, 0);
    CHECK_EQ(d.core.link.stats.drop_cobs + d.core.link.stats.drop_length, 1);
    CHECK_EQ(fake_count(&d.hal), 0);
    t_feed(&d, junk, PD_MAX_ENCODED_FRAME + 40);
    CHECK_EQ(d.core.link.stats.rx_overflow, 1);
    CHECK_EQ(t_events(&d, PD_EVENT_RX_OVERFLOW), 1);
    /* A valid frame glued to the end of the run is skipped with it... */
    protoduino_ArduinoIn in = m_info(8);
    t_send_in(&d, &in);
    CHECK_EQ(t_acks(&d, 8, NULL), 0);
    /* ...and the next one after the 0x00 is received. */
    in = m_info(9);
    t_send_in(&d, &in);
    CHECK_EQ(t_status(&d, 9), protoduino_Status_STATUS_OK);
    CHECK_EQ(d.core.link.stats.rx_overflow, 1);
}

static void test_longest_frame_is_no_overflow_but_too_long_for_a_command(void)
{
    /* A 255-byte payload encodes to exactly MAX_ENCODED_FRAME bytes: no overflow.
     * No ArduinoIn is that long, so the device (which stores PD_RX_PACKET_MAX
     * bytes) drops it as a length error; the longest packet it stores passes. */
    tdev_t d;
    t_active(&d);
    uint8_t payload[PD_MAX_PAYLOAD];
    memset(payload, 0x11, sizeof(payload));
    t_send_packet(&d, PD_PACKET_COMMAND, d.host_seq++, payload, sizeof(payload));
    CHECK_EQ(d.core.link.stats.rx_overflow, 0);
    CHECK_EQ(d.core.link.stats.drop_length, 1);
    CHECK_EQ(d.core.link.stats.packets, 1); /* the RESET */
    t_send_packet(&d, PD_PACKET_COMMAND, d.host_seq++, payload,
                  PD_RX_PACKET_MAX - PD_MIN_PACKET);
    CHECK_EQ(d.core.link.stats.drop_length, 1);
    CHECK_EQ(d.core.link.stats.packets, 2);
}

static void test_noise_and_empty_frames_ignored(void)
{
    tdev_t d;
    t_active(&d);
    const uint8_t noise[] = {0, 0, 0, 0xAA, 0xBB, 0, 0x13, 0x37, 0x42, 0, 0};
    t_feed(&d, noise, sizeof(noise));
    CHECK_EQ(fake_count(&d.hal), 0);
    CHECK_EQ(d.core.link.stats.drop_cobs + d.core.link.stats.drop_length +
                 d.core.link.stats.drop_crc + d.core.link.stats.drop_type,
             2);
    protoduino_ArduinoIn in = m_info(3);
    t_send_in(&d, &in);
    CHECK_EQ(t_status(&d, 3), protoduino_Status_STATUS_OK);
}

static void test_data_and_stray_control_dropped(void)
{
    tdev_t d;
    t_active(&d);
    const uint8_t data_payload[] = {0x0a, 0x02, 0x08, 0x05};
    t_send_packet(&d, PD_PACKET_DATA, d.host_seq++, data_payload, sizeof(data_payload));
    const uint8_t old_heartbeat[] = {0x02}; /* HEARTBEAT until version 3: unknown since */
    t_send_packet(&d, PD_PACKET_CONTROL, d.host_seq++, old_heartbeat, 1);
    const uint8_t ack[] = {PD_CONTROL_RESET_ACK, 1, 0, 0, 0, 0};
    t_send_packet(&d, PD_PACKET_CONTROL, d.host_seq++, ack, sizeof(ack));
    const uint8_t unknown[] = {0x7F};
    t_send_packet(&d, PD_PACKET_CONTROL, d.host_seq++, unknown, 1);
    t_send_packet(&d, PD_PACKET_CONTROL, d.host_seq++, unknown, 0);
    CHECK_EQ(fake_count(&d.hal), 0);
    CHECK_EQ(d.core.link.stats.ignored, 5); /* every one */
    CHECK_EQ(d.core.link.stats.packets, 6);
}

static void test_data_only_while_active(void)
{
    tdev_t d;
    t_boot(&d);
    fake_clear(&d.hal);
    CHECK(!pd_out_send_failsafe(&d.core));
    CHECK_EQ(fake_count(&d.hal), 0);
    CHECK(pd_link_send_event(&d.core.link, &d.hal, PD_EVENT_DESYNC)); /* CONTROL goes in any state */
    CHECK_EQ(fake_count(&d.hal), 1);
}

static void test_failed_write_keeps_seq_and_flushes(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_info(1);
    t_send_in(&d, &in);
    CHECK_EQ(fake_frame(&d.hal, 0)->seq, 1);
    CHECK(!fake_frame(&d.hal, 0)->flushed);
    d.hal.fail_writes = true;
    in = m_info(2);
    t_send_in(&d, &in);
    CHECK_EQ(fake_count(&d.hal), 1);
    CHECK_EQ(d.core.link.stats.tx_failed, 1);
    d.hal.fail_writes = false;
    in = m_info(3);
    t_send_in(&d, &in);
    CHECK_EQ(fake_count(&d.hal), 2);
    CHECK_EQ(fake_frame(&d.hal, 1)->seq, 2); /* the failed frame's SEQ is reused */
    CHECK(fake_frame(&d.hal, 1)->flushed);   /* after a lone 0x00 */
    in = m_info(4);
    t_send_in(&d, &in);
    CHECK(!fake_frame(&d.hal, 2)->flushed);
}

static void test_reboot_returns_to_idle(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_digital_init(1, 13, true);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    fake_clear(&d.hal);
    pd_core_init(&d.core, &d.hal); /* what SIGUSR1 / a reset does */
    CHECK_EQ(t_events(&d, PD_EVENT_BOOT), 1);
    CHECK(!d.core.link.active);
    CHECK_EQ(d.core.outputs.owner[13], PD_MODE_FREE);
    in = m_digital(2, 13, false);
    t_send_in(&d, &in);
    CHECK_EQ(t_events(&d, PD_EVENT_NOT_ACTIVE), 1);
}

static void test_fed_in_any_chunking(void)
{
    /* pd_core_rx() over a whole buffer equals feeding byte by byte. */
    tdev_t a, b;
    t_active(&a);
    t_active(&b);
    protoduino_ArduinoIn in = m_digital_init(5, 12, true);
    t_send_in(&a, &in); /* reference: byte by byte */
    uint8_t pb[64], raw[80], stream[100];
    pb_ostream_t os = pb_ostream_from_buffer(pb, sizeof(pb));
    CHECK(pb_encode(&os, protoduino_ArduinoIn_fields, &in));
    size_t raw_len = 0;
    CHECK_EQ(pd_packet_build(PD_PACKET_COMMAND, b.host_seq++, pb, os.bytes_written, raw,
                             sizeof(raw), &raw_len),
             PD_PACKET_OK);
    size_t n = 0;
    stream[n++] = 0x99; /* noise first */
    stream[n++] = 0;
    n += pd_cobs_encode(raw, raw_len, stream + n, sizeof(stream) - n - 1u);
    stream[n++] = 0;
    pd_core_rx(&b.core, stream, n);
    CHECK_EQ(fake_count(&b.hal), 1);
    CHECK_EQ(t_status(&b, 5), protoduino_Status_STATUS_OK);
    CHECK_EQ(b.hal.digital[12], a.hal.digital[12]);
    CHECK_EQ(b.core.link.stats.packets, a.core.link.stats.packets);
}


/* --- the link alone: a pd_link_t, the fake HAL, and no core ---------------- */

/* A whole wire frame (delimiter included) of one packet; returns its length. */
static size_t wire_of(uint8_t type, uint8_t seq, const uint8_t *payload, size_t len, uint8_t *wire,
                      size_t cap)
{
    uint8_t raw[PD_MIN_PACKET + PD_MAX_PAYLOAD];
    size_t raw_len = 0;
    if (pd_packet_build(type, seq, payload, len, raw, sizeof(raw), &raw_len) != PD_PACKET_OK) {
        return 0;
    }
    size_t n = pd_cobs_encode(raw, raw_len, wire, cap - 1u);
    wire[n++] = 0;
    return n;
}

/* CONTROL EVENTs with `code` among the frames the link sent. */
static int hal_events(const fake_hal_t *hal, uint8_t code)
{
    int n = 0;
    for (size_t i = 0; i < fake_count(hal); i++) {
        const fake_frame_t *f = fake_frame(hal, i);
        n += f->type == PD_PACKET_CONTROL && f->len == 2 && f->payload[0] == PD_CONTROL_EVENT &&
             f->payload[1] == code;
    }
    return n;
}

/* Feed `wire` to the link as the core does; counts each event, returns the last one. */
static pd_link_event_t feed_link(pd_link_t *link, fake_hal_t *hal, const uint8_t *wire, size_t n,
                                 unsigned counts[PD_LINK_OVERFLOW + 1])
{
    pd_link_event_t event = PD_LINK_NONE;
    for (size_t i = 0; i < n; i++) {
        event = pd_link_rx_byte(link, wire[i]);
        if (event == PD_LINK_END) {
            event = pd_link_rx_end(link, hal, wire[i]);
        }
        counts[event]++;
    }
    return event;
}

static void link_active(pd_link_t *link, fake_hal_t *hal)
{
    const uint8_t reset[PD_RESET_SIZE] = {PD_CONTROL_RESET, PD_PROTOCOL_VERSION, 0xDE, 0xAD, 0xBE, 0xEF, 1};
    uint8_t wire[32];
    unsigned counts[PD_LINK_OVERFLOW + 1] = {0};
    fake_init(hal);
    pd_link_init(link);
    size_t n = wire_of(PD_PACKET_CONTROL, 0, reset, sizeof(reset), wire, sizeof(wire));
    CHECK_EQ(feed_link(link, hal, wire, n, counts), PD_LINK_RESET);
    CHECK_EQ(counts[PD_LINK_RESET], 1);
    CHECK_EQ(counts[PD_LINK_NONE], n - 1u);
    CHECK(link->active);
    /* The session is the core's to judge: the link hands it over and answers nothing yet. */
    CHECK(memcmp(pd_link_session(link), reset + 2, 4) == 0);
    CHECK_EQ(fake_count(hal), 0);
    const uint8_t boot[4] = {1, 2, 3, 4};
    pd_link_reset_ack(link, hal, boot, true);
    CHECK_EQ(fake_count(hal), 1);
    CHECK_EQ(fake_frame(hal, 0)->len, PD_RESET_ACK_SIZE);
    CHECK(memcmp(fake_frame(hal, 0)->payload + 6, boot, 4) == 0);
    CHECK_EQ(fake_frame(hal, 0)->payload[10], PD_RESET_ACK_RESUMED);
    fake_clear(hal);
}

static void test_link_alone_reports_a_command_payload_then_the_checked_command(void)
{
    pd_link_t link;
    fake_hal_t hal;
    link_active(&link, &hal);
    const uint8_t payload[] = {0x08, 0x07, 0x00, 0x12}; /* bytes, a zero among them */
    uint8_t wire[32];
    size_t n = wire_of(PD_PACKET_COMMAND, 1, payload, sizeof(payload), wire, sizeof(wire));
    unsigned counts[PD_LINK_OVERFLOW + 1] = {0};
    /* Up to the payload's last byte: nothing; at it, PD_LINK_PAYLOAD, with the CRC (2 bytes and
     * the COBS code they may need) and the delimiter still to come. */
    size_t i = 0;
    pd_link_event_t event = PD_LINK_NONE;
    while (i < n && event == PD_LINK_NONE) {
        event = feed_link(&link, &hal, wire + i, 1, counts);
        i++;
    }
    CHECK_EQ(event, PD_LINK_PAYLOAD);
    CHECK(n - i >= 3u);
    CHECK_EQ(pd_link_payload_len(&link), sizeof(payload));
    CHECK(memcmp(pd_link_payload(&link), payload, sizeof(payload)) == 0);
    CHECK_EQ(feed_link(&link, &hal, wire + i, n - i, counts), PD_LINK_COMMAND);
    CHECK_EQ(counts[PD_LINK_PAYLOAD], 1);
    CHECK_EQ(counts[PD_LINK_COMMAND], 1);
    CHECK(memcmp(pd_link_payload(&link), payload, sizeof(payload)) == 0); /* still there */
    CHECK_EQ(fake_count(&hal), 0); /* the link answers a command with nothing of its own */
}

static void test_link_alone_drops_and_overflows_with_events(void)
{
    pd_link_t link;
    fake_hal_t hal;
    link_active(&link, &hal);
    const uint8_t payload[] = {0x08, 0x07};
    uint8_t wire[32];
    unsigned counts[PD_LINK_OVERFLOW + 1] = {0};
    size_t n = wire_of(PD_PACKET_COMMAND, 1, payload, sizeof(payload), wire, sizeof(wire));
    wire[n - 2] ^= 0x01; /* the CRC's last byte */
    CHECK_EQ(feed_link(&link, &hal, wire, n, counts), PD_LINK_DROPPED);
    CHECK_EQ(counts[PD_LINK_PAYLOAD], 1); /* decoded early, and never run: no COMMAND */
    CHECK_EQ(counts[PD_LINK_COMMAND], 0);
    CHECK_EQ(link.stats.drop_crc, 1);

    /* DATA from the host: valid, nothing to run. */
    n = wire_of(PD_PACKET_DATA, 2, payload, sizeof(payload), wire, sizeof(wire));
    CHECK_EQ(feed_link(&link, &hal, wire, n, counts), PD_LINK_HANDLED);

    /* No delimiter in PD_MAX_ENCODED_FRAME bytes: one OVERFLOW, its event sent, the rest skipped. */
    memset(counts, 0, sizeof(counts));
    const uint8_t one = 0x01;
    for (unsigned k = 0; k < PD_MAX_ENCODED_FRAME + 10u; k++) {
        feed_link(&link, &hal, &one, 1, counts);
    }
    CHECK_EQ(counts[PD_LINK_OVERFLOW], 1);
    CHECK_EQ(counts[PD_LINK_NONE], PD_MAX_ENCODED_FRAME + 9u);
    CHECK_EQ(hal_events(&hal, PD_EVENT_RX_OVERFLOW), 1);
    const uint8_t zero = 0x00;
    CHECK_EQ(feed_link(&link, &hal, &zero, 1, counts), PD_LINK_NONE); /* the skip's end */
}

static void test_link_alone_holds_a_frame_until_its_replies_fit(void)
{
    pd_link_t link;
    fake_hal_t hal;
    link_active(&link, &hal);
    const uint8_t payload[] = {0x08, 0x07};
    uint8_t wire[32];
    unsigned counts[PD_LINK_OVERFLOW + 1] = {0};
    size_t n = wire_of(PD_PACKET_COMMAND, 1, payload, sizeof(payload), wire, sizeof(wire));
    hal.tx_room = PD_TX_RESERVE - 1u;
    CHECK_EQ(feed_link(&link, &hal, wire, n, counts), PD_LINK_HELD);
    CHECK(link.rx_held);
    /* A report may not take the room the held frame waits for. */
    uint8_t buf[PD_TX_BUF];
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    out.which_data = protoduino_ArduinoOut_failsafe_tag;
    out.data.failsafe.epoch = 1;
    size_t len = pd_encode_out(&out, buf + PD_TX_PAYLOAD_AT, PD_TX_MAX_PAYLOAD);
    CHECK(len > 0);
    hal.tx_room = 1000u;
    CHECK(!pd_link_send_spare(&link, &hal, buf, len, false));
    CHECK_EQ(feed_link(&link, &hal, wire + n - 1u, 1, counts), PD_LINK_COMMAND);
    CHECK(pd_link_send_spare(&link, &hal, buf, len, false));
    CHECK_EQ(fake_count(&hal), 1);
}

/* --- The line rate (docs/protocol.md 5, *Line rate*) -------------------------- */

static void send_baud_set(tdev_t *d, uint32_t rate)
{
    const uint8_t payload[PD_BAUD_SIZE] = {PD_CONTROL_BAUD_SET, (uint8_t)(rate >> 24),
                                           (uint8_t)(rate >> 16), (uint8_t)(rate >> 8),
                                           (uint8_t)rate};
    t_send_packet(d, PD_PACKET_CONTROL, d->host_seq++, payload, sizeof(payload));
}

/* The rate of the last BAUD_ACK sent since the last clear, or -1 if none. */
static long long last_baud_ack(const tdev_t *d)
{
    long long rate = -1;
    for (size_t i = 0; i < d->hal.n_frames; i++) {
        const fake_frame_t *f = fake_frame(&d->hal, i);
        if (f->type == PD_PACKET_CONTROL && f->len == PD_BAUD_SIZE &&
            f->payload[0] == PD_CONTROL_BAUD_ACK) {
            rate = ((long long)f->payload[1] << 24) | ((long long)f->payload[2] << 16) |
                   ((long long)f->payload[3] << 8) | f->payload[4];
        }
    }
    return rate;
}

static void test_reset_ack_offers_the_hal_rates(void)
{
    tdev_t d;
    t_boot(&d);
    d.hal.baud_rates = PD_RESET_ACK_BAUD_500K | PD_RESET_ACK_BAUD_1M;
    fake_clear(&d.hal);
    t_send_reset(&d, PD_PROTOCOL_VERSION);
    const fake_frame_t *f = fake_frame(&d.hal, 0);
    CHECK_EQ(f->payload[0], PD_CONTROL_RESET_ACK);
    CHECK_EQ(f->len, PD_RESET_ACK_SIZE);
    CHECK_EQ(f->payload[10], PD_RESET_ACK_BAUD_500K | PD_RESET_ACK_BAUD_1M);
}

static void test_baud_set_acks_then_switches(void)
{
    tdev_t d;
    t_active(&d);
    d.hal.baud_rates = PD_RESET_ACK_BAUD_250K | PD_RESET_ACK_BAUD_500K | PD_RESET_ACK_BAUD_1M;
    send_baud_set(&d, 1000000UL);
    CHECK_EQ(last_baud_ack(&d), 1000000LL);
    CHECK_EQ(d.hal.baud_sets, 1u);
    CHECK_EQ(d.hal.baud, 1000000UL);
    /* The probe at the new rate: acked, no second switch, not yet confirmed. */
    fake_clear(&d.hal);
    send_baud_set(&d, 1000000UL);
    CHECK_EQ(last_baud_ack(&d), 1000000LL);
    CHECK_EQ(d.hal.baud_sets, 1u);
    CHECK(d.core.baud_unconfirmed);
}

static void test_baud_unconfirmed_falls_back(void)
{
    tdev_t d;
    t_active(&d);
    d.hal.baud_rates = PD_RESET_ACK_BAUD_1M;
    send_baud_set(&d, 1000000UL);
    d.hal.now_ms += PD_BAUD_CONFIRM_MS - 1u;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.baud, 1000000UL); /* still inside the bound */
    d.hal.now_ms += 1u;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.baud, (uint32_t)PD_BAUD); /* back at the opening rate */
    CHECK_EQ(d.hal.baud_sets, 2u);
    CHECK(!d.core.baud_unconfirmed);
}

static void test_baud_confirmed_by_a_reset_stays(void)
{
    tdev_t d;
    t_active(&d);
    d.hal.baud_rates = PD_RESET_ACK_BAUD_1M;
    send_baud_set(&d, 1000000UL);
    t_send_reset(&d, PD_PROTOCOL_VERSION); /* the host's RESET at the new rate */
    d.hal.now_ms += 10u * PD_BAUD_CONFIRM_MS;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.baud, 1000000UL);
    CHECK_EQ(d.hal.baud_sets, 1u);
}

static void test_baud_set_of_a_rate_not_offered_is_refused(void)
{
    tdev_t d;
    t_active(&d);
    d.hal.baud_rates = PD_RESET_ACK_BAUD_250K;
    send_baud_set(&d, 1000000UL); /* not offered by this board */
    CHECK_EQ(last_baud_ack(&d), 0LL);
    fake_clear(&d.hal);
    send_baud_set(&d, 57600UL); /* not a rate of the protocol's */
    CHECK_EQ(last_baud_ack(&d), 0LL);
    CHECK_EQ(d.hal.baud_sets, 0u);
}

static void test_baud_set_while_idle_is_ignored(void)
{
    tdev_t d;
    t_boot(&d);
    d.hal.baud_rates = PD_RESET_ACK_BAUD_1M;
    fake_clear(&d.hal);
    send_baud_set(&d, 1000000UL);
    CHECK_EQ(last_baud_ack(&d), -1LL);
    CHECK_EQ(d.hal.baud_sets, 0u);
}

const pd_test_case_t pd_tests_link[] = {
    TEST_CASE(test_reset_ack_offers_the_hal_rates),
    TEST_CASE(test_baud_set_acks_then_switches),
    TEST_CASE(test_baud_unconfirmed_falls_back),
    TEST_CASE(test_baud_confirmed_by_a_reset_stays),
    TEST_CASE(test_baud_set_of_a_rate_not_offered_is_refused),
    TEST_CASE(test_baud_set_while_idle_is_ignored),
    TEST_CASE(test_boot_event),
    TEST_CASE(test_reset_ack),
    TEST_CASE(test_reset_other_version_still_answered),
    TEST_CASE(test_reset_of_another_version_leaves_the_session),
    TEST_CASE(test_new_session_releases_same_session_resumes),
    TEST_CASE(test_boot_id_differs_per_boot),
    TEST_CASE(test_reset_without_version_ignored),
    TEST_CASE(test_command_before_reset_not_active),
    TEST_CASE(test_reset_again_resets_seq_keeps_outputs),
    TEST_CASE(test_seq_in_order_and_lost),
    TEST_CASE(test_seq_desync_event_and_still_processed),
    TEST_CASE(test_seq_wraps),
    TEST_CASE(test_overflow_event_and_recovery),
    TEST_CASE(test_longest_frame_is_no_overflow_but_too_long_for_a_command),
    TEST_CASE(test_noise_and_empty_frames_ignored),
    TEST_CASE(test_data_and_stray_control_dropped),
    TEST_CASE(test_data_only_while_active),
    TEST_CASE(test_failed_write_keeps_seq_and_flushes),
    TEST_CASE(test_reboot_returns_to_idle),
    TEST_CASE(test_fed_in_any_chunking),
    TEST_CASE(test_link_alone_reports_a_command_payload_then_the_checked_command),
    TEST_CASE(test_link_alone_drops_and_overflows_with_events),
    TEST_CASE(test_link_alone_holds_a_frame_until_its_replies_fit),
    {NULL, NULL},
};

/*
 * The I/O engine: the transmit queue's back-pressure on receiving, report
 * slots (newest value wins, never ahead of a command's Ack). The fake HAL's tx_room stands for the platform's transmit queue.
 */
#include <pb_encode.h>
#include <stdio.h>
#include <string.h>

#include "pd_cobs.h"
#include "pd_packet.h"
#include "pd_test.h"
#include "test_util.h"

/* Encode one ArduinoIn as a whole wire frame (delimiter included); returns its length. */
static size_t frame_of(tdev_t *d, const protoduino_ArduinoIn *in, uint8_t *wire, size_t cap)
{
    uint8_t payload[PD_MAX_PAYLOAD];
    uint8_t raw[PD_MIN_PACKET + PD_MAX_PAYLOAD];
    size_t raw_len = 0;
    pb_ostream_t s = pb_ostream_from_buffer(payload, sizeof(payload));
    if (!pb_encode(&s, protoduino_ArduinoIn_fields, in) ||
        pd_packet_build(PD_PACKET_COMMAND, d->host_seq++, payload, s.bytes_written, raw,
                        sizeof(raw), &raw_len) != PD_PACKET_OK) {
        return 0;
    }
    size_t n = pd_cobs_encode(raw, raw_len, wire, cap - 1u);
    wire[n++] = 0;
    return n;
}

static void test_frame_waits_for_transmit_room(void)
{
    tdev_t d;
    t_active(&d);
    uint8_t wire[64];
    protoduino_ArduinoIn in = m_digital_init(7, 13, true);
    size_t n = frame_of(&d, &in, wire, sizeof(wire));
    CHECK(n > 2);

    d.hal.tx_room = PD_TX_RESERVE - 1u;
    /* Every byte but the delimiter is taken; the delimiter waits. */
    CHECK_EQ(pd_core_rx(&d.core, wire, n), n - 1u);
    CHECK_EQ(fake_count(&d.hal), 0);
    CHECK_EQ(d.hal.digital[13], -1); /* not executed either */
    CHECK(!pd_core_rx_byte(&d.core, 0));
    pd_core_poll(&d.core);
    CHECK_EQ(fake_count(&d.hal), 0);

    d.hal.tx_room = PD_TX_RESERVE;
    CHECK(pd_core_rx_byte(&d.core, 0));
    CHECK_EQ(t_status(&d, 7), protoduino_Status_STATUS_OK);
    CHECK_EQ(d.hal.digital[13], 1);
}

static void test_reserve_holds_the_largest_replies(void)
{
    /* A Ping with the longest payload that clears the failsafe sends the
     * largest Ack and then a Failsafe notice: both fit the reserve. */
    tdev_t d;
    t_active(&d);
    uint8_t payload[64];
    memset(payload, 0xA5, sizeof(payload));
    protoduino_ArduinoIn in = m_stop(1);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    fake_clear(&d.hal);
    d.hal.tx_room = PD_TX_RESERVE;
    in = m_ping(2, payload, sizeof(payload));
    in.data.ping.failsafe_epoch = 1; /* the Stop's: this host saw it */
    t_send_in(&d, &in);
    CHECK_EQ(t_status(&d, 2), protoduino_Status_STATUS_OK);
    protoduino_Failsafe fs;
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(!fs.active);
}

/* A report source for the tests: slot N reports value[N], as a DecodeError's count
 * (slot in the high half): any ArduinoOut serves, the engine does not look inside. */
static unsigned report_value[PD_REPORT_SLOTS];
static unsigned report_calls;

static bool test_report(pd_core_t *core, uint8_t slot, protoduino_ArduinoOut *out)
{
    (void)core;
    report_calls++;
    out->which_data = protoduino_ArduinoOut_decode_error_tag;
    out->data.decode_error.count = (uint32_t)slot << 16 | (uint32_t)report_value[slot];
    return true;
}

static int reports_sent(const tdev_t *d, char *last, size_t cap)
{
    int n = 0;
    protoduino_ArduinoOut out;
    for (size_t i = 0; i < fake_count(&d->hal); i++) {
        if (t_out(d, i, &out) && out.which_data == protoduino_ArduinoOut_decode_error_tag) {
            n++;
            snprintf(last, cap, "%u:%u", (unsigned)(out.data.decode_error.count >> 16),
                     (unsigned)(out.data.decode_error.count & 0xFFFFu));
        }
    }
    return n;
}

static void test_report_newest_value_replaces_unsent(void)
{
    tdev_t d;
    char last[64] = "";
    t_active(&d);
    d.core.report = test_report;
    d.core.report_sent = NULL;
    report_calls = 0;

    /* No room for it: the report waits, the bit stays. */
    d.hal.tx_room = 8u;
    report_value[3] = 1;
    pd_state_report(&d.core, 3);
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 0);
    report_value[3] = 2;
    pd_state_report(&d.core, 3);
    report_value[3] = 3;
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 0);

    /* Room: one report, with the newest value; the older ones never leave. */
    d.hal.tx_room = UINT16_MAX;
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 1);
    CHECK(strcmp(last, "3:3") == 0);
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 1); /* sent once */
}

static void test_reply_goes_before_pending_report(void)
{
    tdev_t d;
    char last[64] = "";
    t_active(&d);
    d.core.report = test_report;
    d.core.report_sent = NULL;
    report_value[0] = 42;
    pd_state_report(&d.core, 0);
    /* A command arriving in the same pass is answered first; the report follows. */
    protoduino_ArduinoIn in = m_digital_init(9, 13, false);
    t_send_in(&d, &in);
    pd_core_poll(&d.core);
    CHECK_EQ(fake_count(&d.hal), 2);
    protoduino_ArduinoOut out;
    CHECK(t_out(&d, 0, &out));
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_ack_tag);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 1);
    CHECK(strcmp(last, "0:42") == 0);
}

static void test_report_waits_for_a_command_under_way(void)
{
    tdev_t d;
    char last[64] = "";
    t_active(&d);
    d.core.report = test_report;
    d.core.report_sent = NULL;
    report_value[2] = 7;
    pd_state_report(&d.core, 2);
    /* Half a command frame is in: the report waits for its Ack. */
    const uint8_t half[3] = {0x05, 0x01, 0x02};
    t_feed(&d, half, sizeof(half));
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 0);
    const uint8_t end = 0x00; /* the frame ends (an invalid one: dropped) */
    t_feed(&d, &end, 1);
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 1);
    CHECK(strcmp(last, "2:7") == 0);
}

static void test_report_gives_way_to_commands_for_a_while_only(void)
{
    tdev_t d;
    char last[64] = "";
    t_active(&d);
    d.core.report = test_report;
    d.core.report_sent = NULL;
    report_value[1] = 9;
    pd_state_report(&d.core, 1);
    const uint8_t partial[2] = {0x05, 0x01}; /* a command frame, forever arriving */
    t_feed(&d, partial, sizeof(partial));
    uint32_t t0 = d.hal.now_ms;
    for (uint32_t ms = 0; ms < PD_REPORT_MAX_WAIT_MS; ms++) {
        d.hal.now_ms = t0 + ms;
        pd_core_poll(&d.core);
    }
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 0);
    d.hal.now_ms = t0 + PD_REPORT_MAX_WAIT_MS;
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 1);
    CHECK(strcmp(last, "1:9") == 0);
}

static void test_a_held_command_goes_before_any_report(void)
{
    tdev_t d;
    char last[64] = "";
    t_active(&d);
    d.core.report = test_report;
    d.core.report_sent = NULL;
    /* The queue cannot take a command's replies: its frame is held at the delimiter. */
    d.hal.tx_room = PD_TX_RESERVE - 1u;
    protoduino_ArduinoIn in = m_digital_init(9, 13, false);
    t_send_in(&d, &in);
    CHECK_EQ(t_acks(&d, 9, NULL), 0);
    report_value[2] = 5;
    pd_state_report(&d.core, 2);
    /* The queue empties while the report has waited longer than it ever gives way. */
    d.hal.tx_room = UINT16_MAX;
    d.hal.now_ms += PD_REPORT_MAX_WAIT_MS + 10u;
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 0); /* the held frame first */
    const uint8_t delimiter = 0;
    t_feed(&d, &delimiter, 1); /* the loop offers it again */
    CHECK_EQ(t_acks(&d, 9, NULL), 1);
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 1);
}

static void test_one_report_per_pass_lowest_slot_first(void)
{
    tdev_t d;
    char last[64] = "";
    t_active(&d);
    d.core.report = test_report;
    d.core.report_sent = NULL;
    report_value[1] = 10;
    report_value[5] = 50;
    pd_state_report(&d.core, 5);
    pd_state_report(&d.core, 1);
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 1);
    CHECK(strcmp(last, "1:10") == 0);
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 2);
    CHECK(strcmp(last, "5:50") == 0);
}

static void test_no_report_while_idle(void)
{
    tdev_t d;
    char last[64] = "";
    t_boot(&d);
    fake_clear(&d.hal);
    d.core.report = test_report;
    d.core.report_sent = NULL;
    pd_state_report(&d.core, 0);
    pd_core_poll(&d.core);
    CHECK_EQ(reports_sent(&d, last, sizeof(last)), 0);
    CHECK_EQ(fake_count(&d.hal), 0);
}

/*
 * The receiver decodes COBS and advances the CRC byte by byte; the result must
 * be what decoding the whole frame at its delimiter gives (pd_cobs_decode, then
 * pd_packet_parse): the same verdict for every frame, valid, mutated or noise.
 */
static uint32_t lcg(uint32_t *state)
{
    *state = *state * 1664525u + 1013904223u;
    return *state >> 8;
}

static void test_streaming_receiver_agrees_with_whole_frame_decoding(void)
{
    tdev_t d;
    t_boot(&d);
    uint32_t seed = 12345;
    pd_link_stats_t want = d.core.link.stats;
    for (int round = 0; round < 3000; round++) {
        uint8_t frame[PD_MAX_ENCODED_FRAME];
        size_t len;
        if (round % 3 == 0) {
            /* A valid packet of random type and payload, perhaps mutated. */
            uint8_t raw[PD_MIN_PACKET + PD_MAX_PAYLOAD];
            uint8_t payload[PD_MAX_PAYLOAD];
            size_t plen = lcg(&seed) % 40u, raw_len = 0;
            for (size_t i = 0; i < plen; i++) {
                payload[i] = (uint8_t)lcg(&seed);
            }
            uint8_t type = (uint8_t)(lcg(&seed) % 4u);
            pd_packet_build(type, (uint8_t)lcg(&seed), payload, plen, raw, sizeof(raw), &raw_len);
            len = pd_cobs_encode(raw, raw_len, frame, sizeof(frame));
            if (lcg(&seed) % 2u) {
                frame[lcg(&seed) % len] = (uint8_t)(lcg(&seed) | 1u); /* no 0x00 inside */
            }
        } else {
            len = 1u + lcg(&seed) % (round % 3 == 1 ? 20u : PD_MAX_ENCODED_FRAME);
            for (size_t i = 0; i < len; i++) {
                frame[i] = (uint8_t)(1u + lcg(&seed) % 255u);
            }
        }
        /* What decoding the whole frame says. */
        uint8_t dec[PD_MAX_ENCODED_FRAME];
        pd_packet_t pkt;
        int n = pd_cobs_decode(frame, len, dec, sizeof(dec));
        if (n < 0) {
            want.drop_cobs++;
        } else {
            switch (pd_packet_parse(dec, (size_t)n, &pkt)) {
            case PD_PACKET_OK:
                want.packets++;
                break;
            case PD_PACKET_ERR_CRC:
                want.drop_crc++;
                break;
            case PD_PACKET_ERR_TYPE:
                want.drop_type++;
                break;
            default:
                want.drop_length++;
                break;
            }
        }
        t_feed(&d, frame, len);
        t_feed(&d, (const uint8_t *)"", 1);
        const pd_link_stats_t *got = &d.core.link.stats;
        CHECK_EQ(got->drop_cobs, want.drop_cobs);
        CHECK_EQ(got->drop_crc, want.drop_crc);
        CHECK_EQ(got->drop_type, want.drop_type);
        CHECK_EQ(got->drop_length, want.drop_length);
        CHECK_EQ(got->packets, want.packets);
    }
    CHECK(want.packets > 100 && want.drop_cobs > 100 && want.drop_crc > 100);
}

/*
 * A COMMAND's payload is decoded as soon as its last byte is in, while the CRC
 * and the delimiter are still to come; it runs only once the packet passed its
 * check. A frame whose CRC is wrong was decoded all the same, and must change
 * nothing and answer nothing.
 */
static void test_command_decoded_early_runs_only_after_the_check(void)
{
    tdev_t d;
    t_active(&d);
    uint8_t wire[64];
    protoduino_ArduinoIn in = m_digital_init(9, 13, true);
    size_t n = frame_of(&d, &in, wire, sizeof(wire));
    CHECK(n > 4);

    /* The frame with one bit of its last byte before the delimiter flipped (a
     * CRC byte or a COBS code: either way the packet fails its check). */
    uint8_t bad[64];
    memcpy(bad, wire, n);
    bad[n - 2u] = (uint8_t)(bad[n - 2u] ^ 0x01u);
    if (bad[n - 2u] == 0) {
        bad[n - 2u] = 0x02u;
    }
    /* Up to its payload's last byte: decoded, not run. */
    size_t fed = 0;
    while (fed < n - 1u && !d.core.in_decoded) {
        CHECK(pd_core_rx_byte(&d.core, bad[fed++]));
    }
    CHECK(d.core.in_decoded);
    CHECK(fed < n - 2u); /* the CRC was still to come */
    CHECK_EQ(d.core.in.message_id, 9u);
    /* The rest and the delimiter: dropped, nothing run, nothing answered. */
    t_feed(&d, bad + fed, n - fed);
    CHECK_EQ(fake_count(&d.hal), 0);
    CHECK_EQ(d.hal.digital[13], -1);
    CHECK_EQ(d.core.link.stats.drop_crc + d.core.link.stats.drop_cobs +
                 d.core.link.stats.drop_length,
             1u);

    /* The intact frame: run once, answered once. */
    t_feed(&d, wire, n);
    CHECK_EQ(t_status(&d, 9), protoduino_Status_STATUS_OK);
    CHECK_EQ(d.hal.digital[13], 1);
}

const pd_test_case_t pd_tests_engine[] = {
    TEST_CASE(test_streaming_receiver_agrees_with_whole_frame_decoding),
    TEST_CASE(test_frame_waits_for_transmit_room),
    TEST_CASE(test_command_decoded_early_runs_only_after_the_check),
    TEST_CASE(test_reserve_holds_the_largest_replies),
    TEST_CASE(test_report_newest_value_replaces_unsent),
    TEST_CASE(test_reply_goes_before_pending_report),
    TEST_CASE(test_report_waits_for_a_command_under_way),
    TEST_CASE(test_report_gives_way_to_commands_for_a_while_only),
    TEST_CASE(test_a_held_command_goes_before_any_report),
    TEST_CASE(test_one_report_per_pass_lowest_slot_first),
    TEST_CASE(test_no_report_while_idle),
    {NULL, NULL},
};

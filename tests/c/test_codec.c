/* COBS, CRC16 and packets against the shared wire vectors (wire_v1.json). */
#include <string.h>

#include "pd_cobs.h"
#include "pd_crc.h"
#include "pd_packet.h"
#include "pd_test.h"
#include "pd_vectors.h"
#include "test_util.h"

static void test_cobs_vectors_encode(void)
{
    uint8_t out[600];
    CHECK(PD_VEC_COBS_COUNT > 5);
    for (size_t i = 0; i < PD_VEC_COBS_COUNT; i++) {
        const pd_vec_cobs_t *v = &PD_VEC_COBS[i];
        size_t n = pd_cobs_encode(v->decoded, v->decoded_len, out, sizeof(out));
        CHECK_EQ(n, v->encoded_len);
        CHECK(memcmp(out, v->encoded, n) == 0);
        CHECK(n <= PD_COBS_MAX_ENCODED(v->decoded_len));
        CHECK(memchr(out, 0, n) == NULL);
    }
}

static void test_cobs_vectors_decode(void)
{
    uint8_t out[600];
    for (size_t i = 0; i < PD_VEC_COBS_COUNT; i++) {
        const pd_vec_cobs_t *v = &PD_VEC_COBS[i];
        int n = pd_cobs_decode(v->encoded, v->encoded_len, out, sizeof(out));
        CHECK_EQ(n, v->decoded_len);
        CHECK(memcmp(out, v->decoded, (size_t)n) == 0);
    }
}

static void test_cobs_decode_in_place(void)
{
    uint8_t buf[600];
    for (size_t i = 0; i < PD_VEC_COBS_COUNT; i++) {
        const pd_vec_cobs_t *v = &PD_VEC_COBS[i];
        memcpy(buf, v->encoded, v->encoded_len);
        int n = pd_cobs_decode(buf, v->encoded_len, buf, sizeof(buf));
        CHECK_EQ(n, v->decoded_len);
        CHECK(memcmp(buf, v->decoded, (size_t)n) == 0);
    }
}

static void test_cobs_rejects_invalid(void)
{
    uint8_t out[16];
    const uint8_t past_end[] = {0x05, 0x11, 0x22, 0x33};
    const uint8_t zero_inside[] = {0x03, 0x11, 0x00, 0x22};
    const uint8_t zero_code[] = {0x00};
    CHECK_EQ(pd_cobs_decode(past_end, sizeof(past_end), out, sizeof(out)), -1);
    CHECK_EQ(pd_cobs_decode(zero_inside, sizeof(zero_inside), out, sizeof(out)), -1);
    CHECK_EQ(pd_cobs_decode(zero_code, sizeof(zero_code), out, sizeof(out)), -1);
}

static void test_cobs_respects_capacity(void)
{
    uint8_t out[8];
    const uint8_t data[] = {1, 2, 3, 4, 5, 6, 7, 8};
    const uint8_t enc[] = {0x09, 1, 2, 3, 4, 5, 6, 7, 8};
    /* 8 bytes encode to 9: every capacity below that is refused, 9 works. */
    for (size_t cap = 0; cap < 9; cap++) {
        uint8_t big[16];
        memset(big, 0xEE, sizeof(big));
        CHECK_EQ(pd_cobs_encode(data, sizeof(data), big, cap), 0);
        CHECK_EQ(big[cap], 0xEE); /* nothing written past the capacity */
    }
    CHECK_EQ(pd_cobs_decode(enc, sizeof(enc), out, 7), -1);
    CHECK_EQ(pd_cobs_decode(enc, sizeof(enc), out, 8), 8);
}

static void test_cobs_round_trip_all_lengths(void)
{
    uint8_t data[300], enc[310], dec[300];
    for (size_t len = 0; len <= sizeof(data); len++) {
        for (size_t i = 0; i < len; i++) {
            data[i] = (uint8_t)((i * 37u + len) % 7u == 0 ? 0 : i + 1u);
        }
        size_t n = pd_cobs_encode(data, len, enc, sizeof(enc));
        CHECK(n > 0 && n <= PD_COBS_MAX_ENCODED(len));
        CHECK(memchr(enc, 0, n) == NULL);
        int m = pd_cobs_decode(enc, n, dec, sizeof(dec));
        CHECK_EQ(m, len);
        CHECK(memcmp(dec, data, len) == 0);
    }
}

static void test_crc_vectors(void)
{
    CHECK(PD_VEC_CRC_COUNT > 0);
    for (size_t i = 0; i < PD_VEC_CRC_COUNT; i++) {
        CHECK_EQ(pd_crc16(PD_VEC_CRC[i].data, PD_VEC_CRC[i].len), PD_VEC_CRC[i].crc);
    }
    CHECK_EQ(pd_crc16((const uint8_t *)"123456789", 9), 0x29B1);
}

static void test_packet_vectors_build(void)
{
    uint8_t raw[PD_MIN_PACKET + PD_MAX_PAYLOAD];
    uint8_t wire[PD_MAX_ENCODED_FRAME + 1];
    CHECK(PD_VEC_PACKETS_COUNT > 0);
    for (size_t i = 0; i < PD_VEC_PACKETS_COUNT; i++) {
        const pd_vec_packet_t *v = &PD_VEC_PACKETS[i];
        size_t n = 0;
        CHECK_EQ(pd_packet_build(v->type, v->seq, v->payload, v->payload_len, raw, sizeof(raw), &n),
                 PD_PACKET_OK);
        CHECK_EQ(n, v->raw_len);
        CHECK(memcmp(raw, v->raw, n) == 0);
        size_t w = pd_cobs_encode(raw, n, wire, sizeof(wire) - 1u);
        wire[w++] = 0;
        CHECK_EQ(w, v->wire_len);
        CHECK(memcmp(wire, v->wire, w) == 0);
    }
}

static void test_packet_vectors_parse(void)
{
    uint8_t raw[PD_MAX_ENCODED_FRAME];
    for (size_t i = 0; i < PD_VEC_PACKETS_COUNT; i++) {
        const pd_vec_packet_t *v = &PD_VEC_PACKETS[i];
        pd_packet_t pkt;
        CHECK_EQ(v->wire[v->wire_len - 1], 0);
        int n = pd_cobs_decode(v->wire, v->wire_len - 1u, raw, sizeof(raw));
        CHECK_EQ(n, v->raw_len);
        CHECK_EQ(pd_packet_parse(raw, (size_t)n, &pkt), PD_PACKET_OK);
        CHECK_EQ(pkt.type, v->type);
        CHECK_EQ(pkt.seq, v->seq);
        CHECK_EQ(pkt.len, v->payload_len);
        CHECK(memcmp(pkt.payload, v->payload, pkt.len) == 0);
    }
}

static void test_packet_build_refuses_small_buffer(void)
{
    uint8_t raw[8];
    size_t n = 0;
    const uint8_t payload[4] = {1, 2, 3, 4};
    CHECK_EQ(pd_packet_build(2, 0, payload, 4, raw, 8, &n), PD_PACKET_ERR_SPACE);
    CHECK_EQ(pd_packet_build(2, 0, payload, 3, raw, 8, &n), PD_PACKET_OK);
    CHECK_EQ(n, 8);
}

static void test_packet_parse_reasons(void)
{
    uint8_t raw[16];
    size_t n = 0;
    pd_packet_t pkt;
    const uint8_t payload[2] = {0x00, 0x01};
    CHECK_EQ(pd_packet_build(PD_PACKET_CONTROL, 0, payload, 2, raw, sizeof(raw), &n), PD_PACKET_OK);
    CHECK_EQ(pd_packet_parse(raw, 4, &pkt), PD_PACKET_ERR_LENGTH);
    CHECK_EQ(pd_packet_parse(raw, n - 1u, &pkt), PD_PACKET_ERR_LENGTH);
    raw[4] ^= 0x01;
    CHECK_EQ(pd_packet_parse(raw, n, &pkt), PD_PACKET_ERR_CRC);
    raw[4] ^= 0x01;
    CHECK_EQ(pd_packet_build(0x07, 0, payload, 2, raw, sizeof(raw), &n), PD_PACKET_OK);
    CHECK_EQ(pd_packet_parse(raw, n, &pkt), PD_PACKET_ERR_TYPE);
}

/* Each invalid frame, fed to an ACTIVE device, is dropped: no answer, one drop counted. */
static void test_invalid_frames_dropped(void)
{
    CHECK(PD_VEC_INVALID_COUNT > 0);
    for (size_t i = 0; i < PD_VEC_INVALID_COUNT; i++) {
        tdev_t d;
        t_active(&d);
        const pd_link_stats_t before = d.core.link.stats;
        t_feed(&d, PD_VEC_INVALID[i].wire, PD_VEC_INVALID[i].wire_len);
        const pd_link_stats_t *after = &d.core.link.stats;
        unsigned drops = (unsigned)(after->drop_cobs - before.drop_cobs) +
                         (unsigned)(after->drop_length - before.drop_length) +
                         (unsigned)(after->drop_crc - before.drop_crc) +
                         (unsigned)(after->drop_type - before.drop_type);
        if (drops != 1 || fake_count(&d.hal) != 0 || after->packets != before.packets) {
            fprintf(stderr, "  invalid frame \"%s\"\n", PD_VEC_INVALID[i].name);
        }
        CHECK_EQ(drops, 1);
        CHECK_EQ(after->packets, before.packets);
        CHECK_EQ(fake_count(&d.hal), 0);
    }
}

/* A valid frame right after each invalid one is still received. */
static void test_invalid_frame_does_not_damage_next(void)
{
    for (size_t i = 0; i < PD_VEC_INVALID_COUNT; i++) {
        tdev_t d;
        t_active(&d);
        t_feed(&d, PD_VEC_INVALID[i].wire, PD_VEC_INVALID[i].wire_len);
        protoduino_ArduinoIn in = m_info(77);
        t_send_in(&d, &in);
        CHECK_EQ(t_status(&d, 77), protoduino_Status_STATUS_OK);
    }
}

const pd_test_case_t pd_tests_codec[] = {
    TEST_CASE(test_cobs_vectors_encode),
    TEST_CASE(test_cobs_vectors_decode),
    TEST_CASE(test_cobs_decode_in_place),
    TEST_CASE(test_cobs_rejects_invalid),
    TEST_CASE(test_cobs_respects_capacity),
    TEST_CASE(test_cobs_round_trip_all_lengths),
    TEST_CASE(test_crc_vectors),
    TEST_CASE(test_packet_vectors_build),
    TEST_CASE(test_packet_vectors_parse),
    TEST_CASE(test_packet_build_refuses_small_buffer),
    TEST_CASE(test_packet_parse_reasons),
    TEST_CASE(test_invalid_frames_dropped),
    TEST_CASE(test_invalid_frame_does_not_damage_next),
    {NULL, NULL},
};

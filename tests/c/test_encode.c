/* pd_encode_out against nanopb's pb_encode: byte for byte, every shape and edge value. */
#include <string.h>

#include <pb_decode.h>
#include <pb_encode.h>

#include "fake_hal.h"
#include "pd_encode.h"
#include "pd_outputs.h"
#include "pd_protocol.h"
#include "pd_test.h"
#include "test_util.h"

/* 0 if both encoders agree (and every smaller buffer is refused), else the differing length. */
static int compare(const protoduino_ArduinoOut *msg)
{
    uint8_t ours[protoduino_ArduinoOut_size + 8];
    uint8_t theirs[protoduino_ArduinoOut_size + 8];
    pb_ostream_t s = pb_ostream_from_buffer(theirs, sizeof(theirs));
    protoduino_ArduinoOut nanopb_msg = *msg; /* the servos' writer as pb_encode's callback */
    if (msg->which_data == protoduino_ArduinoOut_ack_tag &&
        msg->data.ack.which_result == protoduino_Ack_outputs_tag) {
        fake_outputs_callbacks(&nanopb_msg.data.ack.result.outputs, &msg->data.ack.result.outputs);
    }
    if (!pb_encode(&s, protoduino_ArduinoOut_fields, &nanopb_msg)) {
        return -1;
    }
    size_t n = pd_encode_out(msg, ours, sizeof(ours));
    if (n != s.bytes_written || memcmp(ours, theirs, n) != 0) {
        fprintf(stderr, "  ours %zu bytes, pb_encode %zu bytes\n", n, s.bytes_written);
        return (int)n + 1000;
    }
    for (size_t cap = 0; cap < n; cap++) {
        if (pd_encode_out(msg, ours, cap) != 0) {
            return -2;
        }
    }
    return 0;
}

static protoduino_ArduinoOut ack(uint32_t id, protoduino_Status status)
{
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    out.which_data = protoduino_ArduinoOut_ack_tag;
    out.data.ack.message_id = id;
    out.data.ack.status = status;
    return out;
}

static void test_encode_ack_plain(void)
{
    const uint32_t ids[] = {0, 1, 127, 128, 16383, 16384, 0x7FFFFFFFu, 0xFFFFFFFFu};
    for (size_t i = 0; i < sizeof(ids) / sizeof(ids[0]); i++) {
        for (int st = _protoduino_Status_MIN; st <= _protoduino_Status_MAX; st++) {
            protoduino_ArduinoOut out = ack(ids[i], (protoduino_Status)st);
            CHECK_EQ(compare(&out), 0);
        }
    }
}

/* The short Ack (ArduinoOut.ack_ok, 7): pb_encode's bytes, the member written even at 0. */
static void test_encode_ack_ok(void)
{
    const uint32_t ids[] = {0, 1, 127, 128, 0xFFFFFFFFu};
    for (size_t i = 0; i < sizeof(ids) / sizeof(ids[0]); i++) {
        protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
        out.which_data = protoduino_ArduinoOut_ack_ok_tag;
        out.data.ack_ok = ids[i];
        CHECK_EQ(compare(&out), 0);
    }
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    out.which_data = protoduino_ArduinoOut_ack_ok_tag;
    out.data.ack_ok = 5;
    uint8_t buf[PD_ENCODE_MAX];
    CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 2);
    CHECK_EQ(buf[0], 0x38);
    CHECK_EQ(buf[1], 5);
}

static void test_encode_ack_ping_echo(void)
{
    for (size_t len = 0; len <= 64; len++) {
        protoduino_ArduinoOut out = ack(1000 + (uint32_t)len, protoduino_Status_STATUS_OK);
        out.data.ack.which_result = protoduino_Ack_ping_echo_tag;
        out.data.ack.result.ping_echo.size = (pb_size_t)len;
        for (size_t i = 0; i < len; i++) {
            out.data.ack.result.ping_echo.bytes[i] = (uint8_t)(i * 4u + len); /* incl. 0x00 */
        }
        CHECK_EQ(compare(&out), 0);
    }
    /* An oversized length is refused, not read past the array. */
    protoduino_ArduinoOut out = ack(1, protoduino_Status_STATUS_OK);
    uint8_t buf[200];
    out.data.ack.which_result = protoduino_Ack_ping_echo_tag;
    out.data.ack.result.ping_echo.size = 65;
    CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 0);
}

static void test_encode_ack_info(void)
{
    protoduino_ArduinoOut out = ack(42, protoduino_Status_STATUS_OK);
    protoduino_DeviceInfo *info = &out.data.ack.result.info;
    out.data.ack.which_result = protoduino_Ack_info_tag;
    CHECK_EQ(compare(&out), 0); /* all defaults: an empty nested message */
    /* Its pin table: the fake board's (the Uno's pins), then others below. */
    fake_hal_t hal;
    fake_init(&hal);
    pd_board_info_t *board = &hal.info;
    fake_info_callbacks(info, &hal);
    strcpy(info->firmware_version, PD_FIRMWARE_VERSION);
    strcpy(info->board, "uno");
    info->protocol_version = 1;
    info->schema_id = 0x614404ADu;
    info->num_pins = 20;
    info->max_servos = 8;
    info->reserved_pins_count = 2;
    info->reserved_pins[0] = 0;
    info->reserved_pins[1] = 1;
    CHECK_EQ(compare(&out), 0);
    /* Longest strings, every field at its largest. */
    strcpy(info->firmware_version, "123456789012345");
    strcpy(info->board, "abcdefghijk"); /* 11: the longest (protoduino.options) */
    /* (at their widths on the device: protoduino.options) */
    info->protocol_version = UINT8_MAX;
    info->schema_id = 0xFFFFFFFFu;
    info->num_pins = PD_MAX_PINS; /* the table's bound */
    info->max_servos = UINT8_MAX;
    info->reserved_pins_count = 4;
    for (int i = 0; i < 4; i++) {
        info->reserved_pins[i] = (uint8_t)(UINT8_MAX - i);
    }
    out.data.ack.message_id = 0xFFFFFFFFu;
    out.data.ack.status = protoduino_Status_STATUS_UNKNOWN_COMMAND;
    CHECK_EQ(compare(&out), 0);
    for (pb_size_t count = 0; count <= 4; count++) {
        info->reserved_pins_count = count;
        info->schema_id = count; /* including 0: omitted */
        CHECK_EQ(compare(&out), 0);
    }
    info->features = UINT16_MAX;
    CHECK_EQ(compare(&out), 0);
    /* Another board's table, at its largest (every pin and timer). */
    board->pwm_pins = T_SET(0xFFFFFu);
    board->reserved_pins = T_SET(0);
    board->servo_timer = PD_INFO_TIMERS_MAX - 1u;
    CHECK_EQ(compare(&out), 0);
    info->num_pins = 1;
    CHECK_EQ(compare(&out), 0);
    board->servo_timer_pins = T_SET(0); /* no timer held: no timers */
    board->clock_timer_pins = T_SET(0);
    CHECK_EQ(compare(&out), 0);
    info->num_pins = 0; /* no pins: no table */
    CHECK_EQ(compare(&out), 0);
    uint8_t big[200];
    info->num_pins = PD_MAX_PINS + 1u; /* past the bounds: refused */
    CHECK_EQ(pd_encode_out(&out, big, sizeof(big)), 0);
    info->num_pins = PD_MAX_PINS;
    board->servo_timer_pins = T_SET(1u << 9);
    board->servo_timer = PD_INFO_TIMERS_MAX;
    CHECK_EQ(pd_encode_out(&out, big, sizeof(big)), 0);
    board->servo_timer = 1;
    uint8_t buf[200];
    info->reserved_pins_count = 5;
    CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 0);
    info->reserved_pins_count = 1;
    memset(info->board, 'x', sizeof(info->board)); /* unterminated */
    CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 0);
}

static void test_encode_failsafe_decode_error(void)
{
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    out.which_data = protoduino_ArduinoOut_failsafe_tag;
    for (int active = 0; active < 2; active++) {
        for (int cause = _protoduino_FailsafeCause_MIN; cause <= _protoduino_FailsafeCause_MAX;
             cause++) {
            out.data.failsafe.active = active;
            out.data.failsafe.cause = (protoduino_FailsafeCause)cause;
            const uint8_t epochs[] = {0, 1, 127, 128, 255};
            for (size_t e = 0; e < sizeof(epochs); e++) {
                out.data.failsafe.epoch = epochs[e];
                CHECK_EQ(compare(&out), 0);
            }
            out.data.failsafe.pin = 19; /* an interlock's */
            CHECK_EQ(compare(&out), 0);
            out.data.failsafe.pin = 0;
            out.data.failsafe.epoch = 0;
        }
    }
    /* An Ack's failsafe state, the shapes the device sends: alone (a Heartbeat's
     * Ack) and beside the longest ping echo (field 5 goes after the oneof's
     * member 3, in field order as pb_encode writes them). */
    for (size_t len = 0; len <= 64; len += 64) {
        out = ack(7, protoduino_Status_STATUS_OK);
        out.data.ack.has_failsafe = true;
        out.data.ack.failsafe.active = true;
        out.data.ack.failsafe.cause = protoduino_FailsafeCause_FAILSAFE_CAUSE_INTERLOCK;
        out.data.ack.failsafe.epoch = 200;
        out.data.ack.failsafe.pin = 19;
        if (len) {
            out.data.ack.which_result = protoduino_Ack_ping_echo_tag;
            out.data.ack.result.ping_echo.size = (pb_size_t)len;
            memset(out.data.ack.result.ping_echo.bytes, 0xA5, len);
        }
        CHECK_EQ(compare(&out), 0);
    }
    /* A shape it never sends (a failsafe state beside DeviceInfo) is refused. */
    {
        uint8_t buf[PD_ENCODE_MAX];
        out = ack(7, protoduino_Status_STATUS_OK);
        out.data.ack.has_failsafe = true;
        out.data.ack.which_result = protoduino_Ack_info_tag;
        CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 0);
    }
    memset(&out, 0, sizeof(out));
    out.which_data = protoduino_ArduinoOut_decode_error_tag;
    const uint32_t counts[] = {0, 1, 300, 0xFFFFFFFFu};
    for (size_t i = 0; i < 4; i++) {
        out.data.decode_error.count = counts[i];
        CHECK_EQ(compare(&out), 0);
    }
}

static void test_encode_ack_outputs_and_refused_item(void)
{
    protoduino_ArduinoOut out = ack(7, protoduino_Status_STATUS_OK);
    out.data.ack.which_result = protoduino_Ack_outputs_tag;
    CHECK_EQ(compare(&out), 0); /* nothing configured: an empty nested message */
    protoduino_OutputStates *st = &out.data.ack.result.outputs;
    /* The servos' bytes come from the outputs' table (pd_outputs_servos): none, then every
     * channel of this build, the most, on the highest pins. */
    static pd_outputs_t outputs;
    pd_outputs_init(&outputs);
    pd_outputs_read(&outputs, st);
    CHECK_EQ(compare(&out), 0); /* no servo: the field omitted */
    for (uint8_t ch = 0; ch < PD_MAX_SERVOS; ch++) {
        outputs.owner[PD_MAX_PINS - 1u - ch] = PD_OWNER(PD_MODE_SERVO, ch);
        outputs.servo[ch].us = (uint16_t)(0xFFFFu - ch);
        outputs.servo[ch].target_us = (uint16_t)(0x80u + ch);
    }
    CHECK_EQ(compare(&out), 0);
    T_PUT_MASK(st->digital_pins, 0xFFFFFFFFu);
    T_PUT_MASK(st->digital_levels, 0x80000001u);
    CHECK_EQ(compare(&out), 0);
    /* Pin sets of every width up to the schema's 9 bytes (the Mega's pins 0..69), a zero
     * byte inside (pins 32..39 unset), as nanopb writes them. */
    for (pb_size_t n = 0; n <= sizeof(st->digital_pins.bytes); n++) {
        memset(st->digital_pins.bytes, 0xA5, sizeof(st->digital_pins.bytes));
        st->digital_pins.bytes[4] = 0;
        st->digital_pins.size = n;
        CHECK_EQ(compare(&out), 0);
    }
    T_PUT_MASK(st->digital_pins, 0xFFFFFFFFu);
    st->pwm_pins.size = sizeof(st->pwm_pins.bytes) + 1u; /* corrupt: refused */
    uint8_t wide[protoduino_ArduinoOut_size + 8];
    CHECK_EQ(pd_encode_out(&out, wide, sizeof(wide)), 0);
    T_PUT_MASK(st->pwm_pins, 0x00000E08u);
    for (pb_size_t n = 0; n <= sizeof(st->pwm_duties); n++) {
        st->pwm_duties_count = n;
        for (pb_size_t i = 0; i < n; i++) {
            st->pwm_duties[i] = (uint8_t)(i == 0 ? 0 : 255 - i * 40); /* 0, 127, 128, 255 ... */
        }
        CHECK_EQ(compare(&out), 0);
    }
    st->pwm_duties_count = sizeof(st->pwm_duties) + 1u; /* corrupt: refused */
    uint8_t too_many[protoduino_ArduinoOut_size + 8];
    CHECK_EQ(pd_encode_out(&out, too_many, sizeof(too_many)), 0);
    out = ack(0xFFFFFFFFu, protoduino_Status_STATUS_OUT_OF_RANGE);
    const uint32_t items[] = {1, 8, 127, 128, 0xFFFFFFFFu};
    for (size_t i = 0; i < sizeof(items) / sizeof(items[0]); i++) {
        out.data.ack.refused_item = items[i]; /* tag 31: two bytes */
        CHECK_EQ(compare(&out), 0);
    }
}

static void test_encode_input_report(void)
{
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    out.which_data = protoduino_ArduinoOut_input_report_tag;
    protoduino_InputReport *r = &out.data.input_report;
    CHECK_EQ(compare(&out), 0); /* all defaults */
    r->time_ms = 0xFFFFFFFFu;
    T_PUT_MASK(r->digital_pins, 0x000FFFFCu);
    T_PUT_MASK(r->digital_levels, 0x00000004u);
    CHECK_EQ(compare(&out), 0);
    T_PUT_MASK(r->analog_pins, 0x000FC000u);
    const uint16_t values[] = {0, 1, 127, 128, 1023, 0xFFFFu};
    for (pb_size_t n = 0; n <= 6; n++) {
        r->analog_values_count = n;
        memcpy(r->analog_values, values, sizeof(values));
        CHECK_EQ(compare(&out), 0);
    }
    T_PUT_MASK(r->counter_pins, 0x0000000Cu);
    const uint32_t counts[] = {0, 0xFFFFFFFFu, 16384u, 1u};
    for (pb_size_t n = 0; n <= 4; n++) {
        r->counter_counts_count = n;
        memcpy(r->counter_counts, counts, sizeof(counts));
        CHECK_EQ(compare(&out), 0);
    }
    r->coalesced = 0xFFFFu;
    CHECK_EQ(compare(&out), 0);
    uint8_t buf[protoduino_ArduinoOut_size + 8];
    r->analog_values_count = 7; /* corrupt: refused */
    CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 0);
    r->analog_values_count = 0;
    r->counter_counts_count = 5;
    CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 0);
}

static void test_encode_bound_holds_every_ack_shape_sent(void)
{
    uint8_t buf[protoduino_ArduinoOut_size + 8];
    /* The largest of each shape the device sends fits PD_ENCODE_MAX. */
    protoduino_ArduinoOut out = ack(0xFFFFFFFFu, protoduino_Status_STATUS_NOT_SUPPORTED);
    out.data.ack.which_result = protoduino_Ack_ping_echo_tag;
    out.data.ack.result.ping_echo.size = 64;
    memset(out.data.ack.result.ping_echo.bytes, 0xFF, 64);
    out.data.ack.has_failsafe = true; /* a liveness message's Ack */
    out.data.ack.failsafe.active = true;
    out.data.ack.failsafe.cause = protoduino_FailsafeCause_FAILSAFE_CAUSE_INTERLOCK;
    out.data.ack.failsafe.epoch = 255;
    out.data.ack.failsafe.pin = 255;
    size_t n = pd_encode_out(&out, buf, PD_ENCODE_MAX);
    CHECK(n > 0 && n <= PD_ENCODE_MAX);
    /* A shape it never sends (a result beside a refused item): refused, nothing written past. */
    out.data.ack.which_result = protoduino_Ack_info_tag;
    memset(&out.data.ack.result.info, 0xFF, sizeof(out.data.ack.result.info));
    out.data.ack.refused_item = 200;
    memset(buf, 0xA5, sizeof(buf));
    CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 0);
    CHECK_EQ(buf[PD_ENCODE_MAX], 0xA5);
    CHECK(PD_ENCODE_MAX < protoduino_ArduinoOut_size);
}

static void test_encode_empty(void)
{
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    uint8_t buf[4];
    CHECK_EQ(pd_encode_out(&out, buf, sizeof(buf)), 0);
    CHECK_EQ(compare(&out), 0);
}

const pd_test_case_t pd_tests_encode[] = {
    TEST_CASE(test_encode_ack_plain),
    TEST_CASE(test_encode_ack_ok),
    TEST_CASE(test_encode_ack_ping_echo),
    TEST_CASE(test_encode_ack_info),
    TEST_CASE(test_encode_failsafe_decode_error),
    TEST_CASE(test_encode_ack_outputs_and_refused_item),
    TEST_CASE(test_encode_input_report),
    TEST_CASE(test_encode_bound_holds_every_ack_shape_sent),
    TEST_CASE(test_encode_empty),
    {NULL, NULL},
};

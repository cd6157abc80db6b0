/*
 * User services on the device (firmware/core/pd_user.c, docs/protocol.md section 7
 * "User services"), with the probe service (tests/c/user/probe.proto): built only
 * by `make -C firmware unit-user`, which runs every other test with the feature on too.
 */
#include <string.h>

#include <pb_decode.h>
#include <pb_encode.h>

#include "pd_encode.h"
#include "pd_test.h"
#include "probe.h"
#include "test_util.h"

#if PD_FEATURE_USER

/* A UserCall of `method` carrying `req` (NULL: an empty request). */
static protoduino_ArduinoIn m_user(uint32_t id, uint8_t method, const probe_Req *req)
{
    protoduino_ArduinoIn in = protoduino_ArduinoIn_init_zero;
    in.message_id = id;
    in.which_data = protoduino_ArduinoIn_user_call_tag;
    in.data.user_call.method = method;
    if (req != NULL) {
        pb_ostream_t s = pb_ostream_from_buffer(in.data.user_call.request.bytes,
                                                sizeof(in.data.user_call.request.bytes));
        if (pb_encode(&s, probe_Req_fields, req)) {
            in.data.user_call.request.size = (pb_size_t)s.bytes_written;
        }
    }
    return in;
}

/* The Ack of `id`, its reply decoded into *rep; false if the Ack carried none. */
static bool reply_of(const tdev_t *d, uint32_t id, protoduino_Ack *ack, probe_Rep *rep)
{
    memset(rep, 0, sizeof(*rep));
    if (t_acks(d, id, ack) != 1 || ack->which_result != protoduino_Ack_user_reply_tag) {
        return false;
    }
    pb_istream_t s = pb_istream_from_buffer(ack->result.user_reply.bytes, ack->result.user_reply.size);
    return pb_decode(&s, probe_Rep_fields, rep);
}

static void reset_record(void)
{
    memset(&probe_record, 0, sizeof(probe_record));
}

static void test_a_call_runs_its_handler_and_replies_in_the_users_schema(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    probe_Req req = {41, {3, {1, 2, 3}}};
    protoduino_ArduinoIn in = m_user(10, 1, &req);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    protoduino_Ack ack;
    probe_Rep rep;
    CHECK(reply_of(&d, 10, &ack, &rep));
    CHECK_EQ(rep.value, 42);
    CHECK_EQ(rep.blob.size, 3);
    CHECK_EQ(rep.blob.bytes[2], 3);
    CHECK_EQ(ack.user_code, 0);
    CHECK_EQ(probe_record.echoes, 1);
}

static void test_a_repeat_is_answered_from_the_window_without_its_reply(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    probe_Req req = {5, {0, {0}}};
    protoduino_ArduinoIn in = m_user(11, 1, &req);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    fake_clear(&d.hal);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK); /* the retransmission */
    protoduino_Ack ack;
    probe_Rep rep;
    CHECK(!reply_of(&d, 11, &ack, &rep)); /* status only: the host knows the reply was lost */
    CHECK_EQ(probe_record.echoes, 1);     /* exactly once */
}

static void test_a_read_only_method_is_answered_in_full_every_time(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    protoduino_ArduinoIn in = m_user(12, 2, NULL);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    fake_clear(&d.hal);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    protoduino_Ack ack;
    probe_Rep rep;
    CHECK(reply_of(&d, 12, &ack, &rep));
    CHECK_EQ(probe_record.peeks, 2);
}

static void test_the_handlers_code_unknown_methods_and_bad_requests(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    probe_Req zero = {0, {0, {0}}};
    protoduino_ArduinoIn in = m_user(13, 1, &zero);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_USER_ERROR);
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 13, &ack), 1);
    CHECK_EQ(ack.user_code, probe_ProbeError_PROBE_ERROR_REFUSED);
    CHECK_EQ(ack.which_result, 0);
    in = m_user(14, 9, NULL); /* no such method */
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_UNKNOWN_COMMAND);
    in = m_user(15, 4, NULL); /* a report is no call */
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_UNKNOWN_COMMAND);
    in = m_user(16, 1, NULL);
    in.data.user_call.request.size = 2; /* field 1, varint, then nothing: truncated */
    in.data.user_call.request.bytes[0] = 0x08;
    in.data.user_call.request.bytes[1] = 0x80;
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_DECODE_ERROR);
    CHECK_EQ(probe_record.echoes, 1);
}

static void test_the_failsafe_refuses_commanding_methods_not_reads(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    d.hal.now_ms += 10000u; /* the default timeout, no liveness message */
    pd_core_poll(&d.core);
    probe_Req req = {1, {0, {0}}};
    protoduino_ArduinoIn in = m_user(17, 1, &req);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_FAILSAFE_EXPIRED);
    in = m_user(18, 2, NULL);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    CHECK_EQ(probe_record.echoes, 0);
}

static void test_user_pins_share_the_pin_table_and_go_safe(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    probe_Req req = {5, {0, {0}}};
    protoduino_ArduinoIn in = m_user(20, 3, &req);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    protoduino_Ack ack;
    probe_Rep rep;
    CHECK(reply_of(&d, 20, &ack, &rep));
    CHECK_EQ(rep.value, protoduino_Status_STATUS_OK);
    CHECK_EQ(d.hal.digital[5], 1);
    in = m_digital_init(21, 5, false); /* a built-in on the user's pin */
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_PIN_IN_USE);
    in = m_digital_init(22, 6, false);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    req.value = 6; /* the user's claim of a built-in's pin */
    in = m_user(23, 3, &req);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    CHECK(reply_of(&d, 23, &ack, &rep));
    CHECK_EQ(rep.value, protoduino_Status_STATUS_PIN_IN_USE);
    in = m_stop(24);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    CHECK_EQ(probe_record.safe_pins, 1ul << 5);
    CHECK_EQ(d.hal.digital[5], 0);
    memset(&in, 0, sizeof(in));
    in.message_id = 25;
    in.which_data = protoduino_ArduinoIn_release_all_tag;
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    CHECK_EQ(probe_record.released_pins, 1ul << 5);
}

static void test_a_handler_releases_its_own_pins_never_a_builtins(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    probe_Req req = {5, {0, {0}}};
    protoduino_ArduinoIn in = m_user(30, 3, &req); /* the probe claims pin 5 */
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    in = m_digital_init(31, 6, false);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    pd_user_ctx_t ctx = {&d.core, &d.hal};
    CHECK(pd_user_owns(&ctx, 5));
    CHECK_EQ(pd_user_release(&ctx, 6), protoduino_Status_STATUS_NOT_INITIALISED);
    CHECK_EQ(pd_user_release(&ctx, 7), protoduino_Status_STATUS_NOT_INITIALISED);
    CHECK_EQ(probe_record.released_pins, 0ul);
    CHECK_EQ(pd_user_release(&ctx, 5), protoduino_Status_STATUS_OK);
    CHECK_EQ(probe_record.released_pins, 1ul << 5); /* its release hook ran */
    CHECK(!pd_user_owns(&ctx, 5));
    CHECK_EQ(pd_user_release(&ctx, 5), protoduino_Status_STATUS_NOT_INITIALISED);
    in = m_digital_init(32, 5, false); /* free for any mode again */
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
    in = m_digital_init(33, 6, true); /* the built-in's pin is still its own */
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK);
}

static void test_reports_newest_wins_with_the_count_of_replaced(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    pd_user_ctx_t ctx = {&d.core, &d.hal};
    d.hal.tx_room = 0; /* no room: the values wait */
    probe_record.level = 1;
    pd_user_publish(&ctx, 4);
    probe_record.level = 2;
    pd_user_publish(&ctx, 4);
    probe_record.level = 3;
    pd_user_publish(&ctx, 4);
    pd_core_poll(&d.core);
    CHECK_EQ(fake_count(&d.hal), 0);
    d.hal.tx_room = 1000;
    pd_core_poll(&d.core);
    CHECK_EQ(fake_count(&d.hal), 1);
    protoduino_ArduinoOut out;
    CHECK(t_out(&d, 0, &out));
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_user_report_tag);
    CHECK_EQ(out.data.user_report.report, 4);
    CHECK_EQ(out.data.user_report.coalesced, 2);
    probe_Rep rep = probe_Rep_init_zero;
    pb_istream_t s = pb_istream_from_buffer(out.data.user_report.body.bytes,
                                            out.data.user_report.body.size);
    CHECK(pb_decode(&s, probe_Rep_fields, &rep));
    CHECK_EQ(rep.value, 3); /* the newest */
    pd_core_poll(&d.core);
    CHECK_EQ(fake_count(&d.hal), 1); /* sent once */
    CHECK_EQ(probe_record.polled_at, d.hal.now_ms);
}

/* pd_encode_out against pb_encode for the user shapes (test_encode.c does the rest). */
static int same_as_pb_encode(const protoduino_ArduinoOut *msg)
{
    uint8_t ours[protoduino_ArduinoOut_size + 8];
    uint8_t theirs[protoduino_ArduinoOut_size + 8];
    pb_ostream_t s = pb_ostream_from_buffer(theirs, sizeof(theirs));
    if (!pb_encode(&s, protoduino_ArduinoOut_fields, msg)) {
        return -1;
    }
    size_t n = pd_encode_out(msg, ours, sizeof(ours));
    return n == s.bytes_written && memcmp(ours, theirs, n) == 0 ? 0 : (int)n + 1000;
}

static void test_a_reply_beyond_its_bounds_is_sent_within_them(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    protoduino_ArduinoIn in = m_user(20, 5, NULL);
    CHECK_EQ(t_cmd(&d, &in), protoduino_Status_STATUS_OK); /* it ran: never a refusal */
    CHECK_EQ(probe_record.overfills, 1);
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 20, &ack), 1);
    CHECK_EQ(ack.which_result, protoduino_Ack_user_reply_tag);
    probe_Label label = probe_Label_init_zero;
    pb_istream_t s = pb_istream_from_buffer(ack.result.user_reply.bytes, ack.result.user_reply.size);
    CHECK(pb_decode(&s, probe_Label_fields, &label));
    CHECK_EQ(strcmp(label.text, "xxxxxxx"), 0); /* its last byte is the terminator's */
    CHECK_EQ(label.values_count, 3);
    CHECK_EQ(label.values[2], 3);
    CHECK(label.has_tag);
    CHECK_EQ(strcmp(label.tag.text, "yyy"), 0);
    CHECK_EQ(label.tag.blob.size, 4);
    CHECK_EQ(label.tag.blob.bytes[3], 'z');
}

static void test_a_report_beyond_its_bounds_is_sent_within_them(void)
{
    tdev_t d;
    t_active(&d);
    reset_record();
    pd_user_ctx_t ctx = {&d.core, &d.hal};
    probe_record.level = 9;
    probe_record.report_blob = 200;
    pd_user_publish(&ctx, 4);
    pd_core_poll(&d.core);
    protoduino_ArduinoOut out;
    CHECK(t_out(&d, 0, &out)); /* sent, not dropped */
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_user_report_tag);
    probe_Rep rep = probe_Rep_init_zero;
    pb_istream_t s = pb_istream_from_buffer(out.data.user_report.body.bytes,
                                            out.data.user_report.body.size);
    CHECK(pb_decode(&s, probe_Rep_fields, &rep));
    CHECK_EQ(rep.value, 9);
    CHECK_EQ(rep.blob.size, sizeof(rep.blob.bytes));
    CHECK_EQ(rep.blob.bytes[0], 'r');
}

static void test_the_encoder_writes_the_user_shapes_as_pb_encode(void)
{
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    out.which_data = protoduino_ArduinoOut_ack_tag;
    out.data.ack.message_id = 0xFFFFFFFFu;
    out.data.ack.which_result = protoduino_Ack_user_reply_tag;
    CHECK_EQ(same_as_pb_encode(&out), 0); /* an empty reply is still written */
    out.data.ack.result.user_reply.size = 64;
    memset(out.data.ack.result.user_reply.bytes, 0xA5, 64);
    CHECK_EQ(same_as_pb_encode(&out), 0);
    out.data.ack.which_result = 0;
    out.data.ack.status = protoduino_Status_STATUS_USER_ERROR;
    out.data.ack.user_code = 255;
    CHECK_EQ(same_as_pb_encode(&out), 0);
    memset(&out.data.ack.result, 0, sizeof(out.data.ack.result));
    out.data.ack.which_result = protoduino_Ack_info_tag;
    out.data.ack.status = protoduino_Status_STATUS_OK;
    out.data.ack.user_code = 0;
    out.data.ack.result.info.user_fingerprint = 0x80000001u;
    CHECK_EQ(same_as_pb_encode(&out), 0);
    memset(&out, 0, sizeof(out));
    out.which_data = protoduino_ArduinoOut_user_report_tag;
    out.data.user_report.report = 255;
    out.data.user_report.coalesced = 65535;
    out.data.user_report.body.size = 64;
    CHECK_EQ(same_as_pb_encode(&out), 0);
    out.data.user_report.body.size = 0;
    CHECK_EQ(same_as_pb_encode(&out), 0);
}

const pd_test_case_t pd_tests_user[] = {
    TEST_CASE(test_a_call_runs_its_handler_and_replies_in_the_users_schema),
    TEST_CASE(test_a_repeat_is_answered_from_the_window_without_its_reply),
    TEST_CASE(test_a_read_only_method_is_answered_in_full_every_time),
    TEST_CASE(test_the_handlers_code_unknown_methods_and_bad_requests),
    TEST_CASE(test_the_failsafe_refuses_commanding_methods_not_reads),
    TEST_CASE(test_user_pins_share_the_pin_table_and_go_safe),
    TEST_CASE(test_a_handler_releases_its_own_pins_never_a_builtins),
    TEST_CASE(test_reports_newest_wins_with_the_count_of_replaced),
    TEST_CASE(test_a_reply_beyond_its_bounds_is_sent_within_them),
    TEST_CASE(test_a_report_beyond_its_bounds_is_sent_within_them),
    TEST_CASE(test_the_encoder_writes_the_user_shapes_as_pb_encode),
    {NULL, NULL},
};

#endif /* PD_FEATURE_USER */

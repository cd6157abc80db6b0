/* The failsafe on a fake clock, Stop, and the latched safe state. */
#include <string.h>

#include "pd_test.h"
#include "test_util.h"

#define S(name) protoduino_Status_STATUS_##name
#define CAUSE(name) protoduino_FailsafeCause_FAILSAFE_CAUSE_##name

/* An active device with a servo on 9 (safe 90 deg = 1472 us) and pin 13 (safe low), both moved. */
static void setup_outputs(tdev_t *d)
{
    t_active(d);
    protoduino_ArduinoIn in = m_servo_init_deg(1, 9, 0, 0, 90);
    t_send_in(d, &in);
    in = m_digital_init(2, 13, false);
    t_send_in(d, &in);
    in = m_servo_us(3, 9, 2000);
    t_send_in(d, &in);
    in = m_digital(4, 13, true);
    t_send_in(d, &in);
    fake_clear(&d->hal);
}

static void ping_at(tdev_t *d, uint32_t id, uint32_t now)
{
    d->hal.now_ms = now;
    protoduino_ArduinoIn in = m_ping(id, NULL, 0);
    t_send_in(d, &in);
}

static void test_failsafe_fires_at_10000_not_9999(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 5000);
    CHECK_EQ(d.hal.servo_us[9], 2000);
    fake_clear(&d.hal);
    d.hal.now_ms = 5000 + 9999;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 2000); /* not yet */
    CHECK_EQ(d.hal.digital[13], 1);
    CHECK_EQ(t_failsafes(&d, NULL), 0);
    CHECK_EQ(d.hal.outputs_safe_calls, 0u);
    d.hal.now_ms = 5000 + 10000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.outputs_safe_calls, 1u); /* the HAL may apply them at once */
    CHECK_EQ(d.hal.servo_us[9], 1472); /* safe values */
    CHECK_EQ(d.hal.digital[13], 0);
    protoduino_Failsafe fs;
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(fs.active);
    CHECK_EQ(fs.cause, CAUSE(PING_TIMEOUT));
    CHECK(d.core.failsafe.active);
}

static void test_failsafe_once_per_silence(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 5000);
    d.hal.now_ms = 15000;
    pd_core_poll(&d.core);
    fake_clear(&d.hal);
    unsigned writes = d.hal.servo_writes[9];
    for (uint32_t t = 15001; t < 60000; t += 997) {
        d.hal.now_ms = t;
        pd_core_poll(&d.core);
    }
    CHECK_EQ(t_failsafes(&d, NULL), 0);
    CHECK_EQ(d.hal.servo_writes[9], writes);
}

static void test_failsafe_counts_from_handshake_without_ping(void)
{
    tdev_t d;
    t_boot(&d);
    d.hal.now_ms = 50000; /* long after boot: an IDLE device has nothing to do */
    pd_core_poll(&d.core);
    CHECK(!d.core.failsafe.active);
    t_send_reset(&d, 1);
    protoduino_ArduinoIn in = m_digital_init(1, 13, false);
    t_send_in(&d, &in);
    in = m_digital(2, 13, true);
    t_send_in(&d, &in);
    fake_clear(&d.hal);
    d.hal.now_ms = 50000 + 9999;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.digital[13], 1);
    d.hal.now_ms = 50000 + 10000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.digital[13], 0);
    CHECK_EQ(t_failsafes(&d, NULL), 1);
}

static void test_other_commands_do_not_feed_the_timer(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    d.hal.now_ms = 9000;
    protoduino_ArduinoIn in = m_servo_us(11, 9, 1900);
    t_send_in(&d, &in);
    in = m_info(12);
    t_send_in(&d, &in);
    const uint8_t hb[] = {PD_CONTROL_HEARTBEAT};
    t_send_packet(&d, PD_PACKET_CONTROL, d.host_seq++, hb, 1);
    d.hal.now_ms = 11000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
}

static void test_ping_clears_flag_outputs_stay_latched(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    d.hal.now_ms = 11000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    unsigned servo_writes = d.hal.servo_writes[9];
    unsigned digital_writes = d.hal.digital_writes[13];
    fake_clear(&d.hal);
    ping_at(&d, 11, 12000);
    CHECK_EQ(t_status(&d, 11), S(OK));
    protoduino_Failsafe fs;
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(!fs.active);
    CHECK(!d.core.failsafe.active);
    /* The Ack comes before the event. */
    protoduino_ArduinoOut out;
    CHECK(t_out(&d, 0, &out));
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_ack_tag);
    /* Latched: nothing moved by itself. */
    CHECK_EQ(d.hal.servo_us[9], 1472);
    CHECK_EQ(d.hal.digital[13], 0);
    CHECK_EQ(d.hal.servo_writes[9], servo_writes);
    CHECK_EQ(d.hal.digital_writes[13], digital_writes);
    /* A further Ping sends no event. */
    fake_clear(&d.hal);
    ping_at(&d, 12, 12500);
    CHECK_EQ(t_failsafes(&d, NULL), 0);
    /* Each output moves again when commanded. */
    protoduino_ArduinoIn in = m_servo_deg(13, 9, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 544);
    CHECK_EQ(d.hal.digital[13], 0);
    in = m_digital(14, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 1);
    /* And a new silence fires again. */
    fake_clear(&d.hal);
    d.hal.now_ms = 12500 + 10000;
    pd_core_poll(&d.core);
    CHECK_EQ(t_failsafes(&d, NULL), 1);
    CHECK_EQ(d.hal.servo_us[9], 1472);
}

static void test_duplicate_ping_counts_as_liveness(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    ping_at(&d, 10, 8000); /* same id: still restarts the timer */
    d.hal.now_ms = 17999;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 2000);
    d.hal.now_ms = 18000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
}

static void test_failsafe_clock_wraps(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 0xFFFFFFFFu - 3000u);
    d.hal.now_ms = 0xFFFFFFFFu - 3000u + 9999u; /* wrapped past zero */
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 2000);
    d.hal.now_ms = 0xFFFFFFFFu - 3000u + 10000u;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
}

static void test_stop(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    fake_clear(&d.hal);
    protoduino_ArduinoIn in = m_stop(20);
    unsigned safe_calls = d.hal.outputs_safe_calls;
    t_send_in(&d, &in);
    CHECK_EQ(d.hal.outputs_safe_calls, safe_calls + 1u);
    CHECK_EQ(d.hal.servo_us[9], 1472); /* at once */
    CHECK_EQ(d.hal.digital[13], 0);
    CHECK_EQ(t_status(&d, 20), S(OK));
    protoduino_Failsafe fs;
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(fs.active);
    CHECK_EQ(fs.cause, CAUSE(STOP));
    protoduino_ArduinoOut out;
    CHECK(t_out(&d, 0, &out));
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_ack_tag); /* Ack, then the event */
    /* A repeated Stop id is re-acked, not executed (no second event). */
    fake_clear(&d.hal);
    t_send_in(&d, &in);
    CHECK_EQ(t_status(&d, 20), S(OK));
    CHECK_EQ(t_failsafes(&d, NULL), 0);
    /* The timer does not fire on top of a Stop. */
    d.hal.now_ms = 30000;
    pd_core_poll(&d.core);
    CHECK_EQ(t_failsafes(&d, NULL), 0);
    /* Latched: a control moves an output normally; the next Ping clears the flag. */
    in = m_digital(21, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 1);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    fake_clear(&d.hal);
    ping_at(&d, 22, 31000);
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(!fs.active);
}

static void test_stop_with_nothing_configured(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_stop(1);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(t_failsafes(&d, NULL), 1);
}

static void test_failsafe_unit(void)
{
    pd_failsafe_t fs;
    pd_failsafe_init(&fs, 100);
    CHECK(!pd_failsafe_due(&fs, 100 + 9999));
    CHECK(pd_failsafe_due(&fs, 100 + 10000));
    pd_failsafe_set(&fs);
    CHECK(!pd_failsafe_due(&fs, 100 + 20000));
    CHECK(pd_failsafe_ping(&fs, 30000));
    CHECK(!pd_failsafe_ping(&fs, 30001));
    pd_failsafe_restart(&fs, 35000);
    CHECK(!pd_failsafe_due(&fs, 44999));
    CHECK(pd_failsafe_due(&fs, 45000));
}

const pd_test_case_t pd_tests_failsafe[] = {
    TEST_CASE(test_failsafe_fires_at_10000_not_9999),
    TEST_CASE(test_failsafe_once_per_silence),
    TEST_CASE(test_failsafe_counts_from_handshake_without_ping),
    TEST_CASE(test_other_commands_do_not_feed_the_timer),
    TEST_CASE(test_ping_clears_flag_outputs_stay_latched),
    TEST_CASE(test_duplicate_ping_counts_as_liveness),
    TEST_CASE(test_failsafe_clock_wraps),
    TEST_CASE(test_stop),
    TEST_CASE(test_stop_with_nothing_configured),
    TEST_CASE(test_failsafe_unit),
    {NULL, NULL},
};

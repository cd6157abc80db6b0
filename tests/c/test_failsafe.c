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

/* A Ping from a host that saw every Failsafe event so far: it carries the
 * device's current epoch (the stale-epoch tests build theirs by hand). */
static void ping_at(tdev_t *d, uint32_t id, uint32_t now)
{
    d->hal.now_ms = now;
    protoduino_ArduinoIn in = m_ping(id, NULL, 0);
    in.data.ping.failsafe_epoch = d->core.failsafe.epoch;
    t_send_in(d, &in);
}

static void ping_epoch_at(tdev_t *d, uint32_t id, uint32_t now, uint8_t epoch)
{
    d->hal.now_ms = now;
    protoduino_ArduinoIn in = m_ping(id, NULL, 0);
    in.data.ping.failsafe_epoch = epoch;
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
    fake_clear(&d.hal);
    d.hal.now_ms = 50000; /* long after boot: an IDLE device has nothing to make safe */
    pd_core_poll(&d.core);
    CHECK_EQ(fake_count(&d.hal), 0); /* and no one to tell */
    t_send_reset(&d, PD_PROTOCOL_VERSION); /* a new session: the timer counts from here */
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
    const uint8_t old_heartbeat[] = {0x02}; /* a CONTROL, HEARTBEAT until version 3 */
    t_send_packet(&d, PD_PACKET_CONTROL, d.host_seq++, old_heartbeat, 1);
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
    /* Latched: a control moves an output normally... */
    in = m_digital(21, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 1);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    /* ... and the Stop did not stop the timer (defect 1): it fires at the
     * deadline of the last Ping and takes that output back. */
    fake_clear(&d.hal);
    d.hal.now_ms = 1000 + 9999;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.digital[13], 1);
    d.hal.now_ms = 1000 + 10000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.digital[13], 0);
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(fs.active);
    CHECK_EQ(fs.cause, CAUSE(PING_TIMEOUT));
    fake_clear(&d.hal);
    ping_at(&d, 22, 31000);
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(!fs.active);
}

/* Defect 1: after the timer ran out, no Control runs until a liveness message. */
static void test_no_commanded_output_without_a_running_timer(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    d.hal.now_ms = 11000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    fake_clear(&d.hal);
    protoduino_ArduinoIn in = m_servo_deg(11, 9, 45);
    CHECK_EQ(t_cmd(&d, &in), S(FAILSAFE_EXPIRED));
    in = m_digital(12, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(FAILSAFE_EXPIRED));
    /* A Pose of masks only (protocol version 6): refused the same way, no output named. */
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 40;
    in.which_data = protoduino_ArduinoIn_pose_tag;
    T_PUT_MASK(in.data.pose.digital_pins, 1UL << 13);
    T_PUT_MASK(in.data.pose.digital_levels, 1UL << 13);
    CHECK_EQ(t_cmd(&d, &in), S(FAILSAFE_EXPIRED));
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 40, &ack), 1);
    CHECK_EQ(ack.refused_item, 0);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    CHECK_EQ(d.hal.digital[13], 0);
    /* Inits only drive safe values: allowed. */
    in = m_digital_init(13, 12, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    /* A Ping restarts the timer: controls run again, and are protected again. */
    ping_at(&d, 14, 12000);
    in = m_servo_deg(15, 9, 45);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    d.hal.now_ms = 22000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    /* The device acts on the expiry at its next poll (every millisecond), and from
     * then on refuses Controls. */
    ping_at(&d, 16, 23000);
    d.hal.now_ms = 33000;
    pd_core_poll(&d.core);
    in = m_servo_deg(17, 9, 45);
    CHECK_EQ(t_cmd(&d, &in), S(FAILSAFE_EXPIRED));
}

/* Defect 2: a RESET of the same session is not liveness; a new session's is. */
static void test_reset_does_not_feed_the_timer(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    for (uint32_t t = 2000; t < 11000; t += 1000) {
        d.hal.now_ms = t;
        t_send_reset(&d, PD_PROTOCOL_VERSION); /* a deaf host's watchdog */
        pd_core_poll(&d.core);
    }
    CHECK_EQ(d.hal.servo_us[9], 2000);
    d.hal.now_ms = 11000;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    CHECK_EQ(d.hal.digital[13], 0);
}

static void test_configured_timeout_and_heartbeat_source(void)
{
    tdev_t d;
    setup_outputs(&d);
    protoduino_ArduinoIn in = {0};
    in.message_id = 30;
    in.which_data = protoduino_ArduinoIn_configure_failsafe_tag;
    in.data.configure_failsafe.timeout_ms = 99; /* below the range */
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
    in.message_id = 31;
    in.data.configure_failsafe.timeout_ms = 60001;
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
    in.message_id = 32;
    in.data.configure_failsafe.timeout_ms = 300;
    in.data.configure_failsafe.liveness = protoduino_Liveness_LIVENESS_HEARTBEAT;
    d.hal.now_ms = 5000;
    CHECK_EQ(t_cmd(&d, &in), S(OK)); /* restarts the timer */
    in = m_servo_us(33, 9, 2000);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    ping_at(&d, 34, 5200); /* not liveness with LIVENESS_HEARTBEAT */
    d.hal.now_ms = 5299;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 2000);
    d.hal.now_ms = 5300;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    /* A Heartbeat is; it clears the flag like a Ping. */
    fake_clear(&d.hal);
    d.hal.now_ms = 6000;
    memset(&in, 0, sizeof(in));
    in.message_id = 35;
    in.which_data = protoduino_ArduinoIn_heartbeat_tag;
    in.data.heartbeat.failsafe_epoch = d.core.failsafe.epoch;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    protoduino_Failsafe fs;
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(!fs.active);
    in = m_servo_us(36, 9, 2000);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    d.hal.now_ms = 6299;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 2000);
    d.hal.now_ms = 6300;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.servo_us[9], 1472);
    /* A new session starts again from the defaults. */
    t_send_reset_session(&d, 77);
    CHECK_EQ(d.core.failsafe.timeout_ms, PD_FAILSAFE_TIMEOUT_MS);
    CHECK(!d.core.failsafe.heartbeat_only);
}

static void test_servo_safe_detach(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_us(1, 9, 0, 0, 1500);
    in.data.servo_init.which_safe = protoduino_ServoInit_safe_detach_tag;
    in.data.servo_init.safe.safe_detach = true;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 0); /* limp from the start */
    in = m_servo_us(2, 9, 2000);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 2000);
    in = m_stop(3);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 0);
    in = m_servo_init_us(4, 9, 0, 0, 1500);
    in.data.servo_init.which_safe = protoduino_ServoInit_safe_detach_tag;
    in.data.servo_init.safe.safe_detach = false; /* not a safe state */
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
}

static void test_same_init_again_leaves_the_pin_alone(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    unsigned servo_writes = d.hal.servo_writes[9];
    unsigned digital_writes = d.hal.digital_writes[13];
    protoduino_ArduinoIn in = m_servo_init_deg(20, 9, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital_init(21, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_writes[9], servo_writes);
    CHECK_EQ(d.hal.digital_writes[13], digital_writes);
    CHECK_EQ(d.hal.servo_us[9], 2000);
    CHECK_EQ(d.hal.digital[13], 1);
    /* Another configuration does re-init to the (new) safe value. */
    in = m_digital_init(22, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital_writes[13], digital_writes + 1u);
    in = m_servo_init_deg(23, 9, 0, 0, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 544);
}

static void test_release_and_release_all(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    protoduino_ArduinoIn in = {0};
    in.message_id = 20;
    in.which_data = protoduino_ArduinoIn_release_tag;
    in.data.release.pin = 9;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 0);
    CHECK_EQ(d.core.outputs.owner[9], 0);
    in.message_id = 21; /* twice: nothing to release */
    CHECK_EQ(t_cmd(&d, &in), S(NOT_INITIALISED));
    in.message_id = 22;
    in.data.release.pin = 1;
    CHECK_EQ(t_cmd(&d, &in), S(RESERVED_PIN));
    /* The freed pin takes another mode; its servo slot is free again. */
    in = m_digital_init(23, 9, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    for (uint32_t pin = 2; pin < 10; pin++) {
        in = m_servo_init_deg(30 + pin, pin == 9 ? 10 : pin, 0, 0, 90);
        CHECK_EQ(t_cmd(&d, &in), S(OK));
    }
    CHECK_EQ(pd_pins_count(d.core.outputs.owner, PD_MODE_SERVO), 8);
    memset(&in, 0, sizeof(in));
    in.message_id = 50;
    in.which_data = protoduino_ArduinoIn_release_all_tag;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(pd_pins_count(d.core.outputs.owner, PD_MODE_SERVO), 0);
    CHECK_EQ(d.hal.digital[13], -1);
    CHECK_EQ(d.hal.digital[9], -1);
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        CHECK_EQ(d.core.outputs.owner[pin], 0);
    }
    in = m_servo_deg(51, 2, 10);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_INITIALISED));
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
    pd_failsafe_stop(&fs); /* a Stop leaves the timer running */
    CHECK(pd_failsafe_due(&fs, 100 + 10000));
    pd_failsafe_fire(&fs);
    CHECK(!pd_failsafe_due(&fs, 100 + 20000));
    CHECK(pd_failsafe_expired(&fs, 100 + 20000));
    fs.epoch = 0; /* pd_core_init's job */
    pd_failsafe_init(&fs, 100);
    pd_failsafe_stop(&fs);
    CHECK_EQ(fs.epoch, 1);
    pd_failsafe_fire(&fs);
    CHECK_EQ(fs.epoch, 2);
    CHECK_EQ(fs.cause, CAUSE(PING_TIMEOUT));
    CHECK_EQ(pd_failsafe_alive(&fs, 30000, 1), PD_ALIVE_STALE); /* from before the fire */
    CHECK(fs.fired && fs.active);
    CHECK_EQ(pd_failsafe_alive(&fs, 30000, 2), PD_ALIVE_CLEARED);
    CHECK_EQ(pd_failsafe_alive(&fs, 30001, 2), PD_ALIVE_OK);
    CHECK(!pd_failsafe_expired(&fs, 40000));
    CHECK(pd_failsafe_due(&fs, 40001));
    pd_failsafe_fire(&fs);
    pd_failsafe_restart(&fs, 50000); /* a configuration never clears a fired failsafe */
    CHECK(fs.fired && pd_failsafe_expired(&fs, 50000));
    fs.epoch = 255;
    pd_failsafe_fire(&fs);
    CHECK_EQ(fs.epoch, 0); /* modulo 256 */
}

/*
 * Issue 20, item 1: bytes held up on the way (a paused ser2net, a Wi-Fi outage
 * that TCP survives) reach the device after its failsafe fired. The Pings and
 * the Control among them were written before the host knew of it: none may
 * clear the failsafe or move an output; the Pings' Acks tell the host the
 * state; the host's next Ping with that epoch re-arms, and only then a Control
 * runs.
 */
static void test_late_pings_never_rearm(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    d.hal.now_ms = 11000;
    pd_core_poll(&d.core); /* fires: epoch 1 */
    CHECK_EQ(d.hal.servo_us[9], 1472);
    protoduino_Failsafe fs;
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(fs.active);
    CHECK_EQ(fs.epoch, 1);
    CHECK_EQ(fs.cause, CAUSE(PING_TIMEOUT));
    fake_clear(&d.hal);
    /* The held-up bytes: two Pings and a Control, all from before the failsafe. */
    ping_epoch_at(&d, 11, 21000, 0);
    ping_epoch_at(&d, 12, 21001, 0);
    /* Each late Ping's Ack carries the state: active, epoch 1. */
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 12, &ack), 1);
    CHECK(ack.has_failsafe);
    CHECK(ack.failsafe.active);
    CHECK_EQ(ack.failsafe.epoch, 1);
    CHECK_EQ(ack.failsafe.cause, CAUSE(PING_TIMEOUT));
    CHECK_EQ(t_failsafes(&d, NULL), 0); /* nothing cleared */
    protoduino_ArduinoIn in = m_servo_us(13, 9, 2000);
    CHECK_EQ(t_cmd(&d, &in), S(FAILSAFE_EXPIRED));
    CHECK_EQ(d.hal.servo_us[9], 1472);
    CHECK(d.core.failsafe.fired);
    /* A late ConfigureFailsafe does not clear it either. */
    memset(&in, 0, sizeof(in));
    in.message_id = 14;
    in.which_data = protoduino_ArduinoIn_configure_failsafe_tag;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK(d.core.failsafe.fired);
    /* Nor a late Heartbeat. */
    memset(&in, 0, sizeof(in));
    in.message_id = 15;
    in.which_data = protoduino_ArduinoIn_heartbeat_tag;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK(d.core.failsafe.fired);
    /* The host that saw it sends epoch 1: cleared after the Ack, and a Control runs. */
    fake_clear(&d.hal);
    ping_epoch_at(&d, 16, 22000, 1);
    CHECK_EQ(t_acks(&d, 16, &ack), 1);
    CHECK(ack.has_failsafe);
    CHECK(!ack.failsafe.active);
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(!fs.active);
    CHECK_EQ(fs.epoch, 1);
    in = m_servo_us(17, 9, 2000);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 2000);
}

/* A Stop is a safe state too: Pings from before it no longer feed the timer,
 * which fires at the deadline of the last Ping that knew the epoch. */
static void test_stop_advances_the_epoch(void)
{
    tdev_t d;
    setup_outputs(&d);
    ping_at(&d, 10, 1000);
    protoduino_ArduinoIn in = m_stop(11);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.core.failsafe.epoch, 1);
    ping_epoch_at(&d, 12, 5000, 0); /* written before the Stop */
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 12, &ack), 1);
    CHECK(ack.has_failsafe && ack.failsafe.active);
    CHECK_EQ(ack.failsafe.cause, CAUSE(STOP));
    d.hal.now_ms = 11000;
    pd_core_poll(&d.core);
    CHECK(d.core.failsafe.fired); /* from the Ping at 1000, not the one at 5000 */
    CHECK_EQ(d.core.failsafe.epoch, 2);
    /* No safe state since power-up: the Ack carries no failsafe field. */
    tdev_t fresh;
    t_active(&fresh);
    in = m_ping(1, NULL, 0);
    t_send_in(&fresh, &in);
    CHECK_EQ(t_acks(&fresh, 1, &ack), 1);
    CHECK(!ack.has_failsafe);
}

const pd_test_case_t pd_tests_failsafe[] = {
    TEST_CASE(test_failsafe_fires_at_10000_not_9999),
    TEST_CASE(test_failsafe_once_per_silence),
    TEST_CASE(test_failsafe_counts_from_handshake_without_ping),
    TEST_CASE(test_other_commands_do_not_feed_the_timer),
    TEST_CASE(test_ping_clears_flag_outputs_stay_latched),
    TEST_CASE(test_duplicate_ping_counts_as_liveness),
    TEST_CASE(test_late_pings_never_rearm),
    TEST_CASE(test_stop_advances_the_epoch),
    TEST_CASE(test_failsafe_clock_wraps),
    TEST_CASE(test_stop),
    TEST_CASE(test_stop_with_nothing_configured),
    TEST_CASE(test_no_commanded_output_without_a_running_timer),
    TEST_CASE(test_reset_does_not_feed_the_timer),
    TEST_CASE(test_configured_timeout_and_heartbeat_source),
    TEST_CASE(test_servo_safe_detach),
    TEST_CASE(test_same_init_again_leaves_the_pin_alone),
    TEST_CASE(test_release_and_release_all),
    TEST_CASE(test_failsafe_unit),
    {NULL, NULL},
};

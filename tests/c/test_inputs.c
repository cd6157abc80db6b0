/* Issue 21 on the device: digital inputs (debounce, interlocks), analog inputs (threshold,
 * heartbeat, rounds), counters, and the InputReport (freshness, coalescing, after the Ack). */
#include <string.h>

#include "pd_test.h"
#include "test_util.h"

#define S(name) protoduino_Status_STATUS_##name

static protoduino_ArduinoIn m_din(uint32_t id, uint8_t pin, bool pull_up, uint16_t debounce,
                                  protoduino_Trip trip)
{
    protoduino_ArduinoIn in;
    memset(&in, 0, sizeof(in));
    in.message_id = id;
    in.which_data = protoduino_ArduinoIn_digital_input_init_tag;
    in.data.digital_input_init.pin = pin;
    in.data.digital_input_init.pull_up = pull_up;
    in.data.digital_input_init.debounce_ms = debounce;
    in.data.digital_input_init.interlock = trip;
    return in;
}

static protoduino_ArduinoIn m_ain(uint32_t id, uint8_t pin, uint32_t interval, uint16_t threshold,
                                  uint32_t heartbeat)
{
    protoduino_ArduinoIn in;
    memset(&in, 0, sizeof(in));
    in.message_id = id;
    in.which_data = protoduino_ArduinoIn_analog_input_init_tag;
    in.data.analog_input_init.pin = pin;
    in.data.analog_input_init.interval_ms = interval;
    in.data.analog_input_init.threshold = threshold;
    in.data.analog_input_init.heartbeat_ms = heartbeat;
    return in;
}

static protoduino_ArduinoIn m_counter(uint32_t id, uint8_t pin, protoduino_Edge edge,
                                      uint32_t interval)
{
    protoduino_ArduinoIn in;
    memset(&in, 0, sizeof(in));
    in.message_id = id;
    in.which_data = protoduino_ArduinoIn_counter_init_tag;
    in.data.counter_init.pin = pin;
    in.data.counter_init.edge = edge;
    in.data.counter_init.interval_ms = interval;
    return in;
}

static protoduino_ArduinoIn m_simple(uint32_t id, pb_size_t which)
{
    protoduino_ArduinoIn in;
    memset(&in, 0, sizeof(in));
    in.message_id = id;
    in.which_data = which;
    return in;
}

static void poll_at(tdev_t *d, uint32_t ms)
{
    d->hal.now_ms = ms;
    pd_core_poll(&d->core);
}

/* Reports since the last clear; the last one to *last. */
static int reports(const tdev_t *d, protoduino_InputReport *last)
{
    int n = 0;
    protoduino_ArduinoOut out;
    for (size_t i = 0; i < fake_count(&d->hal); i++) {
        if (t_out(d, i, &out) && out.which_data == protoduino_ArduinoOut_input_report_tag) {
            n++;
            if (last) {
                *last = out.data.input_report;
            }
        }
    }
    return n;
}

static void test_digital_input_level_reported_after_its_ack(void)
{
    tdev_t d;
    t_active(&d);
    d.hal.level[4] = true;
    protoduino_ArduinoIn in = m_din(1, 4, true, 0, protoduino_Trip_TRIP_NONE);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.input[4], 1); /* with its pull-up */
    poll_at(&d, d.hal.now_ms);
    protoduino_InputReport r;
    CHECK_EQ(reports(&d, &r), 1);
    CHECK_EQ(T_MASK(r.digital_pins), 1u << 4);
    CHECK_EQ(T_MASK(r.digital_levels), 1u << 4);
    /* the Ack went first */
    protoduino_ArduinoOut out;
    CHECK(t_out(&d, 0, &out));
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_ack_tag);
    /* Nothing changed: nothing more. */
    poll_at(&d, d.hal.now_ms + 50);
    CHECK_EQ(reports(&d, NULL), 1);
}

static void test_digital_debounce(void)
{
    tdev_t d;
    t_active(&d);
    uint32_t t = d.hal.now_ms + 1000;
    d.hal.now_ms = t;
    protoduino_ArduinoIn in = m_din(1, 7, false, 20, protoduino_Trip_TRIP_NONE);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    poll_at(&d, t);
    fake_clear(&d.hal);
    /* A 10 ms glitch: never reported. */
    d.hal.level[7] = true;
    for (uint32_t ms = 1; ms <= 10; ms++) {
        poll_at(&d, t + ms);
    }
    d.hal.level[7] = false;
    for (uint32_t ms = 11; ms <= 60; ms++) {
        poll_at(&d, t + ms);
    }
    CHECK_EQ(reports(&d, NULL), 0);
    /* A level that holds 20 ms: reported once, 20 ms after it came. */
    d.hal.level[7] = true;
    poll_at(&d, t + 100);
    for (uint32_t ms = 101; ms < 120; ms++) {
        poll_at(&d, t + ms);
    }
    CHECK_EQ(reports(&d, NULL), 0);
    poll_at(&d, t + 120);
    protoduino_InputReport r;
    CHECK_EQ(reports(&d, &r), 1);
    CHECK_EQ(T_MASK(r.digital_levels), 1u << 7);
    CHECK_EQ(r.time_ms, t + 120);
    in = m_din(2, 7, false, 256, protoduino_Trip_TRIP_NONE);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
}

static protoduino_ArduinoIn m_pwm_init(uint32_t id, uint8_t pin, uint16_t safe)
{
    protoduino_ArduinoIn in = m_simple(id, protoduino_ArduinoIn_pwm_init_tag);
    in.data.pwm_init.pin = pin;
    in.data.pwm_init.safe_duty = safe;
    return in;
}

static protoduino_ArduinoIn m_pwm(uint32_t id, uint8_t pin, uint16_t duty)
{
    protoduino_ArduinoIn in = m_simple(id, protoduino_ArduinoIn_pwm_control_tag);
    in.data.pwm_control.pin = pin;
    in.data.pwm_control.duty = duty;
    return in;
}

static void test_interlock_trips_latches_and_clears(void)
{
    tdev_t d;
    t_active(&d);
    uint32_t t = d.hal.now_ms + 500;
    d.hal.now_ms = t;
    d.hal.level[2] = true; /* the bumper, pulled up, closes to ground */
    protoduino_ArduinoIn in = m_din(1, 2, true, 0, protoduino_Trip_TRIP_LOW);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm_init(2, 3, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm(3, 3, 200);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital_init(4, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital(5, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    poll_at(&d, t);
    fake_clear(&d.hal);

    /* The bumper closes: in the same pass, every output safe, and the host told. */
    d.hal.level[2] = false;
    poll_at(&d, t + 1);
    CHECK_EQ(d.hal.pwm[3], 0);
    CHECK_EQ(d.hal.digital[13], 0);
    protoduino_Failsafe fs;
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(fs.active);
    CHECK_EQ(fs.cause, protoduino_FailsafeCause_FAILSAFE_CAUSE_INTERLOCK);
    CHECK_EQ(fs.pin, 2);
    protoduino_InputReport r;
    CHECK_EQ(reports(&d, &r), 1);
    CHECK_EQ(T_MASK(r.digital_levels) & (1u << 2), 0);

    /* Latched: new values refused, with no effect; a Stop or an Init still goes. */
    in = m_pwm(6, 3, 200);
    CHECK_EQ(t_cmd(&d, &in), S(INTERLOCK_ACTIVE));
    in = m_digital(7, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(INTERLOCK_ACTIVE));
    CHECK_EQ(d.hal.pwm[3], 0);
    CHECK_EQ(d.hal.digital[13], 0);
    in = m_stop(8);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    /* Cleared only once the bumper is open again. */
    in = m_simple(9, protoduino_ArduinoIn_clear_interlock_tag);
    CHECK_EQ(t_cmd(&d, &in), S(INTERLOCK_ACTIVE));
    d.hal.level[2] = true;
    poll_at(&d, t + 2);
    in = m_pwm(10, 3, 200);
    CHECK_EQ(t_cmd(&d, &in), S(INTERLOCK_ACTIVE)); /* open, but not cleared yet */
    /* A ClearInterlock from a host that has not seen the latest safe state (the
     * Stop's epoch 2: one written before it and held up on the way) is refused. */
    CHECK_EQ(d.core.failsafe.epoch, 2);
    in = m_simple(13, protoduino_ArduinoIn_clear_interlock_tag);
    in.data.clear_interlock.failsafe_epoch = 1;
    CHECK_EQ(t_cmd(&d, &in), S(INTERLOCK_ACTIVE));
    fake_clear(&d.hal);
    in = m_simple(11, protoduino_ArduinoIn_clear_interlock_tag);
    in.data.clear_interlock.failsafe_epoch = 2;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK(!fs.active);
    CHECK_EQ(fs.epoch, 2);
    CHECK_EQ(fs.cause, protoduino_FailsafeCause_FAILSAFE_CAUSE_STOP); /* the latest one's */
    in = m_pwm(12, 3, 150);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[3], 150);
    /* It trips again on the next closing. */
    d.hal.level[2] = false;
    poll_at(&d, t + 3);
    CHECK_EQ(d.hal.pwm[3], 0);
}

static void test_interlock_is_told_after_the_report_of_its_edge(void)
{
    /* Issue 32: a host heard of the trip before the report of the press. The trip is in
     * no message before the InputReport carrying the tripped level: not its notice, not
     * the Ack of a Ping whose frame was arriving as it tripped (the report yields to it). */
    tdev_t d;
    t_active(&d);
    uint32_t t = d.hal.now_ms + 500;
    d.hal.level[2] = true;
    protoduino_ArduinoIn in = m_din(1, 2, true, 0, protoduino_Trip_TRIP_LOW);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_stop(2); /* epoch 1: liveness Acks carry the failsafe state from now on */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    const uint8_t echo[1] = {7};
    in = m_ping(3, echo, sizeof(echo));
    in.data.ping.failsafe_epoch = 1;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    poll_at(&d, t);
    fake_clear(&d.hal);

    uint8_t wire[PD_MAX_ENCODED_FRAME + 1];
    in = m_ping(4, echo, sizeof(echo));
    in.data.ping.failsafe_epoch = 1;
    size_t n = t_wire_in(&d, &in, wire);
    t_feed(&d, wire, n - 1u); /* all but its delimiter: a command arriving */
    d.hal.level[2] = false;
    poll_at(&d, t + 1);
    CHECK_EQ(fake_count(&d.hal), 0); /* tripped (latched), told nothing yet */
    t_feed(&d, wire + n - 1u, 1);
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 4, &ack), 1);
    CHECK(ack.has_failsafe);
    CHECK(!ack.failsafe.active); /* the state before the trip */
    CHECK_EQ(ack.failsafe.epoch, 1);
    in = m_simple(5, protoduino_ArduinoIn_clear_interlock_tag);
    in.data.clear_interlock.failsafe_epoch = 1;
    d.hal.level[2] = true; /* even released at once: the host was not told of the trip */
    fake_clear(&d.hal);
    t_send_in(&d, &in);
    CHECK_EQ(t_status(&d, 5), S(INTERLOCK_ACTIVE));
    d.hal.level[2] = false;
    fake_clear(&d.hal);
    poll_at(&d, t + 1); /* the report, then right behind it the notice */
    protoduino_ArduinoOut out;
    CHECK_EQ(fake_count(&d.hal), 2);
    CHECK(t_out(&d, 0, &out));
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_input_report_tag);
    CHECK_EQ(T_MASK(out.data.input_report.digital_pins), 1u << 2);
    CHECK_EQ(T_MASK(out.data.input_report.digital_levels), 0);
    CHECK(t_out(&d, 1, &out));
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_failsafe_tag);
    CHECK(out.data.failsafe.active);
    CHECK_EQ(out.data.failsafe.cause, protoduino_FailsafeCause_FAILSAFE_CAUSE_INTERLOCK);
    CHECK_EQ(out.data.failsafe.epoch, 2);
    CHECK_EQ(out.data.failsafe.pin, 2);
}

static void test_interlock_configured_while_tripped_trips_after_its_ack(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_pwm_init(1, 11, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm(2, 11, 180);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    d.hal.level[6] = false; /* the bumper is pressed already */
    fake_clear(&d.hal);
    in = m_din(3, 6, true, 50, protoduino_Trip_TRIP_LOW);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[11], 180); /* the Init itself drives nothing */
    poll_at(&d, d.hal.now_ms);    /* the next pass, no debounce wait */
    CHECK_EQ(d.hal.pwm[11], 0);
    protoduino_Failsafe fs;
    CHECK_EQ(t_failsafes(&d, &fs), 1);
    CHECK_EQ(fs.cause, protoduino_FailsafeCause_FAILSAFE_CAUSE_INTERLOCK);
    protoduino_ArduinoOut out;
    CHECK(t_out(&d, 0, &out)); /* the Init's Ack went first */
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_ack_tag);
    protoduino_InputReport r;
    CHECK_EQ(reports(&d, &r), 1);
    CHECK_EQ(T_MASK(r.digital_levels) & (1u << 6), 0); /* the level it reads */
    in = m_pwm(4, 11, 180);
    CHECK_EQ(t_cmd(&d, &in), S(INTERLOCK_ACTIVE));
}

static void test_interlock_with_no_host_connected(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_din(1, 8, false, 0, protoduino_Trip_TRIP_HIGH);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm_init(2, 11, 10);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm(3, 11, 255);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    d.core.link.active = false; /* the host is gone (IDLE) */
    d.hal.level[8] = true;
    poll_at(&d, d.hal.now_ms + 1);
    CHECK_EQ(d.hal.pwm[11], 10); /* acts on its own */
}

static void test_analog_first_value_threshold_heartbeat(void)
{
    tdev_t d;
    t_active(&d);
    uint32_t t = d.hal.now_ms + 2000;
    d.hal.now_ms = t;
    d.hal.analog[14] = 500;
    protoduino_ArduinoIn in = m_ain(1, 14, 10, 8, 100);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    poll_at(&d, t);
    protoduino_InputReport r;
    CHECK_EQ(reports(&d, &r), 1); /* the first sample, right after the Ack */
    CHECK_EQ(T_MASK(r.analog_pins), 1u << 14);
    CHECK_EQ(r.analog_values_count, 1);
    CHECK_EQ(r.analog_values[0], 500);
    fake_clear(&d.hal);
    /* Within the threshold: quiet until the heartbeat (100 ms = 10 periods). */
    d.hal.analog[14] = 508;
    for (uint32_t ms = 1; ms < 100; ms++) {
        poll_at(&d, t + ms);
    }
    CHECK_EQ(reports(&d, NULL), 0);
    poll_at(&d, t + 100);
    CHECK_EQ(reports(&d, &r), 1);
    CHECK_EQ(r.analog_values[0], 508);
    fake_clear(&d.hal);
    /* Past the threshold (from what was sent): at the next sample. */
    d.hal.analog[14] = 517;
    poll_at(&d, t + 109);
    CHECK_EQ(reports(&d, NULL), 0);
    poll_at(&d, t + 110);
    CHECK_EQ(reports(&d, &r), 1);
    CHECK_EQ(r.analog_values[0], 517);
    CHECK_EQ(T_MASK(r.digital_pins), 0);
    /* Not an analog pin / bad arguments. */
    in = m_ain(2, 2, 10, 8, 100);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_SUPPORTED));
    in = m_ain(3, 15, 60001, 8, 100);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
    in = m_ain(4, 15, 10, 1024, 100);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
    in = m_ain(5, 25, 10, 1024, 100);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_PIN));
}

static void test_six_analog_inputs_share_a_slow_converter(void)
{
    tdev_t d;
    t_active(&d);
    d.hal.adc_polls = 3; /* each conversion takes three passes */
    uint32_t t = d.hal.now_ms + 3000;
    d.hal.now_ms = t;
    for (uint8_t pin = 14; pin < 20; pin++) {
        d.hal.analog[pin] = (uint16_t)(100 * (pin - 13));
        protoduino_ArduinoIn in = m_ain(pin, pin, 1, 0, 1000); /* every ms: more than it can do */
        CHECK_EQ(t_cmd(&d, &in), S(OK));
    }
    fake_clear(&d.hal);
    unsigned before = d.hal.conversions;
    for (uint32_t pass = 0; pass < 120; pass++) {
        poll_at(&d, t + pass / 4u); /* four passes a millisecond */
    }
    /* Every input sampled alike (round-robin): none starves. */
    CHECK(d.hal.conversions - before >= 38u);
    protoduino_InputReport r;
    int n = reports(&d, &r);
    CHECK(n >= 1);
    /* The first round went out whole: all six in one report. */
    protoduino_ArduinoOut out;
    for (size_t i = 0; i < fake_count(&d.hal); i++) {
        if (t_out(&d, i, &out) && out.which_data == protoduino_ArduinoOut_input_report_tag) {
            CHECK_EQ(T_MASK(out.data.input_report.analog_pins), 0x3Fu << 14);
            CHECK_EQ(out.data.input_report.analog_values_count, 6);
            CHECK_EQ(out.data.input_report.analog_values[5], 600);
            break;
        }
    }
}

static void test_counter_reports_at_most_each_interval(void)
{
    tdev_t d;
    t_active(&d);
    uint32_t t = d.hal.now_ms + 4000;
    d.hal.now_ms = t;
    protoduino_ArduinoIn in = m_counter(1, 3, protoduino_Edge_EDGE_FALLING, 20);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.counter_edge[3], protoduino_Edge_EDGE_FALLING);
    poll_at(&d, t);
    protoduino_InputReport r;
    CHECK_EQ(reports(&d, &r), 1); /* its 0, after the Ack */
    CHECK_EQ(T_MASK(r.counter_pins), 1u << 3);
    CHECK_EQ(r.counter_counts[0], 0);
    fake_clear(&d.hal);
    d.hal.count[3] = 5;
    poll_at(&d, t + 1);
    CHECK_EQ(reports(&d, NULL), 0); /* 20 ms since the last report of it: not yet */
    d.hal.count[3] = 9;
    poll_at(&d, t + 20);
    CHECK_EQ(reports(&d, &r), 1);
    CHECK_EQ(r.counter_counts[0], 9); /* the newest count */
    poll_at(&d, t + 60);
    CHECK_EQ(reports(&d, NULL), 1); /* unchanged: nothing */
    in = m_counter(2, 14, protoduino_Edge_EDGE_RISING, 20);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_SUPPORTED)); /* counters on the digital pins 2..13 */
    /* Released: the counting stops, the pin is free. */
    protoduino_ArduinoIn rel = m_simple(3, protoduino_ArduinoIn_release_tag);
    rel.data.release.pin = 3;
    CHECK_EQ(t_cmd(&d, &rel), S(OK));
    CHECK_EQ(d.hal.counter_edge[3], -1);
    CHECK_EQ(d.hal.input[3], -1);
    in = m_pwm_init(4, 3, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
}

static void test_reports_coalesce_while_the_line_is_full(void)
{
    tdev_t d;
    t_active(&d);
    uint32_t t = d.hal.now_ms + 6000;
    d.hal.now_ms = t;
    protoduino_ArduinoIn in = m_din(1, 5, false, 0, protoduino_Trip_TRIP_NONE);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    poll_at(&d, t);
    fake_clear(&d.hal);
    d.hal.tx_room = 10; /* too little for a report */
    for (uint32_t ms = 1; ms <= 4; ms++) {
        d.hal.level[5] = (ms & 1u) != 0;
        poll_at(&d, t + ms);
    }
    CHECK_EQ(reports(&d, NULL), 0);
    d.hal.tx_room = UINT16_MAX;
    poll_at(&d, t + 5);
    protoduino_InputReport r;
    CHECK_EQ(reports(&d, &r), 1);
    CHECK_EQ(T_MASK(r.digital_levels) & (1u << 5), 0); /* the newest level */
    CHECK_EQ(r.coalesced, 3);                  /* four changes, one report */
    CHECK_EQ(r.time_ms, t + 4);                /* when it was taken, not when it left */
    d.hal.level[5] = true;
    poll_at(&d, t + 6);
    CHECK_EQ(reports(&d, &r), 2);
    CHECK_EQ(r.coalesced, 0);
}

static void test_input_pins_in_the_registry(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_din(1, 9, false, 0, protoduino_Trip_TRIP_NONE);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm_init(2, 9, 0);
    CHECK_EQ(t_cmd(&d, &in), S(PIN_IN_USE));
    in = m_din(3, 1, false, 0, protoduino_Trip_TRIP_NONE);
    CHECK_EQ(t_cmd(&d, &in), S(RESERVED_PIN));
    in = m_din(4, 9, true, 5, protoduino_Trip_TRIP_NONE); /* reconfigured in place */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.input[9], 1);
    in = m_ain(5, 15, 10, 0, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    protoduino_ArduinoIn all = m_simple(6, protoduino_ArduinoIn_release_all_tag);
    CHECK_EQ(t_cmd(&d, &all), S(OK));
    CHECK_EQ(d.hal.input[9], -1);
    CHECK_EQ(d.hal.input[15], -1);
    /* Nine digital inputs: the ninth has no slot. */
    uint8_t pins[9] = {2, 3, 4, 5, 6, 7, 8, 9, 10};
    for (int i = 0; i < 9; i++) {
        in = m_din((uint32_t)(10 + i), pins[i], false, 0, protoduino_Trip_TRIP_NONE);
        CHECK_EQ(t_cmd(&d, &in), i < 8 ? S(OK) : S(NO_FREE_RESOURCE));
    }
}

const pd_test_case_t pd_tests_inputs[] = {
    TEST_CASE(test_digital_input_level_reported_after_its_ack),
    TEST_CASE(test_digital_debounce),
    TEST_CASE(test_interlock_trips_latches_and_clears),
    TEST_CASE(test_interlock_is_told_after_the_report_of_its_edge),
    TEST_CASE(test_interlock_configured_while_tripped_trips_after_its_ack),
    TEST_CASE(test_interlock_with_no_host_connected),
    TEST_CASE(test_analog_first_value_threshold_heartbeat),
    TEST_CASE(test_six_analog_inputs_share_a_slow_converter),
    TEST_CASE(test_counter_reports_at_most_each_interval),
    TEST_CASE(test_reports_coalesce_while_the_line_is_full),
    TEST_CASE(test_input_pins_in_the_registry),
    {NULL, NULL},
};

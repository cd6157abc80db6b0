/* Issue 21 on the device: PWM outputs (pins, timers, safe duty, Pose, ReadOutputs) and DeviceInfo's
 * pin capabilities and features. The fake board has the Uno's masks (fake_hal.c). */
#include <string.h>

#include "pd_encode.h"
#include "pd_test.h"
#include "test_util.h"

#define S(name) protoduino_Status_STATUS_##name

static protoduino_ArduinoIn m_pwm_init(uint32_t id, uint32_t pin, uint32_t safe)
{
    protoduino_ArduinoIn in = protoduino_ArduinoIn_init_zero;
    in.message_id = id;
    in.which_data = protoduino_ArduinoIn_pwm_init_tag;
    in.data.pwm_init.pin = (uint8_t)pin;
    in.data.pwm_init.safe_duty = (uint16_t)safe;
    return in;
}

static protoduino_ArduinoIn m_pwm(uint32_t id, uint32_t pin, uint32_t duty)
{
    protoduino_ArduinoIn in = protoduino_ArduinoIn_init_zero;
    in.message_id = id;
    in.which_data = protoduino_ArduinoIn_pwm_control_tag;
    in.data.pwm_control.pin = (uint8_t)pin;
    in.data.pwm_control.duty = (uint16_t)duty;
    return in;
}

static void test_pwm_init_drives_safe_duty_and_control_sets_duty(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_pwm_init(1, 3, 20);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[3], 20);
    in = m_pwm(2, 3, 200);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[3], 200);
    /* The same Init again: no glitch through the safe duty. */
    unsigned writes = d.hal.pwm_writes[3];
    in = m_pwm_init(3, 3, 20);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm_writes[3], writes);
    CHECK_EQ(d.hal.pwm[3], 200);
    /* Another safe duty: driven at once. */
    in = m_pwm_init(4, 3, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[3], 0);
}

static void test_pwm_refusals(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_pwm_init(1, 4, 0); /* no timer output on pin 4 */
    CHECK_EQ(t_cmd(&d, &in), S(NOT_SUPPORTED));
    /* Timer0's pins do PWM (its overflow keeps the clock, as Arduino's wiring.c does it). */
    in = m_pwm_init(2, 5, 7);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[5], 7);
    in = m_pwm_init(3, 6, 9);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[6], 9);
    in = m_pwm_init(4, 20, 0);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_PIN));
    in = m_pwm_init(5, 1, 0);
    CHECK_EQ(t_cmd(&d, &in), S(RESERVED_PIN));
    in = m_pwm_init(6, 11, 256);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    CHECK_EQ(d.hal.pwm[11], -1);
    in = m_pwm(7, 11, 10);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_INITIALISED));
    in = m_pwm_init(8, 11, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm(9, 11, 256);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    CHECK_EQ(d.hal.pwm[11], 0);
    in = m_digital_init(10, 11, false);
    CHECK_EQ(t_cmd(&d, &in), S(PIN_IN_USE));
    in = m_digital_init(11, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm_init(12, 13, 0); /* 13 has no PWM: the capability comes first */
    CHECK_EQ(t_cmd(&d, &in), S(NOT_SUPPORTED));
}

static void test_servo_timer_shared_with_pins_9_and_10(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_deg(1, 2, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm_init(2, 9, 0); /* a servo runs: Timer1 is the servos' */
    CHECK_EQ(t_cmd(&d, &in), S(TIMER_IN_USE));
    in = m_pwm_init(3, 3, 0); /* Timer2 is free */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    protoduino_ArduinoIn rel = protoduino_ArduinoIn_init_zero;
    rel.message_id = 4;
    rel.which_data = protoduino_ArduinoIn_release_tag;
    rel.data.release.pin = 2;
    CHECK_EQ(t_cmd(&d, &rel), S(OK));
    in = m_pwm_init(5, 10, 0); /* no servo left */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_init_deg(6, 4, 0, 0, 90); /* and now no servo while 10 does PWM */
    CHECK_EQ(t_cmd(&d, &in), S(TIMER_IN_USE));
    CHECK_EQ(d.hal.servo_us[4], -1);
    rel.message_id = 7;
    rel.data.release.pin = 10;
    CHECK_EQ(t_cmd(&d, &rel), S(OK));
    CHECK_EQ(d.hal.pwm[10], -1);
    in = m_servo_init_deg(8, 4, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
}

static void test_pwm_safe_duty_on_stop_and_failsafe(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_pwm_init(1, 3, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm_init(2, 11, 40);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm(3, 3, 255);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm(4, 11, 128);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_stop(5);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[3], 0);
    CHECK_EQ(d.hal.pwm[11], 40);
    /* The failsafe timer (default 10 s) runs out: safe again after a new duty. */
    in = m_pwm(6, 3, 99);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    d.hal.now_ms += PD_FAILSAFE_TIMEOUT_MS + 1u;
    pd_core_poll(&d.core);
    CHECK_EQ(d.hal.pwm[3], 0);
    in = m_pwm(7, 3, 99); /* no liveness since: refused */
    CHECK_EQ(t_cmd(&d, &in), S(FAILSAFE_EXPIRED));
    CHECK_EQ(d.hal.pwm[3], 0);
}

static void test_pwm_in_pose_and_read_outputs(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_pwm_init(1, 11, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm_init(2, 3, 7);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital_init(3, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    memset(&in, 0, sizeof(in));
    in.message_id = 4;
    in.which_data = protoduino_ArduinoIn_pose_tag;
    in.data.pose.items_count = 3;
    in.data.pose.items[0].which_output = protoduino_PoseItem_pwm_tag;
    in.data.pose.items[0].output.pwm.pin = 11;
    in.data.pose.items[0].output.pwm.duty = 77;
    in.data.pose.items[1].which_output = protoduino_PoseItem_digital_tag;
    in.data.pose.items[1].output.digital.pin = 13;
    in.data.pose.items[1].output.digital.level = true;
    in.data.pose.items[2].which_output = protoduino_PoseItem_pwm_tag;
    in.data.pose.items[2].output.pwm.pin = 3;
    in.data.pose.items[2].output.pwm.duty = 300; /* refused: nothing applied */
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 4, &ack), 1);
    CHECK_EQ(ack.refused_item, 3);
    CHECK_EQ(d.hal.pwm[11], 0);
    CHECK_EQ(d.hal.digital[13], 0);
    in.message_id = 5;
    in.data.pose.items[2].output.pwm.duty = 250;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[11], 77);
    CHECK_EQ(d.hal.pwm[3], 250);
    CHECK_EQ(d.hal.digital[13], 1);

    memset(&in, 0, sizeof(in));
    in.message_id = 6;
    in.which_data = protoduino_ArduinoIn_read_outputs_tag;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(t_acks(&d, 6, &ack), 1);
    CHECK_EQ(ack.which_result, protoduino_Ack_outputs_tag);
    CHECK_EQ(T_MASK(ack.result.outputs.pwm_pins), (1u << 3) | (1u << 11));
    CHECK_EQ(ack.result.outputs.pwm_duties_count, 2);
    CHECK_EQ(ack.result.outputs.pwm_duties[0], 250); /* pin order: 3, then 11 */
    CHECK_EQ(ack.result.outputs.pwm_duties[1], 77);
    CHECK_EQ(T_MASK(ack.result.outputs.digital_pins), 1u << 13);
}

/* Issue 32: an H-bridge's PWM and direction pins in one Pose, in any order: the duties of
 * 0 first, then every level (the items', then the masks'), then the other duties, so that
 * a motor stops before its direction pin changes and starts only after it changed. */
static void test_pose_stops_then_sets_levels_then_drives(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_pwm_init(1, 3, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm_init(2, 11, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_pwm(3, 11, 100);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital_init(4, 4, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital_init(5, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    memset(&in, 0, sizeof(in));
    in.message_id = 6;
    in.which_data = protoduino_ArduinoIn_pose_tag;
    in.data.pose.items_count = 3;
    in.data.pose.items[0].which_output = protoduino_PoseItem_pwm_tag;
    in.data.pose.items[0].output.pwm.pin = 3; /* starts */
    in.data.pose.items[0].output.pwm.duty = 150;
    in.data.pose.items[1].which_output = protoduino_PoseItem_digital_tag;
    in.data.pose.items[1].output.digital.pin = 13;
    in.data.pose.items[1].output.digital.level = true;
    in.data.pose.items[2].which_output = protoduino_PoseItem_pwm_tag;
    in.data.pose.items[2].output.pwm.pin = 11; /* stops */
    in.data.pose.items[2].output.pwm.duty = 0;
    T_PUT_MASK(in.data.pose.digital_pins, 1u << 4);
    T_PUT_MASK(in.data.pose.digital_levels, 1u << 4);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.pwm[3], 150);
    CHECK_EQ(d.hal.pwm[11], 0);
    CHECK_EQ(d.hal.digital[13], 1);
    CHECK_EQ(d.hal.digital[4], 1);
    CHECK(d.hal.written_at[11] < d.hal.written_at[13]);
    CHECK(d.hal.written_at[13] < d.hal.written_at[4]);
    CHECK(d.hal.written_at[4] < d.hal.written_at[3]);
}

static void test_device_info_lists_capabilities_and_features(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_info(1);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 1, &ack), 1);
    const protoduino_DeviceInfo *info = &ack.result.info;
    CHECK_EQ(info->features, PD_FEATURES);
    CHECK((info->features >> protoduino_Feature_FEATURE_PWM) & 1u);
    CHECK((info->features >> protoduino_Feature_FEATURE_SERVO) & 1u);
    /* The pin table (DeviceInfo.pins, timers), from the board's (fake_hal.c: the
     * Uno's): UART 0, 1 nothing; counters on 2..13 (INT0, INT1 on 2, 3; pin-change
     * interrupts on 4..13); PWM on 3, 11 (a free timer), 5, 6 (Timer0, which keeps
     * the clock in the same mode) and 9, 10 (Timer1, the servos'); A0..A5 analog.
     * Then the timers it holds: Timer1 the servos'. */
    const fake_frame_t *f = &d.hal.frames[(d.hal.n_frames - 1u) % FAKE_MAX_FRAMES];
    const uint8_t table[] = {
        0x72, 20, 0x00, 0x00, 0x09, 0x0B, 0x19, 0x1B, 0x1B, 0x19, 0x19, 0x5B, 0x5B, 0x1B,
        0x19, 0x19, 0x05, 0x05, 0x05, 0x05, 0x05, 0x05, 0x7A, 2, 0x00, 0x02};
    CHECK(f->len >= sizeof(table));
    CHECK(memcmp(f->payload + f->len - sizeof(table), table, sizeof(table)) == 0);
    /* A board with other pins says so, from its table alone. */
    d.hal.info.pwm_pins = T_SET(1u << 4);
    d.hal.info.servo_timer_pins = T_SET(0);
    d.hal.info.counter_pins = T_SET(0);
    d.hal.info.pin_change_pins = T_SET(0);
    d.hal.info.clock_timer_pins = T_SET(1u << 4);
    d.hal.info.clock_timer = 2;
    CHECK_EQ(pd_encode_pin(&d.hal.info, 4), 0x01 | 0x02 | (3u << 5));
    CHECK_EQ(pd_encode_pin(&d.hal.info, 9), 0x01);
    CHECK_EQ(pd_encode_timer_count(&d.hal.info), 3);
    CHECK_EQ(pd_encode_timer(&d.hal.info, 0), protoduino_TimerUse_TIMER_FREE);
    CHECK_EQ(pd_encode_timer(&d.hal.info, 2), protoduino_TimerUse_TIMER_CLOCK);
    in = m_info(2);
    CHECK_EQ(t_cmd(&d, &in), S(OK)); /* fake_hal checks it against pb_encode's */
}

const pd_test_case_t pd_tests_pwm[] = {
    TEST_CASE(test_pwm_init_drives_safe_duty_and_control_sets_duty),
    TEST_CASE(test_pwm_refusals),
    TEST_CASE(test_servo_timer_shared_with_pins_9_and_10),
    TEST_CASE(test_pwm_safe_duty_on_stop_and_failsafe),
    TEST_CASE(test_pwm_in_pose_and_read_outputs),
    TEST_CASE(test_pose_stops_then_sets_levels_then_drives),
    TEST_CASE(test_device_info_lists_capabilities_and_features),
    {NULL, NULL},
};

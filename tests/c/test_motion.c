/* Issue 13 on the device: Pose (all or nothing, one frame), ReadOutputs, servo speed limits. */
#include <string.h>

#include "pd_test.h"
#include "test_util.h"

#define S(name) protoduino_Status_STATUS_##name

static protoduino_PoseItem servo_item(uint32_t pin, uint32_t degrees)
{
    protoduino_PoseItem item = protoduino_PoseItem_init_zero;
    item.which_output = protoduino_PoseItem_servo_tag;
    item.output.servo.pin = pin;
    item.output.servo.which_value = protoduino_ServoControl_degrees_tag;
    item.output.servo.value.degrees = degrees;
    return item;
}

static protoduino_PoseItem digital_item(uint32_t pin, bool level)
{
    protoduino_PoseItem item = protoduino_PoseItem_init_zero;
    item.which_output = protoduino_PoseItem_digital_tag;
    item.output.digital.pin = pin;
    item.output.digital.level = level;
    return item;
}

static protoduino_ArduinoIn m_pose(uint32_t id, const protoduino_PoseItem *items, size_t n)
{
    protoduino_ArduinoIn in = protoduino_ArduinoIn_init_zero;
    in.message_id = id;
    in.which_data = protoduino_ArduinoIn_pose_tag;
    in.data.pose.items_count = (pb_size_t)n;
    if (n > 0) {
        memcpy(in.data.pose.items, items, n * sizeof(*items));
    }
    return in;
}

static protoduino_ArduinoIn m_servo_init_speed(uint32_t id, uint32_t pin, uint32_t safe_us,
                                               uint32_t max_speed)
{
    protoduino_ArduinoIn in = m_servo_init_us(id, pin, 0, 0, safe_us);
    in.data.servo_init.max_speed = max_speed;
    return in;
}

/* An arm: servos on 3, 5, 6 (default limits, safe 90) and a digital output on 13. */
static void arm(tdev_t *d)
{
    t_active(d);
    uint32_t pins[] = {3, 5, 6};
    for (uint32_t i = 0; i < 3; i++) {
        protoduino_ArduinoIn in = m_servo_init_deg(100 + i, pins[i], 0, 0, 90);
        CHECK_EQ(t_cmd(d, &in), S(OK));
    }
    protoduino_ArduinoIn in = m_digital_init(110, 13, false);
    CHECK_EQ(t_cmd(d, &in), S(OK));
}

#define US(deg) (544 + (deg) * (2400 - 544) / 180)

static void test_pose_applies_every_item_held(void)
{
    tdev_t d;
    arm(&d);
    unsigned holds = d.hal.servo_holds;
    protoduino_PoseItem items[] = {servo_item(3, 10), servo_item(5, 20), digital_item(13, true),
                                   servo_item(6, 30)};
    protoduino_ArduinoIn in = m_pose(1, items, 4);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[3], US(10));
    CHECK_EQ(d.hal.servo_us[5], US(20));
    CHECK_EQ(d.hal.servo_us[6], US(30));
    CHECK_EQ(d.hal.digital[13], 1);
    CHECK_EQ(d.hal.servo_holds, holds + 1); /* all in one hold */
    CHECK(!d.hal.servo_held);
}

static void test_pose_all_or_nothing(void)
{
    tdev_t d;
    arm(&d);
    struct {
        protoduino_PoseItem bad;
        int status;
    } cases[] = {
        {servo_item(6, 181), S(OUT_OF_RANGE)},
        {servo_item(9, 10), S(NOT_INITIALISED)},
        {servo_item(13, 10), S(NOT_INITIALISED)}, /* a digital pin given a servo value */
        {digital_item(6, true), S(NOT_INITIALISED)},
        {servo_item(20, 10), S(INVALID_PIN)},
        {digital_item(1, true), S(RESERVED_PIN)},
        {servo_item(3, 50), S(INVALID_ARGUMENT)}, /* pin 3 twice */
        {protoduino_PoseItem_init_zero, S(INVALID_ARGUMENT)}, /* no output */
    };
    for (size_t c = 0; c < sizeof(cases) / sizeof(cases[0]); c++) {
        protoduino_PoseItem items[] = {servo_item(3, 10), digital_item(13, true), cases[c].bad,
                                       servo_item(5, 20)};
        uint32_t id = (uint32_t)(10 + c);
        protoduino_ArduinoIn in = m_pose(id, items, 4);
        unsigned writes3 = d.hal.servo_writes[3];
        unsigned writes13 = d.hal.digital_writes[13];
        CHECK_EQ(t_cmd(&d, &in), cases[c].status);
        protoduino_Ack ack;
        CHECK_EQ(t_acks(&d, id, &ack), 1);
        CHECK_EQ(ack.refused_item, 3); /* the third item, counted from 1 */
        /* Nothing was applied, not even the valid items before the bad one. */
        CHECK_EQ(d.hal.servo_writes[3], writes3);
        CHECK_EQ(d.hal.digital_writes[13], writes13);
        CHECK_EQ(d.hal.servo_us[3], US(90));
        CHECK_EQ(d.hal.digital[13], 0);
        CHECK(!d.hal.servo_held);
    }
    protoduino_ArduinoIn empty = m_pose(50, NULL, 0);
    CHECK_EQ(t_cmd(&d, &empty), S(INVALID_ARGUMENT));
}

/* A Pose with `n` items and the digital masks (protocol version 6). */
static protoduino_ArduinoIn m_pose_masks(uint32_t id, const protoduino_PoseItem *items, size_t n,
                                         uint32_t pins, uint32_t levels)
{
    protoduino_ArduinoIn in = m_pose(id, items, n);
    T_PUT_MASK(in.data.pose.digital_pins, pins);
    T_PUT_MASK(in.data.pose.digital_levels, levels);
    return in;
}

#define BIT(p) (1UL << (p))

/* The arm, and digital outputs on 2, 4, 7, 8 (safe low); 12 stays unconfigured. */
static void arm_leds(tdev_t *d)
{
    arm(d);
    uint32_t pins[] = {2, 4, 7, 8};
    for (uint32_t i = 0; i < 4; i++) {
        protoduino_ArduinoIn in = m_digital_init(120 + i, pins[i], false);
        CHECK_EQ(t_cmd(d, &in), S(OK));
    }
}

/* The masks set every pin they name, in ascending pin order, in the servos' one hold,
 * before the servos (levels before duties and widths); pins outside digital_pins are
 * untouched. */
static void test_pose_masks_apply_before_the_servos(void)
{
    tdev_t d;
    arm_leds(&d);
    unsigned holds = d.hal.servo_holds;
    unsigned writes2 = d.hal.digital_writes[2];
    protoduino_PoseItem items[] = {servo_item(6, 30), servo_item(3, 10)};
    protoduino_ArduinoIn in =
        m_pose_masks(1, items, 2, BIT(13) | BIT(8) | BIT(7) | BIT(4), BIT(13) | BIT(7));
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[6], US(30));
    CHECK_EQ(d.hal.servo_us[3], US(10));
    CHECK_EQ(d.hal.digital[4], 0);
    CHECK_EQ(d.hal.digital[7], 1);
    CHECK_EQ(d.hal.digital[8], 0);
    CHECK_EQ(d.hal.digital[13], 1);
    CHECK_EQ(d.hal.digital_writes[2], writes2); /* not in the mask */
    CHECK_EQ(d.hal.servo_holds, holds + 1);
    CHECK(!d.hal.servo_held);
    /* The order: the mask's pins upwards, then the servo items as listed. */
    CHECK(d.hal.written_at[4] < d.hal.written_at[7]);
    CHECK(d.hal.written_at[7] < d.hal.written_at[8]);
    CHECK(d.hal.written_at[8] < d.hal.written_at[13]);
    CHECK(d.hal.written_at[13] < d.hal.written_at[6]);
    CHECK(d.hal.written_at[6] < d.hal.written_at[3]);

    /* A Pose of masks alone; a digital item beside them still counts as before. */
    in = m_pose_masks(2, NULL, 0, BIT(2) | BIT(13), BIT(2));
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[2], 1);
    CHECK_EQ(d.hal.digital[13], 0);
    protoduino_PoseItem digital[] = {digital_item(8, true)};
    in = m_pose_masks(3, digital, 1, BIT(4), BIT(4));
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[8], 1);
    CHECK_EQ(d.hal.digital[4], 1);
}

/* Every refusal of a Pose with masks: its status, refused_item (the items counted from 1,
 * then the mask's pins upwards, counted on; 0 for a level outside the mask) and nothing
 * applied, neither the items nor the mask's pins below the refused one. */
static void test_pose_masks_all_or_nothing(void)
{
    tdev_t d;
    arm_leds(&d);
    protoduino_PoseItem two[] = {servo_item(3, 10), servo_item(5, 20)};
    protoduino_PoseItem with13[] = {servo_item(3, 10), digital_item(13, true)};
    protoduino_PoseItem bad_item[] = {servo_item(3, 10), servo_item(5, 181)};
    const uint32_t four = BIT(2) | BIT(4) | BIT(7) | BIT(8);
    struct {
        const protoduino_PoseItem *items;
        size_t n;
        uint32_t pins, levels;
        int status;
        uint32_t refused;
    } cases[] = {
        /* the 5th mask pin, 12, is not a digital output: item 2 + 5 */
        {two, 2, four | BIT(12), four, S(NOT_INITIALISED), 7},
        /* a servo's pin in the mask: its DigitalControl's status first */
        {two, 2, four | BIT(5), four, S(NOT_INITIALISED), 5},
        /* a pin both an item and in the mask */
        {with13, 2, four | BIT(13), four, S(INVALID_ARGUMENT), 7},
        {two, 2, four | BIT(1), four, S(RESERVED_PIN), 3}, /* pin 1 first */
        {two, 2, four | BIT(20), four, S(INVALID_PIN), 7},
        {two, 2, four | BIT(31), four, S(INVALID_PIN), 7},
        /* a level outside the mask: no output named */
        {two, 2, four, four | BIT(13), S(INVALID_ARGUMENT), 0},
        {NULL, 0, four, BIT(12), S(INVALID_ARGUMENT), 0},
        /* an item's refusal comes before the mask's */
        {bad_item, 2, four | BIT(12), four, S(OUT_OF_RANGE), 2},
        /* nothing to set: refused as an empty Pose always was */
        {NULL, 0, 0, 0, S(INVALID_ARGUMENT), 1},
        {NULL, 0, 0, BIT(4), S(INVALID_ARGUMENT), 1},
    };
    for (size_t c = 0; c < sizeof(cases) / sizeof(cases[0]); c++) {
        uint32_t id = (uint32_t)(10 + c);
        protoduino_ArduinoIn in =
            m_pose_masks(id, cases[c].items, cases[c].n, cases[c].pins, cases[c].levels);
        unsigned writes = d.hal.writes;
        CHECK_EQ(t_cmd(&d, &in), cases[c].status);
        protoduino_Ack ack;
        CHECK_EQ(t_acks(&d, id, &ack), 1);
        CHECK_EQ(ack.status, cases[c].status);
        CHECK_EQ(ack.refused_item, cases[c].refused);
        CHECK_EQ(d.hal.writes, writes); /* no output written at all */
        CHECK_EQ(d.hal.servo_us[3], US(90));
        CHECK_EQ(d.hal.digital[2], 0);
        CHECK_EQ(d.hal.digital[7], 0);
        CHECK_EQ(d.hal.digital[13], 0);
        CHECK(!d.hal.servo_held);
    }
}

/* Pin sets past a 32-bit mask (protocol version 8: bytes, 9 at most): a pin of byte 4 or 8
 * the board does not have is refused as its DigitalControl (INVALID_PIN, counted on after the
 * set's lower pins); a level there outside the set names no output; zero bytes past the last
 * pin change nothing; more than the schema's 9 bytes never reach the device (nanopb's bound). */
static void test_pose_sets_past_32_pins(void)
{
    tdev_t d;
    arm_leds(&d);
    const uint8_t pins69[9] = {0x94, 0x01, 0, 0, 0, 0, 0, 0, 0x20}; /* 2, 4, 7, 8 and 69 */
    const uint8_t pins32[5] = {0x94, 0x01, 0, 0, 0x01};              /* 2, 4, 7, 8 and 32 */
    const uint8_t low[9] = {0x80, 0, 0, 0, 0, 0, 0, 0, 0};            /* 7, trailing zeros */
    struct {
        const uint8_t *pins;
        pb_size_t pins_size;
        const uint8_t *levels;
        pb_size_t levels_size;
        int status;
        uint32_t refused;
    } cases[] = {
        {pins69, 9, low, 1, S(INVALID_PIN), 5},
        {pins32, 5, low, 9, S(INVALID_PIN), 5},
        {low, 9, pins69, 9, S(INVALID_ARGUMENT), 0}, /* levels for no output */
    };
    for (size_t c = 0; c < sizeof(cases) / sizeof(cases[0]); c++) {
        uint32_t id = (uint32_t)(40 + c);
        protoduino_ArduinoIn in = m_pose(id, NULL, 0);
        memcpy(in.data.pose.digital_pins.bytes, cases[c].pins, cases[c].pins_size);
        in.data.pose.digital_pins.size = cases[c].pins_size;
        memcpy(in.data.pose.digital_levels.bytes, cases[c].levels, cases[c].levels_size);
        in.data.pose.digital_levels.size = cases[c].levels_size;
        unsigned writes = d.hal.writes;
        CHECK_EQ(t_cmd(&d, &in), cases[c].status);
        protoduino_Ack ack;
        CHECK_EQ(t_acks(&d, id, &ack), 1);
        CHECK_EQ(ack.refused_item, cases[c].refused);
        CHECK_EQ(d.hal.writes, writes); /* nothing applied */
    }
    /* 9 bytes whose last 7 are zeros: pin 7 high, the others of the set low. */
    protoduino_ArduinoIn in = m_pose(50, NULL, 0);
    memcpy(in.data.pose.digital_pins.bytes, pins69, 2);
    in.data.pose.digital_pins.size = 9;
    memcpy(in.data.pose.digital_levels.bytes, low, 9);
    in.data.pose.digital_levels.size = 9;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[7], 1);
    CHECK_EQ(d.hal.digital[2], 0);
    CHECK_EQ(d.hal.digital[8], 0);
}

static void test_read_outputs(void)
{
    tdev_t d;
    arm(&d);
    protoduino_ArduinoIn in = m_servo_us(1, 5, 1500);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital(2, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 3;
    in.which_data = protoduino_ArduinoIn_read_outputs_tag;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 3, &ack), 1);
    CHECK_EQ(ack.which_result, protoduino_Ack_outputs_tag);
    const protoduino_OutputStates *st = &ack.result.outputs;
    const fake_servos_t *servos = st->servos.arg;
    CHECK_EQ(servos->size, 15);
    const uint8_t want[15] = {3, US(90) & 0xFF, US(90) >> 8, US(90) & 0xFF, US(90) >> 8,
                              5, 1500 & 0xFF,   1500 >> 8,   1500 & 0xFF,   1500 >> 8,
                              6, US(90) & 0xFF, US(90) >> 8, US(90) & 0xFF, US(90) >> 8};
    CHECK_EQ(memcmp(servos->bytes, want, 15), 0);
    CHECK_EQ(T_MASK(st->digital_pins), 1UL << 13);
    CHECK_EQ(T_MASK(st->digital_levels), 1UL << 13);
    /* Idempotent: a repeat is answered in full, not from the dedupe window. */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(t_acks(&d, 3, &ack), 1); /* t_cmd cleared the log */
    CHECK_EQ(ack.which_result, protoduino_Ack_outputs_tag);
}

static void poll_at(tdev_t *d, uint32_t ms)
{
    d->hal.now_ms = ms;
    pd_core_poll(&d->core);
}

static void test_speed_limit_steps_per_frame(void)
{
    tdev_t d;
    t_active(&d);
    uint32_t t0 = d.hal.now_ms;
    /* 500 us/s: 10 us per 20 ms frame. */
    protoduino_ArduinoIn in = m_servo_init_speed(1, 9, 1500, 500);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 1500); /* an Init jumps to safe */
    in = m_servo_us(2, 9, 1535);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 1500); /* not yet: it moves frame by frame */
    int seen[8];
    for (int f = 0; f < 8; f++) {
        poll_at(&d, t0 + 20u * (uint32_t)(f + 1));
        poll_at(&d, t0 + 20u * (uint32_t)(f + 1) + 7u); /* within the frame: no step */
        seen[f] = d.hal.servo_us[9];
    }
    const int want[8] = {1510, 1520, 1530, 1535, 1535, 1535, 1535, 1535};
    for (int f = 0; f < 8; f++) {
        CHECK_EQ(seen[f], want[f]);
    }
    CHECK_EQ(d.core.outputs.servo[0].target_us, 1535);
    /* Stop (and the failsafe) return it to safe at the same speed. */
    in = m_stop(3);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 1535);
    poll_at(&d, t0 + 200);
    CHECK_EQ(d.hal.servo_us[9], 1525);
    CHECK(!d.hal.servo_held);
}

static void test_a_step_waits_for_the_last_to_reach_the_pins(void)
{
    tdev_t d;
    t_active(&d);
    uint32_t t0 = d.hal.now_ms;
    protoduino_ArduinoIn in = m_servo_init_speed(1, 9, 1500, 500); /* 10 us per frame */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_us(2, 9, 1600);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    poll_at(&d, t0 + 20u);
    CHECK_EQ(d.hal.servo_us[9], 1510);
    /* The HAL's frame has not taken 1510 yet: a step 20 ms on would share its frame. */
    d.hal.servo_pending = true;
    poll_at(&d, t0 + 40u);
    poll_at(&d, t0 + 50u);
    CHECK_EQ(d.hal.servo_us[9], 1510);
    /* Taken: the step goes at once, and the next is 20 ms after it. */
    d.hal.servo_pending = false;
    poll_at(&d, t0 + 50u);
    CHECK_EQ(d.hal.servo_us[9], 1520);
    poll_at(&d, t0 + 69u);
    CHECK_EQ(d.hal.servo_us[9], 1520);
    poll_at(&d, t0 + 70u);
    CHECK_EQ(d.hal.servo_us[9], 1530);
    /* A HAL that never takes it (a timer with no frames) holds a step one frame at most. */
    d.hal.servo_pending = true;
    poll_at(&d, t0 + 109u);
    CHECK_EQ(d.hal.servo_us[9], 1530);
    poll_at(&d, t0 + 110u);
    CHECK_EQ(d.hal.servo_us[9], 1540);
}

static void test_speed_limit_bounds(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_speed(1, 9, 1500, 12751);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
    in = m_servo_init_speed(2, 9, 1500, 12750);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.core.outputs.servo[0].step, 255);
    in = m_servo_init_speed(3, 9, 1500, 1); /* rounds up to 1 us per frame */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.core.outputs.servo[0].step, 1);
    in = m_servo_init_speed(4, 9, 1500, 74); /* (74 + 25) / 50 = 1 */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.core.outputs.servo[0].step, 1);
    in = m_servo_init_speed(5, 9, 1500, 0); /* no limit: values are driven at once */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_us(6, 9, 2000);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 2000);
}

static void test_pose_with_speed_limits_steps_together(void)
{
    tdev_t d;
    t_active(&d);
    uint32_t t0 = d.hal.now_ms;
    protoduino_ArduinoIn in = m_servo_init_speed(1, 3, 1500, 1000); /* 20 us per frame */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_init_speed(2, 5, 1500, 1000);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    protoduino_PoseItem items[2] = {servo_item(3, 0), servo_item(5, 0)};
    items[0].output.servo.which_value = protoduino_ServoControl_us_tag;
    items[0].output.servo.value.us = 1540;
    items[1].output.servo.which_value = protoduino_ServoControl_us_tag;
    items[1].output.servo.value.us = 1460;
    in = m_pose(3, items, 2);
    unsigned holds = d.hal.servo_holds;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    poll_at(&d, t0 + 20);
    CHECK_EQ(d.hal.servo_us[3], 1520);
    CHECK_EQ(d.hal.servo_us[5], 1480);
    poll_at(&d, t0 + 40);
    CHECK_EQ(d.hal.servo_us[3], 1540);
    CHECK_EQ(d.hal.servo_us[5], 1460);
    CHECK_EQ(d.hal.servo_holds, holds + 3); /* the pose, then one hold per step */
}

const pd_test_case_t pd_tests_motion[] = {
    TEST_CASE(test_pose_applies_every_item_held),
    TEST_CASE(test_pose_all_or_nothing),
    TEST_CASE(test_pose_masks_apply_before_the_servos),
    TEST_CASE(test_pose_masks_all_or_nothing),
    TEST_CASE(test_pose_sets_past_32_pins),
    TEST_CASE(test_read_outputs),
    TEST_CASE(test_speed_limit_steps_per_frame),
    TEST_CASE(test_a_step_waits_for_the_last_to_reach_the_pins),
    TEST_CASE(test_speed_limit_bounds),
    TEST_CASE(test_pose_with_speed_limits_steps_together),
    {NULL, NULL},
};

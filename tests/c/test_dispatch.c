/* Dispatch: one Ack per message, every status, the device semantics, the dedupe window. */
#include <stdlib.h>
#include <string.h>

#include <pb_encode.h>

#include "pd_dispatch.h"
#include "pd_encode.h"
#include "pd_schema.h"
#include "pd_test.h"
#include "test_util.h"

#define S(name) protoduino_Status_STATUS_##name

static void test_ack_ok_every_command(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn msgs[] = {
        m_ping(1, NULL, 0),          m_info(2),          m_servo_init_deg(3, 9, 0, 0, 90),
        m_servo_deg(4, 9, 45),       m_servo_us(5, 9, 1500), m_digital_init(6, 13, false),
        m_digital(7, 13, true),      m_stop(8),
    };
    for (size_t i = 0; i < sizeof(msgs) / sizeof(msgs[0]); i++) {
        CHECK_EQ(t_cmd(&d, &msgs[i]), S(OK));
    }
}

static void test_servo_init_defaults_and_safe_at_once(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_deg(1, 9, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 544 + 90 * (2400 - 544) / 180); /* 1472 */
    CHECK_EQ(d.core.outputs.servo[0].min_us, 544);
    CHECK_EQ(d.core.outputs.servo[0].max_us, 2400);
    in = m_servo_init_us(2, 10, 1000, 2000, 1234);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[10], 1234);
}

static void test_degrees_to_us(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_deg(1, 9, 1000, 2000, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 1000);
    const uint32_t deg[] = {0, 1, 45, 90, 179, 180};
    for (size_t i = 0; i < sizeof(deg) / sizeof(deg[0]); i++) {
        in = m_servo_deg((uint32_t)(10 + i), 9, deg[i]);
        CHECK_EQ(t_cmd(&d, &in), S(OK));
        CHECK_EQ(d.hal.servo_us[9], 1000 + deg[i] * 1000 / 180);
    }
}

static void test_div180_exact_below_180_squared(void)
{
    for (uint32_t x = 0; x < 180u * 180u; x++) {
        CHECK_EQ(pd_div180((uint16_t)x), x / 180u);
    }
}

/* Every degree over the ranges where the 16-bit split (range = 180 q + r) changes shape. */
static void test_degrees_to_us_every_degree(void)
{
    const uint32_t mins[] = {PD_SERVO_LIMIT_MIN_US, 544, 1000};
    const uint32_t ranges[] = {1, 179, 180, 181, 359, 360, 1000, 1799, 1856, 2199};
    uint32_t id = 1;
    for (size_t m = 0; m < sizeof(mins) / sizeof(mins[0]); m++) {
        for (size_t k = 0; k < sizeof(ranges) / sizeof(ranges[0]); k++) {
            uint32_t lo = mins[m];
            uint32_t hi = lo + ranges[k];
            if (hi > PD_SERVO_LIMIT_MAX_US) {
                continue;
            }
            tdev_t d;
            t_active(&d);
            protoduino_ArduinoIn in = m_servo_init_deg(T_ID(id++), 9, lo, hi, 0);
            CHECK_EQ(t_cmd(&d, &in), S(OK));
            for (uint32_t deg = 0; deg <= 180; deg++) {
                in = m_servo_deg(T_ID(id++), 9, deg);
                CHECK_EQ(t_cmd(&d, &in), S(OK));
                CHECK_EQ(d.hal.servo_us[9], lo + deg * (hi - lo) / 180u);
            }
        }
    }
}

static void test_invalid_pin(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn msgs[] = {
        m_servo_init_deg(1, 20, 0, 0, 90), m_servo_deg(2, 20, 0), m_digital_init(3, 20, 0),
        m_digital(4, 99, 1),               m_digital(5, 0xFFFFFFFFu, 1),
    };
    for (size_t i = 0; i < sizeof(msgs) / sizeof(msgs[0]); i++) {
        CHECK_EQ(t_cmd(&d, &msgs[i]), S(INVALID_PIN));
    }
    /* The pin check comes first: an invalid pin with bad arguments is still INVALID_PIN. */
    protoduino_ArduinoIn in = m_servo_init_deg(6, 25, 100, 9000, 999);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_PIN));
    /* pin 19 (A5) is the last valid one */
    in = m_digital_init(7, 19, 1);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
}

static void test_reserved_pin(void)
{
    tdev_t d;
    t_active(&d);
    for (uint32_t pin = 0; pin < 2; pin++) {
        protoduino_ArduinoIn msgs[] = {
            m_servo_init_deg(10 * pin + 1, pin, 0, 0, 90), m_servo_deg(10 * pin + 2, pin, 0),
            m_digital_init(10 * pin + 3, pin, 0), m_digital(10 * pin + 4, pin, 1),
        };
        for (size_t i = 0; i < sizeof(msgs) / sizeof(msgs[0]); i++) {
            CHECK_EQ(t_cmd(&d, &msgs[i]), S(RESERVED_PIN));
        }
        CHECK_EQ(d.hal.digital[pin], -1);
        CHECK_EQ(d.hal.servo_us[pin], -1);
    }
}

static void test_not_initialised(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_deg(1, 9, 90);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_INITIALISED));
    in = m_digital(2, 13, 1);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_INITIALISED));
    /* A control of the other kind is not an init either. */
    in = m_digital_init(3, 13, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_us(4, 13, 1500);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_INITIALISED));
    in = m_servo_init_deg(5, 9, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital(6, 9, 1);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_INITIALISED));
    CHECK_EQ(d.hal.digital[9], -1);
    CHECK_EQ(d.hal.servo_us[13], -1);
}

static void test_servo_init_invalid_argument(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn msgs[] = {
        m_servo_init_deg(1, 9, 399, 2400, 0),  /* min below 400 */
        m_servo_init_deg(2, 9, 544, 2601, 0),  /* max above 2600 */
        m_servo_init_deg(3, 9, 1500, 1500, 0), /* min == max */
        m_servo_init_deg(4, 9, 2000, 1000, 0), /* min > max */
        m_servo_init_deg(5, 9, 2500, 0, 0),    /* min above the default max */
        m_servo_init_deg(6, 9, 0x10000u + 544, 2400, 0), /* would wrap in 16 bits */
    };
    for (size_t i = 0; i < sizeof(msgs) / sizeof(msgs[0]); i++) {
        CHECK_EQ(t_cmd(&d, &msgs[i]), S(INVALID_ARGUMENT));
    }
    protoduino_ArduinoIn in = m_servo_init_deg(7, 9, 0, 0, 0);
    in.data.servo_init.which_safe = 0; /* no safe value */
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
    CHECK_EQ(d.hal.servo_us[9], -1);
    CHECK_EQ(pd_pins_count(d.core.outputs.owner, PD_MODE_SERVO), 0);
    /* The extreme limits themselves are fine. */
    in = m_servo_init_deg(8, 9, 400, 2600, 180);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 2600);
}

static void test_servo_control_invalid_argument(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_deg(1, 9, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_deg(2, 9, 0);
    in.data.servo_control.which_value = 0;
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
    CHECK_EQ(d.hal.servo_us[9], 1472);
}

static void test_out_of_range(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_servo_init_deg(1, 9, 0, 0, 181);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    in = m_servo_init_us(2, 9, 1000, 2000, 999);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    in = m_servo_init_us(3, 9, 1000, 2000, 2001);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    CHECK_EQ(pd_pins_count(d.core.outputs.owner, PD_MODE_SERVO), 0);
    in = m_servo_init_us(4, 9, 1000, 2000, 2000);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    unsigned writes = d.hal.servo_writes[9];
    in = m_servo_deg(5, 9, 181);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    in = m_servo_us(6, 9, 999);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    in = m_servo_us(7, 9, 2001);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    in = m_servo_us(8, 9, 0xFFFFFFFFu);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    CHECK_EQ(d.hal.servo_writes[9], writes); /* refused, not clamped */
    CHECK_EQ(d.hal.servo_us[9], 2000);
    in = m_servo_us(9, 9, 1000);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 1000);
}

static void test_no_free_resource_and_reinit(void)
{
    tdev_t d;
    t_active(&d);
    for (uint32_t i = 0; i < 8; i++) {
        protoduino_ArduinoIn in = m_servo_init_deg(i + 1, 2 + i, 0, 0, 90);
        CHECK_EQ(t_cmd(&d, &in), S(OK));
    }
    protoduino_ArduinoIn in = m_servo_init_deg(20, 12, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(NO_FREE_RESOURCE));
    CHECK_EQ(d.hal.servo_us[12], -1);
    /* Re-init of an existing servo takes no new slot and applies the new limits. */
    in = m_servo_init_us(21, 5, 1000, 2000, 1100);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[5], 1100);
    CHECK_EQ(pd_pins_count(d.core.outputs.owner, PD_MODE_SERVO), 8);
    in = m_servo_us(22, 5, 2100);
    CHECK_EQ(t_cmd(&d, &in), S(OUT_OF_RANGE));
    /* Digital outputs are not limited by servo slots. */
    in = m_digital_init(23, 12, 1);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
}

static void test_pin_in_use(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_digital_init(1, 13, 1);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_init_deg(2, 13, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(PIN_IN_USE));
    in = m_servo_init_deg(3, 9, 0, 0, 90);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital_init(4, 9, 0);
    CHECK_EQ(t_cmd(&d, &in), S(PIN_IN_USE));
    CHECK_EQ(d.hal.servo_us[13], -1);
    CHECK_EQ(d.hal.digital[9], -1);
    /* Re-init as digital is allowed and drives the new safe level. */
    in = m_digital_init(5, 13, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 0);
}

static void test_digital_init_and_control(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_digital_init(1, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 1); /* safe level at once */
    in = m_digital(2, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 0);
    in = m_digital(3, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 1);
}

static void test_message_id_zero(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_digital_init(0, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
    CHECK_EQ(d.hal.digital[13], -1);
    in = m_ping(0, NULL, 0);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_ARGUMENT));
}

static void test_unknown_command(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = protoduino_ArduinoIn_init_zero;
    in.message_id = 42;
    CHECK_EQ(t_cmd(&d, &in), S(UNKNOWN_COMMAND));
}

static void test_decode_error(void)
{
    tdev_t d;
    t_active(&d);
    /* message_id 7, then a servo_init submessage claiming 10 bytes but holding 2. */
    const uint8_t bad[] = {0x08, 0x07, 0x1a, 0x0a, 0x08, 0x09};
    fake_clear(&d.hal);
    t_send_packet(&d, PD_PACKET_COMMAND, d.host_seq++, bad, sizeof(bad));
    CHECK_EQ(fake_count(&d.hal), 2);
    protoduino_ArduinoOut out;
    CHECK(t_out(&d, 0, &out)); /* the event first */
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_decode_error_tag);
    CHECK_EQ(out.data.decode_error.count, 1);
    CHECK_EQ(t_status(&d, 7), S(DECODE_ERROR));
    CHECK_EQ(d.hal.servo_us[9], -1);
    /* Without a message_id: only the event, with the running count. */
    const uint8_t garbage[] = {0xff, 0xff, 0xff};
    fake_clear(&d.hal);
    t_send_packet(&d, PD_PACKET_COMMAND, d.host_seq++, garbage, sizeof(garbage));
    CHECK_EQ(fake_count(&d.hal), 1);
    CHECK(t_out(&d, 0, &out));
    CHECK_EQ(out.which_data, protoduino_ArduinoOut_decode_error_tag);
    CHECK_EQ(out.data.decode_error.count, 2);
    /* A decode error is not remembered: a good retransmission of id 7 executes. */
    protoduino_ArduinoIn in = m_servo_init_deg(7, 9, 0, 0, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.servo_us[9], 544);
}

/* A decode error's Ack tells the host the device saw its id, so the id moves the device's
 * newest id N like any other: else 63 of them in a row, then Pings, would leave N behind the
 * host's acknowledged ids, and an id of the next lap would be answered from the previous
 * lap's entry without running. */
static void test_decode_errors_move_the_newest_id(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_digital(2, 13, true);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 1);
    for (uint8_t id = 3; id <= 65; id++) { /* a servo_init claiming 10 bytes, holding 2 */
        const uint8_t bad[] = {0x08, id, 0x1a, 0x0a, 0x08, 0x09};
        fake_clear(&d.hal);
        t_send_packet(&d, PD_PACKET_COMMAND, d.host_seq++, bad, sizeof(bad));
        CHECK_EQ(t_status(&d, id), S(DECODE_ERROR));
    }
    for (uint32_t id = 66; id <= 128; id++) { /* Pings 66..127, then 1 */
        in = m_ping(id == 128 ? 1 : id, NULL, 0);
        CHECK_EQ(t_cmd(&d, &in), S(OK));
    }
    in = m_digital(2, 13, false); /* id 2 of the next lap: a new command, it runs */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    CHECK_EQ(d.hal.digital[13], 0);
}

static void test_ping_echo_every_byte(void)
{
    tdev_t d;
    t_active(&d);
    uint8_t payload[64];
    for (unsigned chunk = 0; chunk < 4; chunk++) {
        for (unsigned i = 0; i < 64; i++) {
            payload[i] = (uint8_t)(chunk * 64 + i);
        }
        protoduino_ArduinoIn in = m_ping(100 + chunk, payload, sizeof(payload));
        CHECK_EQ(t_cmd(&d, &in), S(OK));
        protoduino_Ack ack;
        CHECK_EQ(t_acks(&d, 100 + chunk, &ack), 1);
        CHECK_EQ(ack.which_result, protoduino_Ack_ping_echo_tag);
        CHECK_EQ(ack.result.ping_echo.size, 64);
        CHECK(memcmp(ack.result.ping_echo.bytes, payload, 64) == 0);
    }
    protoduino_ArduinoIn in = m_ping(120, NULL, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
}

static void test_get_info(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_info(9);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 9, &ack), 1);
    CHECK_EQ(ack.which_result, protoduino_Ack_info_tag);
    const protoduino_DeviceInfo *info = &ack.result.info;
    CHECK(strcmp(info->firmware_version, PD_FIRMWARE_VERSION) == 0);
    CHECK(strcmp(info->board, "fake") == 0);
    CHECK_EQ(info->protocol_version, PD_PROTOCOL_VERSION);
    CHECK_EQ(info->schema_id, PD_SCHEMA_ID);
    CHECK_EQ(info->num_pins, 20);
    CHECK_EQ(info->max_servos, 8);
    CHECK_EQ(info->reserved_pins_count, 2);
    CHECK_EQ(info->reserved_pins[0], 0);
    CHECK_EQ(info->reserved_pins[1], 1);
}

static void test_board_limits_from_hal(void)
{
    tdev_t d;
    t_boot(&d);
    d.hal.info.num_pins = 10;
    d.hal.info.max_servos = 2;
    t_send_reset(&d, PD_PROTOCOL_VERSION);
    protoduino_ArduinoIn in = m_digital_init(1, 10, 0);
    CHECK_EQ(t_cmd(&d, &in), S(INVALID_PIN));
    in = m_servo_init_deg(2, 2, 0, 0, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_init_deg(3, 3, 0, 0, 0);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    in = m_servo_init_deg(4, 4, 0, 0, 0);
    CHECK_EQ(t_cmd(&d, &in), S(NO_FREE_RESOURCE));
}

/* An analog-only pin (the Nano's A6, A7): an analog input and nothing else, refused every
 * other mode (STATUS_NOT_SUPPORTED), and its byte of DeviceInfo.pins says so (no
 * PIN_DIGITAL). */
static void test_an_analog_only_pin_is_an_analog_input_and_nothing_else(void)
{
    tdev_t d;
    t_boot(&d);
    d.hal.info.analog_only_pins = T_SET(1UL << 19);
    t_send_reset(&d, PD_PROTOCOL_VERSION);
    CHECK_EQ(pd_encode_pin(&d.hal.info, 19), protoduino_PinBit_PIN_ANALOG);
    CHECK_EQ(pd_encode_pin(&d.hal.info, 18), protoduino_PinBit_PIN_DIGITAL | protoduino_PinBit_PIN_ANALOG);
    protoduino_ArduinoIn in = m_digital_init(1, 19, 0);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_SUPPORTED));
    in = m_servo_init_deg(2, 19, 0, 0, 0);
    CHECK_EQ(t_cmd(&d, &in), S(NOT_SUPPORTED));
    CHECK_EQ(d.hal.digital[19], -1); /* nothing at the pin */
    CHECK_EQ(d.hal.servo_us[19], -1);
#if PD_FEATURE_DIGITAL_INPUT
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 3;
    in.which_data = protoduino_ArduinoIn_digital_input_init_tag;
    in.data.digital_input_init.pin = 19;
    CHECK_EQ(t_cmd(&d, &in), S(NOT_SUPPORTED));
#endif
#if PD_FEATURE_ANALOG_INPUT
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 4;
    in.which_data = protoduino_ArduinoIn_analog_input_init_tag;
    in.data.analog_input_init.pin = 19;
    CHECK_EQ(t_cmd(&d, &in), S(OK));
#endif
    in = m_digital_init(5, 18, 0); /* its neighbour, a port pin, is digital as ever */
    CHECK_EQ(t_cmd(&d, &in), S(OK));
}

static void test_one_ack_per_message(void)
{
    /* A burst of commands in one stream: exactly one Ack each, in order. */
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn msgs[] = {m_digital_init(11, 13, 0), m_digital(12, 13, 1),
                                   m_digital(13, 14, 1), m_info(14), m_ping(15, NULL, 0)};
    for (size_t i = 0; i < 5; i++) {
        t_send_in(&d, &msgs[i]);
    }
    CHECK_EQ(fake_count(&d.hal), 5);
    for (size_t i = 0; i < 5; i++) {
        protoduino_ArduinoOut out;
        CHECK(t_out(&d, i, &out));
        CHECK_EQ(out.which_data, protoduino_ArduinoOut_ack_tag);
        CHECK_EQ(out.data.ack.message_id, 11 + i);
    }
    CHECK_EQ(t_status(&d, 13), S(NOT_INITIALISED));
}

/* The Ack that would carry only the id and STATUS_OK goes in its short form (2 B of
 * payload, a 9 B frame); a refusal, a result, a failsafe state keep the long one. */
static void test_short_ack_when_only_id_and_ok(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn init = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &init), S(OK));
    fake_clear(&d.hal);
    protoduino_ArduinoIn on = m_digital(2, 13, true);
    CHECK_EQ(t_cmd(&d, &on), S(OK));
    const fake_frame_t *f = fake_frame(&d.hal, 0);
    CHECK(f != NULL);
    CHECK_EQ(f->type, PD_PACKET_DATA);
    CHECK_EQ(f->len, 2);
    CHECK_EQ(f->payload[0], 0x38); /* field 7, varint */
    CHECK_EQ(f->payload[1], 2);
    fake_clear(&d.hal);
    protoduino_ArduinoIn bad = m_digital(3, 12, true); /* not initialised: the long form */
    CHECK_EQ(t_cmd(&d, &bad), S(NOT_INITIALISED));
    protoduino_ArduinoOut out;
    f = fake_frame(&d.hal, 0);
    CHECK(f != NULL && f->len > 2 && f->payload[0] == 0x0A);
    fake_clear(&d.hal);
    protoduino_ArduinoIn ping = m_ping(4, NULL, 0); /* a result (the empty echo): long */
    CHECK_EQ(t_cmd(&d, &ping), S(OK));
    f = fake_frame(&d.hal, 0);
    CHECK(f != NULL && f->payload[0] == 0x0A);
    CHECK(t_out(&d, 0, &out));
    CHECK_EQ(out.data.ack.which_result, protoduino_Ack_ping_echo_tag);
    fake_clear(&d.hal);
    CHECK_EQ(t_cmd(&d, &on), S(OK)); /* a repeat answered from the window: short too */
    f = fake_frame(&d.hal, 0);
    CHECK(f != NULL && f->len == 2 && f->payload[0] == 0x38 && f->payload[1] == 2);
}

/* --- dedupe window ------------------------------------------------------- */

static void test_dedupe_repeat_not_executed(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn init = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &init), S(OK));
    protoduino_ArduinoIn on = m_digital(2, 13, true);
    CHECK_EQ(t_cmd(&d, &on), S(OK));
    protoduino_ArduinoIn off = m_digital(3, 13, false);
    CHECK_EQ(t_cmd(&d, &off), S(OK));
    unsigned writes = d.hal.digital_writes[13];
    CHECK_EQ(t_cmd(&d, &on), S(OK)); /* retransmission of id 2: acked again... */
    CHECK_EQ(d.hal.digital[13], 0);  /* ...but not executed */
    CHECK_EQ(d.hal.digital_writes[13], writes);
    /* Also the stored status of a refused command is what comes back. */
    protoduino_ArduinoIn bad = m_digital(4, 14, true);
    CHECK_EQ(t_cmd(&d, &bad), S(NOT_INITIALISED));
    protoduino_ArduinoIn init14 = m_digital_init(5, 14, false);
    CHECK_EQ(t_cmd(&d, &init14), S(OK));
    CHECK_EQ(t_cmd(&d, &bad), S(NOT_INITIALISED)); /* would be OK if executed again */
    CHECK_EQ(d.hal.digital[14], 0);
    /* Even if the content differs, an id is executed once. */
    protoduino_ArduinoIn other = m_digital(3, 13, true);
    CHECK_EQ(t_cmd(&d, &other), S(OK));
    CHECK_EQ(d.hal.digital[13], 0);
}

/* Entries in the window (free slots hold 0). */
static int dd_count(const pd_dedupe_t *dd)
{
    int n = 0;
    for (uint8_t i = 0; i < PD_DEDUPE_WINDOW; i++) {
        n += dd->id[i] != 0;
    }
    return n;
}

static void test_dedupe_window_evicts_after_16(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn init = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &init), S(OK));
    /* id 2 sets the pin, ids 3..16 refuse other things (still recorded), id 17 clears it. */
    protoduino_ArduinoIn first = m_digital(2, 13, true);
    CHECK_EQ(t_cmd(&d, &first), S(OK));
    for (uint32_t id = 3; id <= 16; id++) {
        protoduino_ArduinoIn in = m_servo_deg(id, 9, 0); /* NOT_INITIALISED, still recorded */
        CHECK_EQ(t_cmd(&d, &in), S(NOT_INITIALISED));
    }
    protoduino_ArduinoIn off = m_digital(17, 13, false);
    CHECK_EQ(t_cmd(&d, &off), S(OK));
    /* N = 17: id 2 is 15 back, inside the window (id 1, 16 back, has left it). */
    CHECK_EQ(dd_count(&d.core.dedupe), PD_DEDUPE_WINDOW);
    CHECK_EQ(t_cmd(&d, &first), S(OK));
    CHECK_EQ(d.hal.digital[13], 0); /* deduplicated */
    /* A newer id, even an idempotent one, moves N: id 2 is 16 back and runs again. */
    protoduino_ArduinoIn ping = m_ping(18, NULL, 0);
    CHECK_EQ(t_cmd(&d, &ping), S(OK));
    CHECK_EQ(t_cmd(&d, &first), S(OK));
    CHECK_EQ(d.hal.digital[13], 1);
    CHECK(dd_count(&d.core.dedupe) <= PD_DEDUPE_WINDOW); /* never one id twice */
}

/* An id met again after a wrap never finds its old entry, even one no later
 * command pushed out (only idempotent ones came between), and even when a
 * newer id arrived before it (its first transmission was lost). */
static void test_dedupe_stale_entry_of_the_same_id_executes(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn init = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &init), S(OK));
    protoduino_ArduinoIn on = m_digital(5, 13, true);
    CHECK_EQ(t_cmd(&d, &on), S(OK));
    for (uint32_t k = 6; k <= PD_MAX_MESSAGE_ID + 4u; k++) { /* 6..127, 1..4: Pings */
        uint32_t id = (k - 1u) % PD_MAX_MESSAGE_ID + 1u;
        protoduino_ArduinoIn ping = m_ping(id, NULL, 0);
        CHECK_EQ(t_cmd(&d, &ping), S(OK));
    }
    protoduino_ArduinoIn ping = m_ping(6, NULL, 0); /* id 5's first transmission is lost */
    CHECK_EQ(t_cmd(&d, &ping), S(OK));
    protoduino_ArduinoIn off = m_digital(5, 13, false); /* a new command under id 5 */
    CHECK_EQ(t_cmd(&d, &off), S(OK));
    CHECK_EQ(d.hal.digital[13], 0); /* executed, not answered from the old entry */
    CHECK_EQ(dd_count(&d.core.dedupe), 1);
    CHECK_EQ(t_cmd(&d, &off), S(OK)); /* and its own repeat is one */
    CHECK_EQ(t_cmd(&d, &on), S(OK));
    CHECK_EQ(d.hal.digital[13], 0);
}

/* N moves only to an id 1..63 ahead of it; anything else is older. */
static void test_dedupe_newest_moves_only_forward(void)
{
    pd_dedupe_t dd;
    pd_dedupe_init(&dd);
    pd_dedupe_sync(&dd, 11, true);
    CHECK_EQ(dd.newest, 10);
    pd_dedupe_done(&dd, 10 + PD_ID_AHEAD_MAX + 1u, 0); /* 64 ahead: behind */
    CHECK_EQ(dd.newest, 10);
    CHECK_EQ(pd_dedupe_lookup(&dd, 10 + PD_ID_AHEAD_MAX), -1);
    CHECK_EQ(dd.newest, 10); /* a lookup moves nothing */
    pd_dedupe_done(&dd, 10 + PD_ID_AHEAD_MAX, -1); /* 63 ahead: newer */
    CHECK_EQ(dd.newest, 10 + PD_ID_AHEAD_MAX);
    pd_dedupe_done(&dd, 40, 0); /* older: N stays */
    CHECK_EQ(dd.newest, 10 + PD_ID_AHEAD_MAX);
    pd_dedupe_sync(&dd, 1, false); /* NEXT_ID 1: N is 127, the id before it */
    CHECK_EQ(dd.newest, PD_MAX_MESSAGE_ID);
    pd_dedupe_done(&dd, 3, 0); /* across the wrap: newer */
    CHECK_EQ(dd.newest, 3);
    pd_dedupe_done(&dd, PD_MAX_MESSAGE_ID, 0);
    CHECK_EQ(dd.newest, 3);
}

static void test_dedupe_id_outside_1_to_127_refused(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn init = m_digital_init(PD_MAX_MESSAGE_ID + 1u, 13, false);
    CHECK_EQ(t_cmd(&d, &init), S(INVALID_ARGUMENT));
    CHECK_EQ(d.hal.digital[13], -1);
    CHECK_EQ(dd_count(&d.core.dedupe), 0);
}

static void test_dedupe_ping_and_info_answered_in_full(void)
{
    tdev_t d;
    t_active(&d);
    const uint8_t payload[3] = {1, 2, 3};
    protoduino_ArduinoIn ping = m_ping(50, payload, 3);
    CHECK_EQ(t_cmd(&d, &ping), S(OK));
    CHECK_EQ(t_cmd(&d, &ping), S(OK));
    protoduino_Ack ack;
    CHECK_EQ(t_acks(&d, 50, &ack), 1);
    CHECK_EQ(ack.which_result, protoduino_Ack_ping_echo_tag);
    CHECK_EQ(ack.result.ping_echo.size, 3);
    protoduino_ArduinoIn info = m_info(51);
    CHECK_EQ(t_cmd(&d, &info), S(OK));
    CHECK_EQ(t_cmd(&d, &info), S(OK));
    CHECK_EQ(t_acks(&d, 51, &ack), 1);
    CHECK_EQ(ack.which_result, protoduino_Ack_info_tag);
    CHECK_EQ(dd_count(&d.core.dedupe), 0); /* they take no slot */
}

static void test_dedupe_survives_reset_not_reboot(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn init = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &init), S(OK));
    protoduino_ArduinoIn on = m_digital(2, 13, true);
    CHECK_EQ(t_cmd(&d, &on), S(OK));
    protoduino_ArduinoIn off = m_digital(3, 13, false);
    CHECK_EQ(t_cmd(&d, &off), S(OK));
    t_send_reset(&d, PD_PROTOCOL_VERSION); /* the host handshakes again (NEXT_ID 4), retransmits */
    CHECK_EQ(d.core.dedupe.newest, 3);
    CHECK_EQ(t_cmd(&d, &on), S(OK));
    CHECK_EQ(d.hal.digital[13], 0);
    pd_core_init(&d.core, &d.hal); /* a reboot forgets everything */
    CHECK_EQ(dd_count(&d.core.dedupe), 0);
}

/* A new session's id 1 runs, whatever the previous owner left in the window. */
static void test_dedupe_new_session_clears(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn init = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &init), S(OK));
    protoduino_ArduinoIn on = m_digital(2, 13, true);
    CHECK_EQ(t_cmd(&d, &on), S(OK));
    t_send_reset_next(&d, T_SESSION + 1u, 1); /* another host, its ids from 1 */
    CHECK_EQ(dd_count(&d.core.dedupe), 0);
    CHECK_EQ(d.core.dedupe.newest, PD_MAX_MESSAGE_ID);
    CHECK_EQ(t_cmd(&d, &init), S(OK)); /* its id 1: executed (the pin was released) */
    CHECK_EQ(d.hal.digital[13], 0);
    CHECK_EQ(t_cmd(&d, &on), S(OK));
    CHECK_EQ(d.hal.digital[13], 1);
}

/* With its slots out of insertion order, a full window overwrites slot `next`, not the
 * entry inserted first (tests/unit/test_testing.py checks protoduino.testing.DedupeWindow
 * on the same steps). */
static void test_dedupe_full_window_evicts_slot_next(void)
{
    pd_dedupe_t dd;
    pd_dedupe_init(&dd);
    pd_dedupe_sync(&dd, 1, true); /* N = 127 */
    /* Id 2, then 1 (its first transmission lost), then 3..16: slots 0..15, next 0. */
    static const uint8_t order[PD_DEDUPE_WINDOW] = {2,  1,  3,  4,  5,  6,  7,  8,
                                                    9, 10, 11, 12, 13, 14, 15, 16};
    for (uint8_t k = 0; k < PD_DEDUPE_WINDOW; k++) {
        CHECK_EQ(pd_dedupe_lookup(&dd, order[k]), -1);
        pd_dedupe_done(&dd, order[k], protoduino_Status_STATUS_OK);
        CHECK_EQ(dd.id[k], order[k]);
    }
    CHECK_EQ(dd.next, 0);
    CHECK_EQ(dd.newest, 16);
    pd_dedupe_done(&dd, 17, -1); /* a Ping: N 17, id 1 (16 back) dropped */
    CHECK_EQ(dd.id[1], 0);
    pd_dedupe_done(&dd, 17, protoduino_Status_STATUS_OK); /* the free slot after next */
    CHECK_EQ(dd.id[1], 17);
    CHECK_EQ(dd.next, 2);
    /* An id out of reach (44 behind N: no repeat, N stays), the window full: slot 2 (id 3). */
    CHECK_EQ(pd_dedupe_lookup(&dd, 100), -1);
    pd_dedupe_done(&dd, 100, protoduino_Status_STATUS_NOT_INITIALISED);
    CHECK_EQ(dd.newest, 17);
    CHECK_EQ(dd.next, 3);
    CHECK_EQ(dd.id[0], 2);
    CHECK_EQ(dd.id[2], 100);
    CHECK_EQ(pd_dedupe_lookup(&dd, 2), protoduino_Status_STATUS_OK);
    CHECK_EQ(pd_dedupe_lookup(&dd, 3), -1);
}

static void test_dedupe_unit(void)
{
    pd_dedupe_t dd;
    pd_dedupe_init(&dd);
    pd_dedupe_sync(&dd, 1, true);
    for (uint32_t k = 1; k <= 3u * PD_MAX_MESSAGE_ID; k++) {
        uint8_t id = (uint8_t)((k - 1u) % PD_MAX_MESSAGE_ID + 1u);
        CHECK_EQ(pd_dedupe_lookup(&dd, id), -1);
        pd_dedupe_done(&dd, id, id % 10);
        CHECK_EQ(pd_dedupe_lookup(&dd, id), id % 10);
        for (uint8_t back = 1; back < 20 && back < k; back++) {
            uint8_t old = (uint8_t)((id + PD_MAX_MESSAGE_ID - 1u - back) % PD_MAX_MESSAGE_ID + 1u);
            CHECK_EQ(pd_dedupe_lookup(&dd, old), back < PD_DEDUPE_WINDOW ? old % 10 : -1);
        }
        CHECK_EQ(dd.newest, id);
    }
}

/* --- the short decode (pd_dispatch_decode_short) against nanopb's whole decode --- */

/*
 * Both decodes of `payload`, each into an ArduinoIn filled with the same stale
 * bytes (what the previous command left), compared byte for byte with the
 * answer: -1 when the short decode left the payload to the full one, else what
 * it said; *same tells whether the two agreed.
 */
static int decode_both(const uint8_t *payload, size_t len, bool *same)
{
    protoduino_ArduinoIn fast, full;
    memset(&fast, 0xA5, sizeof(fast));
    memset(&full, 0xA5, sizeof(full));
    int r = pd_dispatch_decode_short(&fast, payload, len);
    if (r < 0) {
        /* Nothing written: the full decode starts from what it would have. */
        protoduino_ArduinoIn untouched;
        memset(&untouched, 0xA5, sizeof(untouched));
        *same = memcmp(&fast, &untouched, sizeof(fast)) == 0;
        return r;
    }
    bool ok = pd_dispatch_decode_full(&full, payload, len);
    *same = (r == 1) == ok && memcmp(&fast, &full, sizeof(fast)) == 0;
    return r;
}

static size_t encode_in(const protoduino_ArduinoIn *in, uint8_t *buf, size_t cap)
{
    pb_ostream_t s = pb_ostream_from_buffer(buf, cap);
    if (!pb_encode(&s, protoduino_ArduinoIn_fields, in)) {
        return 0;
    }
    return s.bytes_written;
}

/* What a host sends, one of each shape the short decode takes (and the Controls twice). */
static size_t short_bases(protoduino_ArduinoIn *ins, size_t cap)
{
    size_t n = 0;
    const uint8_t bytes[64] = {1, 2, 3, 0x80, 0xff, 0};
    ins[n++] = m_digital(7, 13, true);
    ins[n++] = m_digital(127, 0, false); /* an empty DigitalControl: length 0 */
    ins[n++] = m_servo_deg(1, 9, 180);
    ins[n++] = m_servo_us(42, 10, 2400);
    ins[n++] = m_ping(3, bytes, sizeof(bytes));
    ins[n++] = m_servo_init_us(4, 9, 1000, 2000, 1500);
    ins[n++] = m_stop(5);
    ins[n++] = m_info(6);
    protoduino_ArduinoIn in = protoduino_ArduinoIn_init_zero;
    in.message_id = 8;
    in.which_data = protoduino_ArduinoIn_pwm_control_tag;
    in.data.pwm_control.pin = 3;
    in.data.pwm_control.duty = 255;
    ins[n++] = in;
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 9;
    in.which_data = protoduino_ArduinoIn_pose_tag;
    in.data.pose.items_count = 3;
    in.data.pose.items[0].which_output = protoduino_PoseItem_servo_tag;
    in.data.pose.items[0].output.servo.pin = 9;
    in.data.pose.items[0].output.servo.which_value = protoduino_ServoControl_degrees_tag;
    in.data.pose.items[0].output.servo.value.degrees = 90;
    in.data.pose.items[1].which_output = protoduino_PoseItem_digital_tag;
    in.data.pose.items[1].output.digital.pin = 13;
    in.data.pose.items[1].output.digital.level = true;
    in.data.pose.items[2].which_output = protoduino_PoseItem_pwm_tag;
    in.data.pose.items[2].output.pwm.pin = 11;
    in.data.pose.items[2].output.pwm.duty = 128;
    ins[n++] = in;
    T_PUT_MASK(in.data.pose.digital_pins, (1UL << 2) | (1UL << 7) | (1UL << 19)); /* the sets */
    T_PUT_MASK(in.data.pose.digital_levels, 1UL << 7);
    ins[n++] = in;
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 12;
    in.which_data = protoduino_ArduinoIn_pose_tag;
    T_PUT_MASK(in.data.pose.digital_pins, 0xFCu); /* six digital outputs, sets only */
    T_PUT_MASK(in.data.pose.digital_levels, 0x54u);
    ins[n++] = in;
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 10;
    in.which_data = protoduino_ArduinoIn_heartbeat_tag;
    in.data.heartbeat.failsafe_epoch = 200;
    ins[n++] = in;
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 11;
    in.which_data = protoduino_ArduinoIn_configure_failsafe_tag;
    in.data.configure_failsafe.timeout_ms = 60000;
    in.data.configure_failsafe.liveness = protoduino_Liveness_LIVENESS_HEARTBEAT;
    ins[n++] = in;
    /* The Inits and Release of one-byte tags (the Controls above have generated decoders). */
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 13;
    in.which_data = protoduino_ArduinoIn_digital_init_tag;
    in.data.digital_init.pin = 13;
    in.data.digital_init.safe_level = true;
    ins[n++] = in;
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 14;
    in.which_data = protoduino_ArduinoIn_pwm_init_tag;
    in.data.pwm_init.pin = 11;
    in.data.pwm_init.safe_duty = 200;
    ins[n++] = in;
    in = (protoduino_ArduinoIn)protoduino_ArduinoIn_init_zero;
    in.message_id = 15;
    in.which_data = protoduino_ArduinoIn_release_tag;
    in.data.release.pin = 9;
    ins[n++] = in;
    if (n > cap) {
        abort(); /* the caller's array is too short */
    }
    return n;
}

/*
 * Every payload a host library writes takes the short way, and it agrees with
 * the full decode on every one-byte change of those payloads (256 values at
 * each place), every truncation and every byte appended: the statuses of
 * protocol.md section 7 (rule 10's decode error among them) follow from the
 * decoded ArduinoIn and whether it decoded, so they agree too.
 */
static void test_short_decode_matches_full(void)
{
    protoduino_ArduinoIn ins[24];
    size_t count = short_bases(ins, sizeof(ins) / sizeof(ins[0]));
    size_t taken = 0, refused = 0, full = 0;
    for (size_t k = 0; k < count; k++) {
        uint8_t base[PD_MAX_PAYLOAD];
        uint8_t buf[PD_MAX_PAYLOAD + 1];
        size_t n = encode_in(&ins[k], base, sizeof(base));
        CHECK(n >= 4u);
        bool same = false;
        CHECK_EQ(decode_both(base, n, &same), 1); /* a host's payload: the short way, decoded */
        CHECK(same);
        for (size_t i = 0; i < n; i++) {
            for (unsigned v = 0; v < 256u; v++) {
                memcpy(buf, base, n);
                buf[i] = (uint8_t)v;
                int r = decode_both(buf, n, &same);
                CHECK(same);
                taken += r == 1;
                refused += r == 0;
                full += r < 0;
            }
        }
        for (size_t cut = 0; cut < n; cut++) {
            decode_both(base, cut, &same);
            CHECK(same);
        }
        for (unsigned v = 0; v < 256u; v++) {
            memcpy(buf, base, n);
            buf[n] = (uint8_t)v;
            CHECK_EQ(decode_both(buf, n + 1u, &same), -1); /* a byte after the command */
            CHECK(same);
        }
    }
    /* All three outcomes were compared, not only the easy one. */
    CHECK(taken > 0u);
    CHECK(refused > 0u);
    CHECK(full > 0u);
}

/* The descriptor the generated header gives member `name` (its MSGTYPE, which
 * codegen.share_descriptors may point at another message of the same shape). */
#define T_CAT2(a, b) a##b
#define T_CAT(a, b) T_CAT2(a, b)
#define T_MEMBER_DESC(name) (&T_CAT(protoduino_ArduinoIn_data_##name##_MSGTYPE, _msg))

/* The short decode takes member N's descriptor from nanopb's ArduinoIn descriptor as
 * submessage N - 2: true while every field but the message id is a member, in order. */
static void test_short_decode_descriptors(void)
{
    size_t members = 0;
#define T_MEMBER(name, feature_, flags_, result_)                                    \
    CHECK(protoduino_ArduinoIn_msg.submsg_info[protoduino_ArduinoIn_##name##_tag - 2] == \
          T_MEMBER_DESC(name));                                                      \
    members++;
    PD_COMMANDS(T_MEMBER)
#undef T_MEMBER
    CHECK_EQ(members + 1u, protoduino_ArduinoIn_msg.field_count);
    CHECK_EQ(members + 1u, protoduino_ArduinoIn_msg.largest_tag);
}

/* Shapes the short decode leaves to nanopb's whole decode, which still runs them. */
/* A digital write to pin 13 in a shape the short decode leaves to the full one: it still
 * runs, answered under `id`, and the pin shows `level`. */
static void check_other_shape(tdev_t *d, const uint8_t *payload, size_t len, uint32_t id,
                              int level)
{
    bool same = false;
    CHECK_EQ(decode_both(payload, len, &same), -1);
    fake_clear(&d->hal);
    t_send_packet(d, PD_PACKET_COMMAND, d->host_seq++, payload, len);
    CHECK_EQ(t_status(d, id), S(OK));
    CHECK_EQ(d->hal.digital[13], level);
}

static void test_other_shapes_still_decode(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    /* The command first, the id after it. */
    const uint8_t id_last[] = {0x22, 0x04, 0x08, 0x0d, 0x10, 0x01, 0x08, 0x02};
    check_other_shape(&d, id_last, sizeof(id_last), 2, 1);
    /* A two-byte length (4 as 0x84 0x00) and a two-byte id (3 as 0x83 0x00). */
    const uint8_t long_len[] = {0x08, 0x03, 0x22, 0x84, 0x00, 0x08, 0x0d, 0x10, 0x00};
    check_other_shape(&d, long_len, sizeof(long_len), 3, 0);
    const uint8_t long_id[] = {0x08, 0x84, 0x00, 0x22, 0x04, 0x08, 0x0d, 0x10, 0x01};
    check_other_shape(&d, long_id, sizeof(long_id), 4, 1);
}

/* A payload of the short shape whose command does not decode: rule 10, as before. */
static void test_short_decode_error(void)
{
    tdev_t d;
    t_active(&d);
    protoduino_ArduinoIn in = m_digital_init(1, 13, false);
    CHECK_EQ(t_cmd(&d, &in), S(OK));
    /* id 7, DigitalControl{pin: 300}: wider than the device's one-byte pin. */
    const uint8_t wide[] = {0x08, 0x07, 0x22, 0x05, 0x08, 0xac, 0x02, 0x10, 0x01};
    bool same = false;
    CHECK_EQ(decode_both(wide, sizeof(wide), &same), 0);
    CHECK(same);
    fake_clear(&d.hal);
    t_send_packet(&d, PD_PACKET_COMMAND, d.host_seq++, wide, sizeof(wide));
    CHECK_EQ(fake_count(&d.hal), 2); /* the DecodeError event, then the Ack */
    CHECK_EQ(t_status(&d, 7), S(DECODE_ERROR));
    CHECK_EQ(d.hal.digital[13], 0);
}

const pd_test_case_t pd_tests_dispatch[] = {
    TEST_CASE(test_ack_ok_every_command),
    TEST_CASE(test_servo_init_defaults_and_safe_at_once),
    TEST_CASE(test_degrees_to_us),
    TEST_CASE(test_div180_exact_below_180_squared),
    TEST_CASE(test_degrees_to_us_every_degree),
    TEST_CASE(test_invalid_pin),
    TEST_CASE(test_reserved_pin),
    TEST_CASE(test_not_initialised),
    TEST_CASE(test_servo_init_invalid_argument),
    TEST_CASE(test_servo_control_invalid_argument),
    TEST_CASE(test_out_of_range),
    TEST_CASE(test_no_free_resource_and_reinit),
    TEST_CASE(test_pin_in_use),
    TEST_CASE(test_digital_init_and_control),
    TEST_CASE(test_message_id_zero),
    TEST_CASE(test_unknown_command),
    TEST_CASE(test_decode_error),
    TEST_CASE(test_decode_errors_move_the_newest_id),
    TEST_CASE(test_short_decode_matches_full),
    TEST_CASE(test_short_decode_descriptors),
    TEST_CASE(test_other_shapes_still_decode),
    TEST_CASE(test_short_decode_error),
    TEST_CASE(test_ping_echo_every_byte),
    TEST_CASE(test_get_info),
    TEST_CASE(test_board_limits_from_hal),
    TEST_CASE(test_an_analog_only_pin_is_an_analog_input_and_nothing_else),
    TEST_CASE(test_one_ack_per_message),
    TEST_CASE(test_dedupe_repeat_not_executed),
    TEST_CASE(test_short_ack_when_only_id_and_ok),
    TEST_CASE(test_dedupe_window_evicts_after_16),
    TEST_CASE(test_dedupe_stale_entry_of_the_same_id_executes),
    TEST_CASE(test_dedupe_newest_moves_only_forward),
    TEST_CASE(test_dedupe_id_outside_1_to_127_refused),
    TEST_CASE(test_dedupe_ping_and_info_answered_in_full),
    TEST_CASE(test_dedupe_survives_reset_not_reboot),
    TEST_CASE(test_dedupe_new_session_clears),
    TEST_CASE(test_dedupe_full_window_evicts_slot_next),
    TEST_CASE(test_dedupe_unit),
    {NULL, NULL},
};

#include "pd_encode.h"

#include <stdbool.h>
#include <string.h>

/* Protobuf wire types. */
#define WT_VARINT 0u
#define WT_LEN 2u
#define WT_FIXED32 5u

/* A nested message's length is patched in place afterwards: one byte, or in a build
 * whose largest message is longer (the Mega's, PD_ENCODE_LONG) two where it needs them. */
#define PD_ENCODE_LONG (PD_ENCODE_MAX >= 128u)
typedef char pd_assert_out_small[(PD_ENCODE_MAX < 0x4000u) ? 1 : -1];
/* The bound covers every member of ArduinoOut that is not an Ack, and is no larger than nanopb's. */
typedef char pd_assert_bound[(PD_ENCODE_MAX <= protoduino_ArduinoOut_size &&
                              2u + protoduino_DecodeError_size <= PD_ENCODE_MAX) ? 1 : -1];
/* The user reply's bound above is the schema's (protoduino.options), and a
 * UserCall's Ack fits beside the shapes that make the bound. */
typedef char pd_assert_user_bounds[(sizeof(((protoduino_Ack *)0)->result.user_reply.bytes) == 64u &&
                                    sizeof(((protoduino_UserReport *)0)->body.bytes) <= 64u &&
                                    8u + PD_ENCODE_USER_ACK_MAX <= PD_ENCODE_ACK_MAX) ? 1 : -1];

/*
 * No bounds check per byte: pd_encode_out takes only a buffer that holds the
 * largest ArduinoOut the device sends (PD_ENCODE_MAX, from nanopb's sizes of the
 * same bounds this encoder enforces: every bytes, string and repeated field is
 * checked against its static size before it is written). A check per byte was
 * a fifth of an Ack's cycles on the Uno, between the command's delimiter and
 * the Ack's first byte.
 */
typedef struct writer {
    uint8_t *p; /* the next byte */
    bool ok;    /* false: a field out of its bounds, nothing to send */
} writer_t;

static void put(writer_t *w, uint8_t byte)
{
    *w->p++ = byte;
}

static void put_varint(writer_t *w, uint32_t value)
{
    while (value >= 0x80u) {
        put(w, (uint8_t)(value | 0x80u));
        /* value >>= 7 as a byte move and a shift by one: a 32-bit shift by 7 is
         * a 7-pass loop at -Os, four times per message_id on the Uno. */
        value = ((value >> 8) << 1) | ((uint8_t)value >> 7);
    }
    put(w, (uint8_t)value);
}

static void put_tag(writer_t *w, uint8_t tag, uint8_t wire_type)
{
    if (tag < 16u) {
        put(w, (uint8_t)((tag << 3) | wire_type));
    } else { /* two bytes, up to tag 31 */
        put(w, (uint8_t)(0x80u | ((tag << 3) & 0x7Fu) | wire_type));
        put(w, (uint8_t)(tag >> 4));
    }
}

/* A singular proto3 scalar: omitted when zero. */
static void put_uint(writer_t *w, uint8_t tag, uint32_t value)
{
    if (value != 0) {
        put_tag(w, tag, WT_VARINT);
        put_varint(w, value);
    }
}

static void put_bytes(writer_t *w, uint8_t tag, const void *data, size_t len)
{
    put_tag(w, tag, WT_LEN);
    put_varint(w, (uint32_t)len);
    for (size_t i = 0; i < len; i++) {
        put(w, ((const uint8_t *)data)[i]);
    }
}

static void put_string(writer_t *w, uint8_t tag, const char *s, size_t max)
{
    size_t n = 0;
    while (n < max && s[n] != '\0') {
        n++;
    }
    if (n == max) {
        w->ok = false; /* unterminated, as pb_encode would refuse it */
    } else if (n > 0) {
        put_bytes(w, tag, s, n);
    }
}

/* Start a nested message; returns where its length byte goes. */
static uint8_t *open_msg(writer_t *w, uint8_t tag)
{
    put_tag(w, tag, WT_LEN);
    uint8_t *at = w->p;
    put(w, 0);
    return at;
}

/* Its length fits one byte where the whole ArduinoOut is under 128 (the Uno); else a
 * length of 128 or more takes two, the message moving up one byte for the second. */
static void close_msg(writer_t *w, uint8_t *at)
{
    size_t len = (size_t)(w->p - at - 1);
#if PD_ENCODE_LONG
    if (len >= 0x80u) {
        memmove(at + 2, at + 1, len);
        at[0] = (uint8_t)(len | 0x80u);
        at[1] = (uint8_t)(len >> 7);
        w->p++;
        return;
    }
#endif
    *at = (uint8_t)len;
}

static void put_fixed32(writer_t *w, uint8_t tag, uint32_t v)
{
    if (v != 0) {
        put_tag(w, tag, WT_FIXED32);
        put(w, (uint8_t)v); /* little-endian */
        put(w, (uint8_t)(v >> 8));
        put(w, (uint8_t)(v >> 16));
        put(w, (uint8_t)(v >> 24));
    }
}

/* A pin set (protocol version 8, pd_pinset.h): bytes, omitted when empty, as pb_encode does;
 * every pin set's bound is the schema's 9 bytes. Not inlined: seven fields share it. */
static __attribute__((noinline)) void put_pinset(writer_t *w, uint8_t tag, const uint8_t *bytes,
                                                 pb_size_t size)
{
    if (size > PD_PINSET_WIRE_MAX) {
        w->ok = false;
    } else if (size > 0) {
        put_bytes(w, tag, bytes, size);
    }
}
#define PUT_PINSET(w, tag, field) put_pinset((w), (tag), (field).bytes, (field).size)

static void put_info(writer_t *w, const protoduino_DeviceInfo *info)
{
    put_string(w, protoduino_DeviceInfo_firmware_version_tag, info->firmware_version,
               sizeof(info->firmware_version));
    put_uint(w, protoduino_DeviceInfo_protocol_version_tag, info->protocol_version);
    put_fixed32(w, protoduino_DeviceInfo_schema_id_tag, info->schema_id);
    put_string(w, protoduino_DeviceInfo_board_tag, info->board, sizeof(info->board));
    put_uint(w, protoduino_DeviceInfo_num_pins_tag, info->num_pins);
    put_uint(w, protoduino_DeviceInfo_max_servos_tag, info->max_servos);
    pb_size_t count = info->reserved_pins_count;
    if (count > sizeof(info->reserved_pins) / sizeof(info->reserved_pins[0])) {
        w->ok = false;
    } else if (count > 0) {
        uint8_t *at = open_msg(w, protoduino_DeviceInfo_reserved_pins_tag); /* packed */
        for (pb_size_t i = 0; i < count; i++) {
            put_varint(w, info->reserved_pins[i]);
        }
        close_msg(w, at);
    }
    put_uint(w, protoduino_DeviceInfo_rx_buffer_tag, info->rx_buffer);
    put_uint(w, protoduino_DeviceInfo_features_tag, info->features);
#if PD_FEATURE_USER
    put_fixed32(w, protoduino_DeviceInfo_user_fingerprint_tag, info->user_fingerprint);
#endif
    /* The board's own table, read through the HAL (in pins.arg: pd_dispatch.c) so
     * that on the Uno its fields stay constants the compiler folds into the code,
     * not a struct in RAM. A DeviceInfo of no pins has no table. */
    uint8_t n = info->num_pins;
    if (n == 0) {
        return;
    }
    const pd_board_info_t *board = pd_hal_board_info(info->pins.arg);
    uint8_t timers = pd_encode_timer_count(board);
    if (n > PD_MAX_PINS || timers > PD_INFO_TIMERS_MAX) {
        w->ok = false;
        return;
    }
    uint8_t *at = open_msg(w, protoduino_DeviceInfo_pins_tag);
    for (uint8_t pin = 0; pin < n; pin++) {
        put(w, pd_encode_pin(board, pin));
    }
    close_msg(w, at);
    if (timers > 0) {
        at = open_msg(w, protoduino_DeviceInfo_timers_tag);
        for (uint8_t timer = 0; timer < timers; timer++) {
            put(w, pd_encode_timer(board, timer));
        }
        close_msg(w, at);
    }
}

uint8_t pd_encode_pin(const pd_board_info_t *board, uint8_t pin)
{
    if (pin >= PD_MAX_PINS || pin >= board->num_pins || pd_pinset_has(&board->reserved_pins, pin)) {
        return 0;
    }
    uint8_t v = pd_pinset_has(&board->analog_only_pins, pin) ? 0u : protoduino_PinBit_PIN_DIGITAL;
    if (pd_pinset_has(&board->pwm_pins, pin)) {
        v |= protoduino_PinBit_PIN_PWM;
    }
    if (pd_pinset_has(&board->analog_pins, pin)) {
        v |= protoduino_PinBit_PIN_ANALOG;
    }
    if (pd_pinset_has(&board->counter_pins, pin)) {
        v |= protoduino_PinBit_PIN_COUNTER;
    }
    if (pd_pinset_has(&board->pin_change_pins, pin)) {
        v |= protoduino_PinBit_PIN_PIN_CHANGE;
    }
    if (pd_pinset_has(&board->servo_timer_pins, pin)) {
        uint8_t timer =
            pd_pinset_has(&board->servo_timer_2_pins, pin) ? board->servo_timer_2 : board->servo_timer;
        v |= (uint8_t)((timer + 1u) << 5);
    } else if (pd_pinset_has(&board->clock_timer_pins, pin)) {
        v |= (uint8_t)((board->clock_timer + 1u) << 5);
    }
    return v;
}

uint8_t pd_encode_timer_count(const pd_board_info_t *board)
{
    uint8_t n = 0;
    if (pd_pinset_any(&board->servo_timer_pins)) {
        n = (uint8_t)(board->servo_timer + 1u);
    }
    if (pd_pinset_any(&board->clock_timer_pins) && board->clock_timer + 1u > n) {
        n = (uint8_t)(board->clock_timer + 1u);
    }
    if (board->servo_timer_2 + 1u > n && board->servo_timer_2 != 0) {
        n = (uint8_t)(board->servo_timer_2 + 1u);
    }
    return n;
}

uint8_t pd_encode_timer(const pd_board_info_t *board, uint8_t timer)
{
    if ((pd_pinset_any(&board->servo_timer_pins) && timer == board->servo_timer) ||
        (board->servo_timer_2 != 0 && timer == board->servo_timer_2)) {
        return protoduino_TimerUse_TIMER_SERVOS;
    }
    if (pd_pinset_any(&board->clock_timer_pins) && timer == board->clock_timer) {
        return protoduino_TimerUse_TIMER_CLOCK;
    }
    return protoduino_TimerUse_TIMER_FREE;
}

/* A packed repeated varint field; omitted when empty, as pb_encode does. */
static void put_packed(writer_t *w, uint8_t tag, const void *values, uint8_t width,
                       pb_size_t count, size_t max)
{
    if (count > max) {
        w->ok = false;
    } else if (count > 0) {
        uint8_t *at = open_msg(w, tag);
        const uint8_t *v = values;
        for (pb_size_t i = 0; i < count; i++, v += width) {
            uint32_t value = v[0] | (uint32_t)v[1] << 8;
            if (width == 4u) {
                value |= (uint32_t)v[2] << 16 | (uint32_t)v[3] << 24;
            }
            put_varint(w, value);
        }
        close_msg(w, at);
    }
}

static __attribute__((noinline)) void put_report(writer_t *w, const protoduino_InputReport *r)
{
    typedef char widths[(sizeof(r->analog_values[0]) == 2u &&
                         sizeof(r->counter_counts[0]) == 4u) ? 1 : -1];
    (void)sizeof(widths);
    put_uint(w, protoduino_InputReport_time_ms_tag, r->time_ms);
    PUT_PINSET(w, protoduino_InputReport_digital_pins_tag, r->digital_pins);
    PUT_PINSET(w, protoduino_InputReport_digital_levels_tag, r->digital_levels);
    PUT_PINSET(w, protoduino_InputReport_analog_pins_tag, r->analog_pins);
    put_packed(w, protoduino_InputReport_analog_values_tag, r->analog_values, 2u,
               r->analog_values_count, sizeof(r->analog_values) / sizeof(r->analog_values[0]));
    PUT_PINSET(w, protoduino_InputReport_counter_pins_tag, r->counter_pins);
    put_packed(w, protoduino_InputReport_counter_counts_tag, r->counter_counts, 4u,
               r->counter_counts_count, sizeof(r->counter_counts) / sizeof(r->counter_counts[0]));
    put_uint(w, protoduino_InputReport_coalesced_tag, r->coalesced);
}

/* A Failsafe's fields (the event, and an Ack's failsafe state). */
static void put_failsafe(writer_t *w, uint8_t tag, const protoduino_Failsafe *fs)
{
    uint8_t *at = open_msg(w, tag);
    put_uint(w, protoduino_Failsafe_active_tag, fs->active ? 1u : 0u);
    put_uint(w, protoduino_Failsafe_cause_tag, (uint32_t)fs->cause);
    put_uint(w, protoduino_Failsafe_epoch_tag, fs->epoch);
    put_uint(w, protoduino_Failsafe_pin_tag, fs->pin);
    close_msg(w, at);
}

/* Not inlined into pd_encode_out: 56 B less of the Uno's flash, for one call
 * per Ack. */
static __attribute__((noinline)) void put_ack(writer_t *w, const protoduino_Ack *ack)
{
    /* The most this Ack's shape can take, checked before anything is written
     * (PD_ENCODE_ACK_MAX: the shapes the device sends fit). */
    uint8_t need = ack->which_result == protoduino_Ack_info_tag ? PD_ENCODE_NESTED(PD_ENCODE_INFO_MAX)
#if PD_FEATURE_USER
                   : ack->which_result == protoduino_Ack_user_reply_tag ? PD_ENCODE_USER_ACK_MAX
#endif
                   : ack->which_result == protoduino_Ack_outputs_tag
                       ? PD_ENCODE_NESTED(PD_ENCODE_OUTPUTS_MAX)
                   : ack->which_result == protoduino_Ack_ping_echo_tag ? 66u
                                                                       : 0u;
    need = (uint8_t)(need + (ack->has_failsafe ? 2u + protoduino_Failsafe_size : 0u) +
                     (ack->refused_item ? 4u : 0u));
    /* A failsafe state goes only beside a ping echo or nothing (a liveness message's Ack):
     * refused beside another result, whatever the bound of this build admits (the Mega's,
     * sized by ReadOutputs' 24 servos, would hold DeviceInfo and a failsafe state). */
    bool shape = !ack->has_failsafe || ack->which_result == 0 ||
                 ack->which_result == protoduino_Ack_ping_echo_tag;
    if (!shape || 8u + need > PD_ENCODE_ACK_MAX) {
        w->ok = false;
        return;
    }
    put_uint(w, protoduino_Ack_message_id_tag, ack->message_id);
    put_uint(w, protoduino_Ack_status_tag, (uint32_t)ack->status);
    if (ack->which_result == protoduino_Ack_ping_echo_tag) {
        if (ack->result.ping_echo.size > sizeof(ack->result.ping_echo.bytes)) {
            w->ok = false;
            return;
        }
        put_bytes(w, protoduino_Ack_ping_echo_tag, ack->result.ping_echo.bytes,
                  ack->result.ping_echo.size);
    } else if (ack->which_result == protoduino_Ack_info_tag) {
        uint8_t *at = open_msg(w, protoduino_Ack_info_tag);
        put_info(w, &ack->result.info);
        close_msg(w, at);
    }
    /* Field 5 sits between the oneof's members 3/4 and 30, in field order as
     * pb_encode writes them. */
    if (ack->has_failsafe) {
        put_failsafe(w, protoduino_Ack_failsafe_tag, &ack->failsafe);
    }
#if PD_FEATURE_USER
    /* Fields 6 and 7, before 30: a UserCall's reply (always written when set,
     * even empty: the set member of a oneof) and its handler's code. */
    if (ack->which_result == protoduino_Ack_user_reply_tag) {
        if (ack->result.user_reply.size > sizeof(ack->result.user_reply.bytes)) {
            w->ok = false;
            return;
        }
        put_bytes(w, protoduino_Ack_user_reply_tag, ack->result.user_reply.bytes,
                  ack->result.user_reply.size);
    }
    put_uint(w, protoduino_Ack_user_code_tag, ack->user_code);
#endif
    if (ack->which_result == protoduino_Ack_outputs_tag) {
        const protoduino_OutputStates *st = &ack->result.outputs;
        uint8_t *at = open_msg(w, protoduino_Ack_outputs_tag);
        if (st->servos.funcs.encode != NULL) { /* omitted when empty, as pb_encode does */
            pd_encode_servos_fn *write = pd_encode_servos_get(&st->servos);
            uint8_t *servos = open_msg(w, protoduino_OutputStates_servos_tag);
            w->p = write(st->servos.arg, w->p);
            close_msg(w, servos); /* at most 5 * PD_MAX_SERVOS: one length byte */
            if (*servos == 0) {
                w->p = servos - 1;
            }
        }
        PUT_PINSET(w, protoduino_OutputStates_digital_pins_tag, st->digital_pins);
        PUT_PINSET(w, protoduino_OutputStates_digital_levels_tag, st->digital_levels);
        PUT_PINSET(w, protoduino_OutputStates_pwm_pins_tag, st->pwm_pins);
        if (st->pwm_duties_count > sizeof(st->pwm_duties)) {
            w->ok = false;
        } else if (st->pwm_duties_count > 0) {
            uint8_t *duties = open_msg(w, protoduino_OutputStates_pwm_duties_tag); /* packed */
            for (pb_size_t i = 0; i < st->pwm_duties_count; i++) {
                put_varint(w, st->pwm_duties[i]);
            }
            close_msg(w, duties);
        }
        close_msg(w, at);
    }
    put_uint(w, protoduino_Ack_refused_item_tag, ack->refused_item);
}

size_t pd_encode_out(const protoduino_ArduinoOut *msg, uint8_t *buf, size_t cap)
{
    writer_t w = {buf, true};
    uint8_t *at;

    if (cap < PD_ENCODE_MAX) {
        return 0; /* the largest message might not fit: see writer_t */
    }
    switch (msg->which_data) {
    case protoduino_ArduinoOut_ack_tag:
        at = open_msg(&w, protoduino_ArduinoOut_ack_tag);
        put_ack(&w, &msg->data.ack);
        close_msg(&w, at);
        break;
    case protoduino_ArduinoOut_failsafe_tag:
        put_failsafe(&w, protoduino_ArduinoOut_failsafe_tag, &msg->data.failsafe);
        break;
    case protoduino_ArduinoOut_ack_ok_tag: /* a oneof's set member: written even when 0 */
        put_tag(&w, protoduino_ArduinoOut_ack_ok_tag, WT_VARINT);
        put_varint(&w, msg->data.ack_ok);
        break;
    case protoduino_ArduinoOut_input_report_tag:
        at = open_msg(&w, protoduino_ArduinoOut_input_report_tag);
        put_report(&w, &msg->data.input_report);
        close_msg(&w, at);
        break;
    case protoduino_ArduinoOut_decode_error_tag:
        at = open_msg(&w, protoduino_ArduinoOut_decode_error_tag);
        put_uint(&w, protoduino_DecodeError_count_tag, msg->data.decode_error.count);
        close_msg(&w, at);
        break;
#if PD_FEATURE_USER
    case protoduino_ArduinoOut_user_report_tag:
        at = open_msg(&w, protoduino_ArduinoOut_user_report_tag);
        put_uint(&w, protoduino_UserReport_report_tag, msg->data.user_report.report);
        if (msg->data.user_report.body.size > sizeof(msg->data.user_report.body.bytes)) {
            w.ok = false;
        } else if (msg->data.user_report.body.size > 0) {
            put_bytes(&w, protoduino_UserReport_body_tag, msg->data.user_report.body.bytes,
                      msg->data.user_report.body.size);
        }
        put_uint(&w, protoduino_UserReport_coalesced_tag, msg->data.user_report.coalesced);
        close_msg(&w, at);
        break;
#endif
    default:
        break; /* no member set: the empty message */
    }
    return w.ok ? (size_t)(w.p - buf) : 0;
}

#include "test_util.h"

#include <stdlib.h>
#include <string.h>

#include <pb_decode.h>
#include <pb_encode.h>

#include "pd_cobs.h"
#include "pd_packet.h"

void t_boot(tdev_t *d)
{
    memset(d, 0, sizeof(*d));
    fake_init(&d->hal);
    d->hal.now_ms = 1000;
    pd_core_init(&d->core, &d->hal);
}

void t_active(tdev_t *d)
{
    t_boot(d);
    t_send_reset(d, PD_PROTOCOL_VERSION);
    fake_clear(&d->hal);
}

void t_feed(tdev_t *d, const uint8_t *bytes, size_t len)
{
    for (size_t i = 0; i < len; i++) {
        pd_core_rx_byte(&d->core, bytes[i]);
    }
}

static size_t wire_packet(uint8_t type, uint8_t seq, const uint8_t *payload, size_t len,
                          uint8_t wire[PD_MAX_ENCODED_FRAME + 1])
{
    uint8_t raw[PD_MIN_PACKET + PD_MAX_PAYLOAD];
    size_t raw_len = 0;

    if (pd_packet_build(type, seq, payload, len, raw, sizeof(raw), &raw_len) != PD_PACKET_OK) {
        abort();
    }
    size_t n = pd_cobs_encode(raw, raw_len, wire, PD_MAX_ENCODED_FRAME);
    if (n == 0) {
        abort();
    }
    wire[n++] = 0;
    return n;
}

void t_send_packet(tdev_t *d, uint8_t type, uint8_t seq, const uint8_t *payload, size_t len)
{
    uint8_t wire[PD_MAX_ENCODED_FRAME + 1];
    t_feed(d, wire, wire_packet(type, seq, payload, len, wire));
}

void t_send_reset(tdev_t *d, uint8_t version)
{
    if (version == PD_PROTOCOL_VERSION) {
        t_send_reset_session(d, T_SESSION);
        return;
    }
    /* Another version: the shape version 1 used (CODE VERSION). */
    const uint8_t payload[2] = {PD_CONTROL_RESET, version};
    const uint8_t flush = 0;
    t_feed(d, &flush, 1);
    t_send_packet(d, PD_PACKET_CONTROL, 0, payload, sizeof(payload));
    d->host_seq = 1;
}

void t_send_reset_session(tdev_t *d, uint32_t session)
{
    /* The id after the newest one sent, as a host's RESET carries it. */
    t_send_reset_next(d, session, (uint8_t)(d->last_id % PD_MAX_MESSAGE_ID + 1u));
}

void t_send_reset_next(tdev_t *d, uint32_t session, uint8_t next_id)
{
    const uint8_t payload[PD_RESET_SIZE] = {
        PD_CONTROL_RESET,         PD_PROTOCOL_VERSION,     (uint8_t)(session >> 24),
        (uint8_t)(session >> 16), (uint8_t)(session >> 8), (uint8_t)session,
        next_id,
    };
    const uint8_t flush = 0;
    t_feed(d, &flush, 1);
    t_send_packet(d, PD_PACKET_CONTROL, 0, payload, sizeof(payload));
    d->host_seq = 1;
}

size_t t_wire_in(tdev_t *d, const protoduino_ArduinoIn *in, uint8_t wire[PD_MAX_ENCODED_FRAME + 1])
{
    uint8_t buf[PD_MAX_PAYLOAD];
    pb_ostream_t s = pb_ostream_from_buffer(buf, sizeof(buf));
    if (!pb_encode(&s, protoduino_ArduinoIn_fields, in)) {
        abort();
    }
    size_t n = wire_packet(PD_PACKET_COMMAND, d->host_seq++, buf, s.bytes_written, wire);
    if (in->message_id >= 1u && in->message_id <= PD_MAX_MESSAGE_ID) {
        uint32_t ahead = (in->message_id + PD_MAX_MESSAGE_ID - (d->last_id ? d->last_id : PD_MAX_MESSAGE_ID)) %
                         PD_MAX_MESSAGE_ID;
        if (ahead >= 1u && ahead <= PD_ID_AHEAD_MAX) {
            d->last_id = (uint8_t)in->message_id;
        }
    }
    return n;
}

void t_send_in(tdev_t *d, const protoduino_ArduinoIn *in)
{
    uint8_t wire[PD_MAX_ENCODED_FRAME + 1];
    t_feed(d, wire, t_wire_in(d, in, wire));
}

bool t_out(const tdev_t *d, size_t i, protoduino_ArduinoOut *out)
{
    const fake_frame_t *f = fake_frame(&d->hal, i);
    if (!f || f->type != PD_PACKET_DATA) {
        return false;
    }
    /* An Ack's OutputStates.servos: the last decoded (the callback's arg points here). */
    static fake_servos_t servos;
    if (!fake_decode_out(f->payload, f->len, out, &servos)) {
        return false;
    }
    if (out->which_data == protoduino_ArduinoOut_ack_ok_tag) {
        /* The short Ack is the Ack of that id with STATUS_OK and nothing else, as a host reads it. */
        uint32_t id = out->data.ack_ok;
        memset(out, 0, sizeof(*out));
        out->which_data = protoduino_ArduinoOut_ack_tag;
        out->data.ack.message_id = id;
    }
    return true;
}

int t_acks(const tdev_t *d, uint32_t id, protoduino_Ack *ack)
{
    int n = 0;
    protoduino_ArduinoOut out;
    for (size_t i = 0; i < fake_count(&d->hal); i++) {
        if (t_out(d, i, &out) && out.which_data == protoduino_ArduinoOut_ack_tag &&
            out.data.ack.message_id == id) {
            n++;
            if (ack) {
                *ack = out.data.ack;
            }
        }
    }
    return n;
}

int t_status(const tdev_t *d, uint32_t id)
{
    protoduino_Ack ack;
    return t_acks(d, id, &ack) == 1 ? (int)ack.status : -1;
}

int t_events(const tdev_t *d, uint8_t code)
{
    int n = 0;
    for (size_t i = 0; i < fake_count(&d->hal); i++) {
        const fake_frame_t *f = fake_frame(&d->hal, i);
        if (f->type == PD_PACKET_CONTROL && f->len >= 2 && f->payload[0] == PD_CONTROL_EVENT &&
            f->payload[1] == code) {
            n++;
        }
    }
    return n;
}

int t_failsafes(const tdev_t *d, protoduino_Failsafe *fs)
{
    int n = 0;
    protoduino_ArduinoOut out;
    for (size_t i = 0; i < fake_count(&d->hal); i++) {
        if (t_out(d, i, &out) && out.which_data == protoduino_ArduinoOut_failsafe_tag) {
            n++;
            if (fs) {
                *fs = out.data.failsafe;
            }
        }
    }
    return n;
}

int t_cmd(tdev_t *d, const protoduino_ArduinoIn *in)
{
    fake_clear(&d->hal);
    t_send_in(d, in);
    return t_status(d, in->message_id);
}

static protoduino_ArduinoIn m_new(uint32_t id, pb_size_t which)
{
    protoduino_ArduinoIn in = protoduino_ArduinoIn_init_zero;
    in.message_id = id;
    in.which_data = which;
    return in;
}

protoduino_ArduinoIn m_ping(uint32_t id, const uint8_t *payload, size_t len)
{
    protoduino_ArduinoIn in = m_new(id, protoduino_ArduinoIn_ping_tag);
    in.data.ping.payload.size = (pb_size_t)len;
    if (len) {
        memcpy(in.data.ping.payload.bytes, payload, len);
    }
    return in;
}

protoduino_ArduinoIn m_servo_init_deg(uint32_t id, uint32_t pin, uint32_t min_us, uint32_t max_us,
                                      uint32_t safe_degrees)
{
    protoduino_ArduinoIn in = m_new(id, protoduino_ArduinoIn_servo_init_tag);
    in.data.servo_init.pin = pin;
    in.data.servo_init.min_us = min_us;
    in.data.servo_init.max_us = max_us;
    in.data.servo_init.which_safe = protoduino_ServoInit_safe_degrees_tag;
    in.data.servo_init.safe.safe_degrees = safe_degrees;
    return in;
}

protoduino_ArduinoIn m_servo_init_us(uint32_t id, uint32_t pin, uint32_t min_us, uint32_t max_us,
                                     uint32_t safe_us)
{
    protoduino_ArduinoIn in = m_servo_init_deg(id, pin, min_us, max_us, 0);
    in.data.servo_init.which_safe = protoduino_ServoInit_safe_us_tag;
    in.data.servo_init.safe.safe_us = safe_us;
    return in;
}

protoduino_ArduinoIn m_servo_deg(uint32_t id, uint32_t pin, uint32_t degrees)
{
    protoduino_ArduinoIn in = m_new(id, protoduino_ArduinoIn_servo_control_tag);
    in.data.servo_control.pin = pin;
    in.data.servo_control.which_value = protoduino_ServoControl_degrees_tag;
    in.data.servo_control.value.degrees = degrees;
    return in;
}

protoduino_ArduinoIn m_servo_us(uint32_t id, uint32_t pin, uint32_t us)
{
    protoduino_ArduinoIn in = m_new(id, protoduino_ArduinoIn_servo_control_tag);
    in.data.servo_control.pin = pin;
    in.data.servo_control.which_value = protoduino_ServoControl_us_tag;
    in.data.servo_control.value.us = us;
    return in;
}

protoduino_ArduinoIn m_digital_init(uint32_t id, uint32_t pin, bool safe)
{
    protoduino_ArduinoIn in = m_new(id, protoduino_ArduinoIn_digital_init_tag);
    in.data.digital_init.pin = pin;
    in.data.digital_init.safe_level = safe;
    return in;
}

protoduino_ArduinoIn m_digital(uint32_t id, uint32_t pin, bool level)
{
    protoduino_ArduinoIn in = m_new(id, protoduino_ArduinoIn_digital_control_tag);
    in.data.digital_control.pin = pin;
    in.data.digital_control.level = level;
    return in;
}

protoduino_ArduinoIn m_stop(uint32_t id)
{
    return m_new(id, protoduino_ArduinoIn_stop_tag);
}

protoduino_ArduinoIn m_info(uint32_t id)
{
    return m_new(id, protoduino_ArduinoIn_get_info_tag);
}

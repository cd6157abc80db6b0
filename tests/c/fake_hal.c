#include "fake_hal.h"

#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <pb_decode.h>
#include <pb_encode.h>

#include "pd_cobs.h"
#include "pd_encode.h"
#include "pd_packet.h"

static void fake_abort(const char *why)
{
    fprintf(stderr, "fake_hal: malformed frame from the core: %s\n", why);
    abort();
}

/* A pin set of pins 0..31 (pd_pinset.h). */
static pd_pinset_t fake_set(uint32_t mask)
{
    pd_pinset_t set = {{0}};
    set.w[0] = mask;
    return set;
}

void fake_init(fake_hal_t *hal)
{
    /* Everything but the frame log (written before it is read): the fuzzer
     * calls this once per input, and clearing 16 KB each time halves its speed. */
    memset(hal, 0, offsetof(fake_hal_t, frames));
    memset(&hal->servo_us, 0, sizeof(*hal) - offsetof(fake_hal_t, servo_us));
    for (int pin = 0; pin < PD_MAX_PINS; pin++) {
        hal->servo_us[pin] = -1;
        hal->digital[pin] = -1;
        hal->pwm[pin] = -1;
        hal->input[pin] = -1;
        hal->counter_edge[pin] = -1;
    }
    hal->adc_pin = -1;
    hal->adc_polls = 1;
    hal->info.board = "fake";
    /* The Uno's (pd_avr_main.c). */
    hal->info.pwm_pins = fake_set((1UL << 3) | (1UL << 5) | (1UL << 6) | (1UL << 9) | (1UL << 10) | (1UL << 11));
    hal->info.analog_pins = fake_set(0x3FUL << 14);
    hal->info.servo_timer_pins = fake_set((1UL << 9) | (1UL << 10));
    hal->info.servo_timer = 1;
    hal->info.clock_timer = 0;
    hal->info.counter_pins = fake_set(0x3FFCUL);    /* 2..13, as the Uno */
    hal->info.pin_change_pins = fake_set(0x3FF0UL); /* 4..13: pin-change interrupts */
    hal->info.num_pins = 20;
    hal->info.max_servos = 8;
    hal->info.reserved_pins = fake_set(0x3);
    hal->info.rx_buffer = 127;
    hal->tx_room = UINT16_MAX;
}

void fake_clear(fake_hal_t *hal)
{
    hal->n_frames = 0;
}

size_t fake_count(const fake_hal_t *hal)
{
    return hal->n_frames < FAKE_MAX_FRAMES ? hal->n_frames : FAKE_MAX_FRAMES;
}

const fake_frame_t *fake_frame(const fake_hal_t *hal, size_t i)
{
    size_t kept = fake_count(hal);
    if (i >= kept) {
        return NULL;
    }
    size_t first = hal->n_frames - kept;
    return &hal->frames[(first + i) % FAKE_MAX_FRAMES];
}

uint16_t pd_hal_tx_room(void *ctx)
{
    return ((fake_hal_t *)ctx)->tx_room;
}

bool pd_hal_write(void *ctx, const uint8_t *data, uint16_t len)
{
    fake_hal_t *hal = ctx;
    if (len > hal->tx_room) {
        return false; /* all or nothing, as the HAL contract says */
    }
    uint8_t raw[PD_MAX_ENCODED_FRAME];
    bool flushed = false;
    pd_packet_t pkt;

    if (len > 0 && data[0] == 0) {
        flushed = true;
        data++;
        len--;
    }
    if (len < 2 || data[len - 1] != 0) {
        fake_abort("no delimiter");
    }
    if (memchr(data, 0, len - 1u) != NULL) {
        fake_abort("0x00 inside the frame");
    }
    if (len - 1u > PD_MAX_ENCODED_FRAME) {
        fake_abort("longer than MAX_ENCODED_FRAME");
    }
    int n = pd_cobs_decode(data, len - 1u, raw, sizeof(raw));
    if (n < 0) {
        fake_abort("not valid COBS");
    }
    if (pd_packet_parse(raw, (size_t)n, &pkt) != PD_PACKET_OK) {
        fake_abort("not a valid packet");
    }
    if (pkt.type == PD_PACKET_COMMAND) {
        fake_abort("the device sent a COMMAND");
    }
    if (pkt.type == PD_PACKET_DATA) {
        /* The core's own encoder must produce exactly what pb_encode would. */
        protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
        uint8_t canon[PD_MAX_PAYLOAD];
        pb_ostream_t os = pb_ostream_from_buffer(canon, sizeof(canon));
        fake_servos_t servos;
        bool decoded = fake_decode_out(pkt.payload, pkt.len, &out, &servos);
        if (decoded && out.which_data == protoduino_ArduinoOut_ack_tag &&
            out.data.ack.which_result == protoduino_Ack_info_tag) {
            /* The pin table is skipped by the decoder (callbacks): the board's. */
            fake_info_callbacks(&out.data.ack.result.info, hal);
        }
        if (!decoded ||
            !pb_encode(&os, protoduino_ArduinoOut_fields, &out) || os.bytes_written != pkt.len ||
            memcmp(canon, pkt.payload, pkt.len) != 0) {
            fake_abort("DATA payload is not nanopb's canonical ArduinoOut");
        }
    }
    if (hal->fail_writes) {
        return false;
    }
    fake_frame_t *f = &hal->frames[hal->n_frames % FAKE_MAX_FRAMES];
    f->type = pkt.type;
    f->seq = pkt.seq;
    f->len = pkt.len;
    f->flushed = flushed;
    memcpy(f->payload, pkt.payload, pkt.len);
    hal->n_frames++;
    return true;
}

uint32_t pd_hal_millis(void *ctx)
{
    return ((fake_hal_t *)ctx)->now_ms;
}

void pd_hal_servo_write(void *ctx, uint8_t channel, uint8_t pin, uint16_t us)
{
    fake_hal_t *hal = ctx;
    if (pin >= hal->info.num_pins || pd_pinset_has(&hal->info.reserved_pins, pin)) {
        fprintf(stderr, "fake_hal: servo on invalid pin %u\n", pin);
        abort();
    }
    if (channel >= hal->info.max_servos || us < 400 || us > 2600 || hal->digital[pin] >= 0) {
        fprintf(stderr, "fake_hal: bad servo write ch %u pin %u us %u\n", channel, pin, us);
        abort();
    }
    hal->servo_us[pin] = us;
    hal->servo_writes[pin]++;
    hal->written_at[pin] = ++hal->writes;
}

bool pd_hal_servo_pending(void *ctx)
{
    const fake_hal_t *hal = ctx;
    return hal->servo_pending;
}

void pd_hal_servo_hold(void *ctx, bool hold)
{
    fake_hal_t *hal = ctx;
    if (hal->servo_held == hold) {
        fprintf(stderr, "fake_hal: servo hold %d twice\n", hold);
        abort();
    }
    hal->servo_held = hold;
    hal->servo_holds += hold;
}

void pd_hal_digital_write(void *ctx, uint8_t pin, bool level)
{
    fake_hal_t *hal = ctx;
    if (pin >= hal->info.num_pins || pd_pinset_has(&hal->info.reserved_pins, pin) ||
        hal->servo_us[pin] > 0) {
        fprintf(stderr, "fake_hal: digital write on invalid pin %u\n", pin);
        abort();
    }
    hal->servo_us[pin] = -1; /* a detached servo's pin may become a digital output */
    hal->digital[pin] = level ? 1 : 0;
    hal->digital_writes[pin]++;
    hal->written_at[pin] = ++hal->writes;
}

void pd_hal_servo_detach(void *ctx, uint8_t channel, uint8_t pin)
{
    fake_hal_t *hal = ctx;
    if (pin >= hal->info.num_pins || channel >= hal->info.max_servos || hal->digital[pin] >= 0) {
        fprintf(stderr, "fake_hal: bad servo detach ch %u pin %u\n", channel, pin);
        abort();
    }
    hal->servo_us[pin] = 0; /* no pulses */
    hal->servo_writes[pin]++;
}

void pd_hal_digital_release(void *ctx, uint8_t pin)
{
    fake_hal_t *hal = ctx;
    if (pin >= hal->info.num_pins || hal->digital[pin] < 0) {
        fprintf(stderr, "fake_hal: release of pin %u, not a digital output\n", pin);
        abort();
    }
    hal->digital[pin] = -1;
    hal->digital_writes[pin]++;
}

void pd_hal_pwm_write(void *ctx, uint8_t pin, uint8_t duty)
{
    fake_hal_t *hal = ctx;
    if (pin >= hal->info.num_pins || !pd_pinset_has(&hal->info.pwm_pins, pin) ||
        hal->servo_us[pin] >= 0 || hal->digital[pin] >= 0) {
        fprintf(stderr, "fake_hal: PWM write on pin %u, not a free PWM pin\n", pin);
        abort();
    }
    hal->pwm[pin] = duty;
    hal->pwm_writes[pin]++;
    hal->written_at[pin] = ++hal->writes;
}

void pd_hal_pwm_release(void *ctx, uint8_t pin)
{
    fake_hal_t *hal = ctx;
    if (pin >= hal->info.num_pins || hal->pwm[pin] < 0) {
        fprintf(stderr, "fake_hal: release of pin %u, not a PWM output\n", pin);
        abort();
    }
    hal->pwm[pin] = -1;
    hal->pwm_writes[pin]++;
}

static void fake_input_pin(const fake_hal_t *hal, uint8_t pin, const char *what)
{
    if (pin >= hal->info.num_pins || (pd_pinset_has(&hal->info.reserved_pins, pin)) ||
        hal->digital[pin] >= 0 || hal->pwm[pin] >= 0 || hal->servo_us[pin] >= 0) {
        fprintf(stderr, "fake_hal: %s on pin %u, not free for an input\n", what, pin);
        abort();
    }
}

void pd_hal_input_config(void *ctx, uint8_t pin, bool pull_up)
{
    fake_hal_t *hal = ctx;
    fake_input_pin(hal, pin, "input config");
    hal->input[pin] = pull_up ? 1 : 0;
}

void pd_hal_input_release(void *ctx, uint8_t pin)
{
    fake_hal_t *hal = ctx;
    if (pin >= hal->info.num_pins || hal->input[pin] < 0 || hal->counter_edge[pin] >= 0) {
        fprintf(stderr, "fake_hal: release of pin %u, not an input (or still counting)\n", pin);
        abort();
    }
    hal->input[pin] = -1;
}

pd_pinset_t pd_hal_digital_read_all(void *ctx)
{
    fake_hal_t *hal = ctx;
    pd_pinset_t levels = {{0}};
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        pd_pinset_put(&levels, pin, hal->level[pin]);
    }
    hal->digital_reads++;
    return levels;
}

void pd_hal_analog_start(void *ctx, uint8_t pin)
{
    fake_hal_t *hal = ctx;
    if (hal->adc_pin >= 0 || pin >= PD_MAX_PINS || !pd_pinset_has(&hal->info.analog_pins, pin) ||
        hal->input[pin] < 0) {
        fprintf(stderr, "fake_hal: conversion of pin %u (one under way: %d)\n", pin, hal->adc_pin);
        abort();
    }
    hal->adc_pin = pin;
    hal->adc_left = hal->adc_polls;
    hal->conversions++;
}

bool pd_hal_analog_done(void *ctx, uint16_t *counts)
{
    fake_hal_t *hal = ctx;
    if (hal->adc_pin < 0) {
        fprintf(stderr, "fake_hal: no conversion under way\n");
        abort();
    }
    if (hal->adc_left > 1) {
        hal->adc_left--;
        return false;
    }
    *counts = hal->analog[hal->adc_pin];
    hal->adc_pin = -1;
    return true;
}

void pd_hal_counter_start(void *ctx, uint8_t pin, uint8_t edge)
{
    fake_hal_t *hal = ctx;
    if (pin >= PD_MAX_PINS || !pd_pinset_has(&hal->info.counter_pins, pin) || hal->input[pin] < 0) {
        fprintf(stderr, "fake_hal: counter on pin %u\n", pin);
        abort();
    }
    hal->counter_edge[pin] = edge;
    hal->count[pin] = 0;
}

uint32_t pd_hal_counter_read(void *ctx, uint8_t pin)
{
    fake_hal_t *hal = ctx;
    if (pin >= PD_MAX_PINS || hal->counter_edge[pin] < 0) {
        fprintf(stderr, "fake_hal: counter read on pin %u, not counting\n", pin);
        abort();
    }
    return hal->count[pin];
}

void pd_hal_counter_stop(void *ctx, uint8_t pin)
{
    fake_hal_t *hal = ctx;
    if (pin >= PD_MAX_PINS || hal->counter_edge[pin] < 0) {
        fprintf(stderr, "fake_hal: counter stop on pin %u, not counting\n", pin);
        abort();
    }
    hal->counter_edge[pin] = -1;
}

uint32_t pd_hal_boot_id(void *ctx)
{
    fake_hal_t *hal = ctx;
    return ++hal->boots;
}

uint8_t pd_hal_baud_rates(void *ctx)
{
    return ((fake_hal_t *)ctx)->baud_rates;
}

void pd_hal_set_baud(void *ctx, uint32_t baud)
{
    fake_hal_t *hal = ctx;
    hal->baud = baud;
    hal->baud_sets++;
}

void pd_hal_outputs_safe(void *ctx)
{
    fake_hal_t *hal = ctx;
    hal->outputs_safe_calls++;
}

const pd_board_info_t *pd_hal_board_info(void *ctx)
{
    return &((fake_hal_t *)ctx)->info;
}

/* field->message: the DeviceInfo (its num_pins: the table's length, its pins.arg: the HAL). */
static bool encode_pins(pb_ostream_t *s, const pb_field_t *field, void *const *arg)
{
    (void)arg;
    const protoduino_DeviceInfo *info = field->message;
    const pd_board_info_t *board = pd_hal_board_info(info->pins.arg);
    uint8_t bytes[256];
    for (uint8_t pin = 0; pin < info->num_pins; pin++) {
        bytes[pin] = pd_encode_pin(board, pin);
    }
    return info->num_pins == 0 ||
           (pb_encode_tag_for_field(s, field) && pb_encode_string(s, bytes, info->num_pins));
}

static bool encode_timers(pb_ostream_t *s, const pb_field_t *field, void *const *arg)
{
    (void)arg;
    const protoduino_DeviceInfo *info = field->message;
    const pd_board_info_t *board = pd_hal_board_info(info->pins.arg);
    uint8_t bytes[256];
    uint8_t n = info->num_pins == 0 ? 0 : pd_encode_timer_count(board);
    for (uint8_t timer = 0; timer < n; timer++) {
        bytes[timer] = pd_encode_timer(board, timer);
    }
    return n == 0 || (pb_encode_tag_for_field(s, field) && pb_encode_string(s, bytes, n));
}

void fake_info_callbacks(protoduino_DeviceInfo *info, fake_hal_t *hal)
{
    info->pins.arg = hal;
    info->pins.funcs.encode = encode_pins;
    info->timers.funcs.encode = encode_timers;
}

static bool decode_servos(pb_istream_t *s, const pb_field_t *field, void **arg)
{
    (void)field;
    fake_servos_t *servos = *arg;
    servos->size = s->bytes_left;
    return s->bytes_left <= sizeof(servos->bytes) &&
           pb_read(s, servos->bytes, s->bytes_left);
}

static bool encode_servos(pb_ostream_t *s, const pb_field_t *field, void *const *arg)
{
    const fake_servos_t *servos = *arg;
    return servos->size == 0 || (pb_encode_tag_for_field(s, field) &&
                                 pb_encode_string(s, servos->bytes, servos->size));
}

static bool encode_outputs_servos(pb_ostream_t *s, const pb_field_t *field, void *const *arg)
{
    const protoduino_OutputStates *device = *arg;
    pd_encode_servos_fn *write = pd_encode_servos_get(&device->servos);
    uint8_t bytes[5u * PD_MAX_SERVOS];
    size_t n = write == NULL ? 0 : (size_t)(write(device->servos.arg, bytes) - bytes);
    return n == 0 || (pb_encode_tag_for_field(s, field) && pb_encode_string(s, bytes, n));
}

void fake_outputs_callbacks(protoduino_OutputStates *st, const protoduino_OutputStates *device)
{
    st->servos.arg = (void *)(uintptr_t)device;
    st->servos.funcs.encode = encode_outputs_servos;
}

void fake_servos_callbacks(protoduino_OutputStates *st, fake_servos_t *servos)
{
    st->servos.arg = servos;
    st->servos.funcs.decode = decode_servos;
}

bool fake_decode_out(const uint8_t *payload, size_t len, protoduino_ArduinoOut *out,
                     fake_servos_t *servos)
{
    servos->size = 0;
    memset(out, 0, sizeof(*out));
    pb_istream_t s = pb_istream_from_buffer(payload, len);
    if (!pb_decode(&s, protoduino_ArduinoOut_fields, out)) {
        return false;
    }
    if (out->which_data == protoduino_ArduinoOut_ack_tag &&
        out->data.ack.which_result == protoduino_Ack_outputs_tag) {
        memset(out, 0, sizeof(*out));
        out->which_data = protoduino_ArduinoOut_ack_tag;
        out->data.ack.which_result = protoduino_Ack_outputs_tag;
        fake_servos_callbacks(&out->data.ack.result.outputs, servos);
        s = pb_istream_from_buffer(payload, len);
        if (!pb_decode_noinit(&s, protoduino_ArduinoOut_fields, out)) {
            return false;
        }
        out->data.ack.result.outputs.servos.funcs.encode = encode_servos;
    }
    return true;
}

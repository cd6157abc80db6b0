/*
 * Structure-aware libFuzzer target: what lies past the CRC.
 *
 * fuzz_rx.c feeds the fuzzer's bytes to the receive path as they are, so most
 * of its inputs die at the COBS or CRC check and few mutations of a command's
 * payload ever reach nanopb. Here the input is a script of operations, and the
 * harness frames each packet itself (right SEQ, CRC and COBS), so every
 * mutated payload is decoded and dispatched:
 *
 *   [op][len][len bytes] ...
 *   op & 7 = 0..3  a COMMAND packet with those bytes as its payload (an ArduinoIn)
 *            4     a CONTROL packet with those bytes as its payload
 *            5     the bytes as they are, straight into the receiver
 *            6     the clock moves on by len * 50 ms, the outside world moves the inputs
 *                  (a level, an analog value, a count, from len's bits), then a poll
 *                  (failsafe, reports, interlocks)
 *            7     the host's SEQ jumps by len (gaps and desyncs)
 *
 * The device is booted and handshaken (RESET) first. Checked after every
 * operation: at most one Ack per COMMAND packet; for every COMMAND payload,
 * that the short decode (pd_dispatch_decode_short), where it takes the payload,
 * leaves the ArduinoIn and the answer as nanopb's decode of the whole message
 * does (pd_dispatch_decode_full); and at the end the bounds
 * fuzz_rx.c checks. The fake HAL aborts on a malformed frame sent and on any
 * pin write outside the board's rules; ASan and UBSan catch the rest.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dedupe_sane.h"
#include "fake_hal.h"
#include "pd_cobs.h"
#include "pd_core.h"
#include "pd_dispatch.h"
#include "pd_packet.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* ArduinoOut's first byte when it carries an Ack: field 1, length-delimited. */
#define ACK_TAG 0x0Au

static void feed_packet(pd_core_t *core, uint8_t type, uint8_t seq, const uint8_t *payload,
                        size_t len)
{
    uint8_t raw[PD_MIN_PACKET + PD_MAX_PAYLOAD];
    uint8_t frame[PD_COBS_MAX_ENCODED(sizeof(raw))];
    size_t raw_len = 0;

    if (pd_packet_build(type, seq, payload, len, raw, sizeof(raw), &raw_len) != PD_PACKET_OK) {
        abort(); /* len <= 255 always fits */
    }
    size_t n = pd_cobs_encode(raw, raw_len, frame, sizeof(frame));
    for (size_t i = 0; i < n; i++) {
        pd_core_rx_byte(core, frame[i]);
    }
    pd_core_rx_byte(core, 0);
}

/* The short decode and the full one agree on `payload` (each from the same stale bytes). */
static void check_decodes_agree(const uint8_t *payload, size_t len)
{
    protoduino_ArduinoIn fast, full;
    memset(&fast, 0xA5, sizeof(fast));
    memset(&full, 0xA5, sizeof(full));
    int r = pd_dispatch_decode_short(&fast, payload, len);
    if (r < 0) {
        if (memcmp(&fast, &full, sizeof(fast)) != 0) {
            abort(); /* left to the full decode, yet written */
        }
        return;
    }
    bool ok = pd_dispatch_decode_full(&full, payload, len);
    if ((r == 1) != ok || memcmp(&fast, &full, sizeof(fast)) != 0) {
        abort();
    }
}

static size_t acks_sent(const fake_hal_t *hal)
{
    size_t acks = 0;
    for (size_t i = 0; i < fake_count(hal); i++) {
        const fake_frame_t *f = fake_frame(hal, i);
        if (f != NULL && f->type == PD_PACKET_DATA && f->len > 0 && f->payload[0] == ACK_TAG) {
            acks++;
        }
    }
    return acks;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static fake_hal_t hal;
    static pd_core_t core;
    static const uint8_t reset[PD_RESET_SIZE] = {PD_CONTROL_RESET, PD_PROTOCOL_VERSION, 0, 0, 0, 1, 1};
    uint8_t seq = 1;
    size_t i = 0;

    fake_init(&hal);
    hal.now_ms = 1;
    pd_core_init(&core, &hal);
    feed_packet(&core, PD_PACKET_CONTROL, 0, reset, sizeof(reset));
    if (!core.link.active) {
        abort();
    }
    while (i + 2 <= size) {
        uint8_t op = data[i] & 7u;
        size_t len = data[i + 1];
        i += 2;
        if (len > size - i) {
            len = size - i;
        }
        const uint8_t *arg = data + i;
        i += len;
        fake_clear(&hal);
        switch (op) {
        case 4:
            feed_packet(&core, PD_PACKET_CONTROL, seq++, arg, len);
            break;
        case 5:
            for (size_t k = 0; k < len; k++) {
                pd_core_rx_byte(&core, arg[k]);
            }
            break;
        case 6:
            hal.now_ms += (uint32_t)len * 50u;
            hal.level[len % PD_MAX_PINS] = !hal.level[len % PD_MAX_PINS];
            hal.analog[14u + len % 6u] = (uint16_t)(len * 4u);
            hal.count[2u + (len & 1u)] += (uint32_t)len;
            pd_core_poll(&core);
            break;
        case 7:
            seq = (uint8_t)(seq + len);
            break;
        default:
            check_decodes_agree(arg, len);
            feed_packet(&core, PD_PACKET_COMMAND, seq++, arg, len);
            if (acks_sent(&hal) > 1) {
                abort(); /* exactly one Ack per ArduinoIn, never two */
            }
            break;
        }
    }
    if (core.link.rx_len > PD_MAX_ENCODED_FRAME ||
        pd_pins_count(core.outputs.owner, PD_MODE_SERVO) > PD_MAX_SERVOS ||
        !dedupe_sane(&core.dedupe)) {
        abort();
    }
    /* Every pin of a mode with slots owns a slot of its own (the slot's pin is
     * the one whose owner byte names it), and a servo drives its pin within limits. */
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t owner = core.outputs.owner[pin];
        if (owner == 0) {
            continue;
        }
        for (uint8_t other = (uint8_t)(pin + 1u); other < PD_MAX_PINS; other++) {
            /* Digital outputs and a user service's pins are kept by pin, not by slot. */
            bool by_pin = PD_OWNER_MODE(owner) == PD_MODE_DIGITAL ||
                          (PD_FEATURE_USER && PD_OWNER_MODE(owner) == PD_MODE_USER);
            if (!by_pin && core.outputs.owner[other] == owner) {
                abort();
            }
        }
        if (PD_OWNER_MODE(owner) != PD_MODE_SERVO) {
            continue;
        }
        if (PD_OWNER_SLOT(owner) >= PD_MAX_SERVOS) {
            abort();
        }
        const pd_servo_t *s = &core.outputs.servo[PD_OWNER_SLOT(owner)];
        int us = hal.servo_us[pin];
        if (us != 0 && (us < s->min_us || us > s->max_us)) { /* 0: detached */
            abort();
        }
    }
    return 0;
}

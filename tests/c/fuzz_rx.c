/*
 * libFuzzer target on the whole receive path: bytes -> COBS frames -> packets
 * -> link state machine -> nanopb -> dispatch -> outputs/failsafe -> the frames
 * the device sends back.
 *
 * The first input byte picks the mode:
 *
 * - odd: raw. The rest goes byte by byte into a freshly booted device, as a
 *   UART delivers it; every 0x00 also advances the fake clock by 1.5 s and
 *   polls, so the failsafe runs too. This is where framing, COBS and packet
 *   checks are attacked.
 * - even: structured. Random mutations of raw frames nearly always break the
 *   CRC, so they rarely reach the layers above it. Here the rest is a list of
 *   records [hdr][len][len bytes of payload]; the harness frames each one
 *   properly (COBS, CRC) and feeds it. hdr bits 0-1: TYPE (3 = an invalid
 *   type); bits 2-4: SEQ skew (0 = in order); bits 5-7: clock advance in
 *   1.25 s steps before the next poll. Bit 1 of the mode byte skips the
 *   handshake, so COMMANDs meet an IDLE device.
 *
 * The fake HAL aborts on any malformed frame the device sends, on any DATA
 * payload that differs from nanopb's own encoding, and on any pin write
 * outside the board's rules; ASan and UBSan catch memory and arithmetic errors.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include "dedupe_sane.h"
#include "fake_hal.h"
#include "pd_cobs.h"
#include "pd_core.h"
#include "pd_packet.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void feed_packet(pd_core_t *core, uint8_t type, uint8_t seq, const uint8_t *payload,
                        size_t len)
{
    uint8_t raw[PD_MIN_PACKET + PD_MAX_PAYLOAD];
    uint8_t wire[PD_MAX_ENCODED_FRAME + 1];
    size_t raw_len = 0;

    if (pd_packet_build(type, seq, payload, len, raw, sizeof(raw), &raw_len) != PD_PACKET_OK) {
        abort();
    }
    size_t n = pd_cobs_encode(raw, raw_len, wire, sizeof(wire) - 1u);
    if (n == 0) {
        abort();
    }
    wire[n++] = 0;
    pd_core_rx(core, wire, n);
}

static void check_invariants(const fake_hal_t *hal, const pd_core_t *core)
{
    if (core->link.rx_len > PD_MAX_ENCODED_FRAME ||
        pd_pins_count(core->outputs.owner, PD_MODE_SERVO) > PD_MAX_SERVOS ||
        !dedupe_sane(&core->dedupe)) {
        abort();
    }
    /* Every pin of a mode with slots owns a slot of its own (the slot's pin is
     * the one whose owner byte names it), and a servo drives its pin within limits. */
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t owner = core->outputs.owner[pin];
        if (owner == 0) {
            continue;
        }
        for (uint8_t other = (uint8_t)(pin + 1u); other < PD_MAX_PINS; other++) {
            if (PD_OWNER_MODE(owner) != PD_MODE_DIGITAL && core->outputs.owner[other] == owner) {
                abort();
            }
        }
        if (PD_OWNER_MODE(owner) != PD_MODE_SERVO) {
            continue;
        }
        if (PD_OWNER_SLOT(owner) >= PD_MAX_SERVOS) {
            abort();
        }
        const pd_servo_t *s = &core->outputs.servo[PD_OWNER_SLOT(owner)];
        int us = hal->servo_us[pin];
        if ((us != 0 && (us < s->min_us || us > s->max_us)) ||
            (s->safe_us != PD_SERVO_SAFE_DETACH && (s->safe_us < s->min_us || s->safe_us > s->max_us))) {
            abort();
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static fake_hal_t hal;
    static pd_core_t core;

    if (size == 0) {
        return 0;
    }
    uint8_t mode = data[0];
    data++;
    size--;
    fake_init(&hal);
    hal.now_ms = 1;
    pd_core_init(&core, &hal);

    if (mode & 1u) {
        for (size_t i = 0; i < size; i++) {
            pd_core_rx_byte(&core, data[i]);
            if (data[i] == 0) {
                hal.now_ms += 1500;
                pd_core_poll(&core);
            }
        }
    } else {
        uint8_t seq = 0;
        if (!(mode & 2u)) {
            const uint8_t reset[PD_RESET_SIZE] = {PD_CONTROL_RESET, PD_PROTOCOL_VERSION, 0, 0, 0, 1, 1};
            feed_packet(&core, PD_PACKET_CONTROL, seq++, reset, sizeof(reset));
        }
        size_t i = 0;
        while (i + 2 <= size) {
            uint8_t hdr = data[i];
            size_t len = data[i + 1];
            i += 2;
            if (len > size - i) {
                len = size - i;
            }
            seq = (uint8_t)(seq + ((hdr >> 2) & 7u) * 37u); /* 0: in order; else a skew */
            feed_packet(&core, (uint8_t)(hdr & 3u) == 3u ? 0x7Fu : (uint8_t)(hdr & 3u), seq++,
                        data + i, len);
            i += len;
            hal.now_ms += (uint32_t)(hdr >> 5) * 1250u;
            pd_core_poll(&core);
        }
    }
    check_invariants(&hal, &core);
    return 0;
}

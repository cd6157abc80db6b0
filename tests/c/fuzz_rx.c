/*
 * libFuzzer target on the whole receive path: bytes -> COBS frames -> packets
 * -> link state machine -> nanopb -> dispatch -> outputs/failsafe -> the frames
 * the device sends back.
 *
 * The input goes byte by byte into a freshly booted device, exactly as a UART
 * delivers it. Every 0x00 also advances the fake clock by 1.5 s and polls, so
 * the failsafe paths run too. The fake HAL aborts on any malformed frame the
 * device sends and on any pin write outside the board's rules (invalid or
 * reserved pin, servo pulse outside 400..2600 us, a pin in two modes), and
 * ASan/UBSan catch memory and arithmetic errors.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include "fake_hal.h"
#include "pd_core.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static fake_hal_t hal;
    static pd_core_t core;

    fake_init(&hal);
    hal.now_ms = 1;
    pd_core_init(&core, &hal);
    for (size_t i = 0; i < size; i++) {
        pd_core_rx_byte(&core, data[i]);
        if (data[i] == 0) {
            hal.now_ms += 1500;
            pd_core_poll(&core);
        }
    }
    /* Invariants that must hold whatever came in. */
    if (core.link.rx_len > PD_MAX_ENCODED_FRAME || core.outputs.servo_count > PD_MAX_SERVOS ||
        core.dedupe.count > PD_DEDUPE_WINDOW) {
        abort();
    }
    for (uint8_t ch = 0; ch < core.outputs.servo_count; ch++) {
        const pd_servo_t *s = &core.outputs.servo[ch];
        int us = hal.servo_us[s->pin];
        if (us < s->min_us || us > s->max_us || s->safe_us < s->min_us ||
            s->safe_us > s->max_us || core.outputs.pin_mode[s->pin] != PD_PIN_SERVO + ch) {
            abort();
        }
    }
    return 0;
}

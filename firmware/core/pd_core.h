/*
 * The device as one value: link, dedupe window, outputs and failsafe, with no
 * globals, so the unit tests and the fuzzer can instantiate as many as they
 * like. The platform's main loop calls pd_core_init() once at power-up, then
 * pd_core_rx() with every received byte and pd_core_poll() often (at least
 * every few milliseconds: the failsafe is checked there).
 */
#ifndef PD_CORE_H
#define PD_CORE_H

#include <stddef.h>
#include <stdint.h>

#include "pd_dispatch.h"
#include "pd_failsafe.h"
#include "pd_hal.h"
#include "pd_link.h"
#include "pd_outputs.h"
#include "pd_protocol.h"

/* Reported in DeviceInfo.firmware_version; follows the Python package's version. */
#define PD_FIRMWARE_VERSION "0.1.0"

typedef struct pd_core {
    void *hal; /* handed back to every pd_hal_* call */
    pd_link_t link;
    pd_dedupe_t dedupe;
    pd_outputs_t outputs;
    pd_failsafe_t failsafe;
    uint32_t decode_errors; /* COMMAND payloads that did not decode, since boot */
} pd_core_t;

/* Power-up state: nothing configured, link IDLE; sends EVENT BOOT. */
void pd_core_init(pd_core_t *core, void *hal);

static inline void pd_core_rx_byte(pd_core_t *core, uint8_t byte)
{
    pd_link_rx_byte(core, byte);
}

void pd_core_rx(pd_core_t *core, const uint8_t *data, size_t len);

/* Periodic work: the failsafe timer. */
void pd_core_poll(pd_core_t *core);

/* Every configured output to its safe value, flag set, event sent (Stop, timeout). */
void pd_core_enter_safe(pd_core_t *core, protoduino_FailsafeCause cause);

#endif /* PD_CORE_H */

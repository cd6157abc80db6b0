/*
 * The blinker's handlers (docs/services.md): the generated blinker_service.h
 * declares them. Pins and time only through pd_hal.h, so the same code runs on
 * the simulated board and on the Uno; the toggling is done in the poll hook,
 * not in a handler, which only checks and records.
 */
#include "blinker_service.h"

static struct {
    bool on;         /* blinking */
    bool level;      /* the level driven now */
    uint8_t pin;
    uint16_t half_ms;
    uint32_t next;   /* pd_hal_millis() of the next toggle */
    uint32_t toggles;
} blink;

uint8_t blinker_start_blink(pd_user_ctx_t *ctx, const blinker_Blink *request,
                            blinker_Blinking *reply)
{
    if (request->period_ms < 20u || request->period_ms > 60000u) {
        return blinker_BlinkerError_BLINKER_ERROR_BAD_PERIOD;
    }
    if (request->pin > 255u) {
        return blinker_BlinkerError_BLINKER_ERROR_PIN_UNAVAILABLE;
    }
    uint8_t pin = (uint8_t)request->pin;
    if (blink.on && blink.pin != pin) {
        return blinker_BlinkerError_BLINKER_ERROR_BUSY;
    }
    /* In the pin table like any output: a servo or a digital output there refuses it. */
    if (!pd_user_owns(ctx, pin) && pd_user_claim(ctx, pin) != protoduino_Status_STATUS_OK) {
        return blinker_BlinkerError_BLINKER_ERROR_PIN_UNAVAILABLE;
    }
    blink.pin = pin;
    blink.half_ms = (uint16_t)(request->period_ms / 2u);
    blink.on = true;
    blink.level = true;
    blink.toggles++;
    pd_hal_digital_write(ctx->hal, pin, true);
    blink.next = pd_hal_millis(ctx->hal) + blink.half_ms;
    reply->pin = pin;
    reply->half_ms = blink.half_ms;
    return 0;
}

uint8_t blinker_stop_blink(pd_user_ctx_t *ctx, const blinker_Empty *request, blinker_Toggles *reply)
{
    (void)request;
    if (blink.on) {
        blink.on = false;
        if (blink.level) {
            blink.level = false;
            blink.toggles++;
        }
        pd_hal_digital_write(ctx->hal, blink.pin, false);
    }
    reply->count = blink.toggles;
    reply->on = false;
    return 0;
}

uint8_t blinker_count(pd_user_ctx_t *ctx, const blinker_Empty *request, blinker_Toggles *reply)
{
    (void)ctx;
    (void)request;
    reply->count = blink.toggles;
    reply->on = blink.on;
    return 0;
}

bool blinker_stopped(pd_user_ctx_t *ctx, blinker_Toggles *report)
{
    (void)ctx;
    report->count = blink.toggles;
    report->on = blink.on;
    return true;
}

/* The failsafe, Stop or an interlock: low, no more toggling until started again, and
 * the host told so (a Stopped report). */
void blinker_safe(pd_user_ctx_t *ctx, uint8_t pin)
{
    if (pin == blink.pin) {
        bool was_on = blink.on;
        blink.on = false;
        if (blink.level) {
            blink.level = false;
            blink.toggles++;
        }
        if (was_on) {
            blinker_publish_stopped(ctx);
        }
    }
    pd_hal_digital_write(ctx->hal, pin, false);
}

void blinker_release(pd_user_ctx_t *ctx, uint8_t pin)
{
    if (pin == blink.pin) {
        blink.on = false;
        blink.level = false;
    }
    pd_hal_digital_release(ctx->hal, pin);
}

void blinker_poll(pd_user_ctx_t *ctx, uint32_t now_ms)
{
    if (blink.on && (int32_t)(now_ms - blink.next) >= 0 && pd_user_owns(ctx, blink.pin)) {
        blink.level = !blink.level;
        blink.toggles++;
        pd_hal_digital_write(ctx->hal, blink.pin, blink.level);
        blink.next += blink.half_ms;
    }
}

/*
 * The toggler's handler and hooks: the poll hook makes the level changes, each
 * 1, 2 or 3 ms (in turn) after the one before on pd_hal_millis().
 */
#include "toggler_service.h"

static struct {
    uint8_t pin;
    bool level;
    uint32_t left; /* level changes still to make */
    uint32_t made;
    uint32_t next; /* pd_hal_millis() of the next one */
} run;

uint8_t toggler_start(pd_user_ctx_t *ctx, const toggler_Run *request, toggler_Started *reply)
{
    if (request->pin > 255u || request->edges == 0u) {
        return toggler_TogglerError_TOGGLER_ERROR_PIN_UNAVAILABLE;
    }
    uint8_t pin = (uint8_t)request->pin;
    if (!pd_user_owns(ctx, pin) && pd_user_claim(ctx, pin) != protoduino_Status_STATUS_OK) {
        return toggler_TogglerError_TOGGLER_ERROR_PIN_UNAVAILABLE;
    }
    run.pin = pin;
    run.level = true;
    run.made = 1u;
    run.left = request->edges - 1u;
    pd_hal_digital_write(ctx->hal, pin, true);
    run.next = pd_hal_millis(ctx->hal) + 1u;
    reply->pin = pin;
    return 0;
}

void toggler_safe(pd_user_ctx_t *ctx, uint8_t pin)
{
    if (pin == run.pin) {
        run.left = 0u;
    }
    pd_hal_digital_write(ctx->hal, pin, false);
}

void toggler_release(pd_user_ctx_t *ctx, uint8_t pin)
{
    if (pin == run.pin) {
        run.left = 0u;
    }
    pd_hal_digital_release(ctx->hal, pin);
}

void toggler_poll(pd_user_ctx_t *ctx, uint32_t now_ms)
{
    if (run.left > 0u && (int32_t)(now_ms - run.next) >= 0) {
        run.level = !run.level;
        run.left--;
        run.made++;
        pd_hal_digital_write(ctx->hal, run.pin, run.level);
        run.next += 1u + run.made % 3u; /* gaps of 1, 2, 3, 1, ... ms */
    }
}

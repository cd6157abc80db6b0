/*
 * The button counter's handlers (docs/services.md): the handler claims the pin
 * and configures it; the poll hook debounces it and publishes each change as a
 * Changes report, built when it can go out (newest wins); Unwatch releases the pin.
 */
#include "presses_service.h"

static struct {
    bool watching;
    bool level;     /* debounced */
    bool raw;       /* last read */
    uint8_t pin;
    uint8_t debounce_ms;
    uint32_t since; /* pd_hal_millis() the raw level last changed */
    uint32_t count;
    uint32_t time_ms;
} button;

static void fill(presses_Press *press)
{
    press->count = button.count;
    press->level = button.level;
    press->time_ms = button.time_ms;
}

uint8_t presses_watch_button(pd_user_ctx_t *ctx, const presses_Watch *request,
                             presses_Press *reply)
{
    if (request->debounce_ms > 255u) {
        return presses_PressesError_PRESSES_ERROR_BAD_DEBOUNCE;
    }
    if (request->pin > 255u || (!pd_user_owns(ctx, (uint8_t)request->pin) &&
                                pd_user_claim(ctx, (uint8_t)request->pin) != protoduino_Status_STATUS_OK)) {
        return presses_PressesError_PRESSES_ERROR_PIN_UNAVAILABLE;
    }
    button.pin = (uint8_t)request->pin;
    button.debounce_ms = (uint8_t)request->debounce_ms;
    pd_hal_input_config(ctx->hal, button.pin, true);
    pd_pinset_t levels = pd_hal_digital_read_all(ctx->hal);
    button.raw = pd_pinset_has(&levels, button.pin);
    button.level = button.raw;
    button.since = pd_hal_millis(ctx->hal);
    button.time_ms = button.since;
    button.count = 0;
    button.watching = true;
    fill(reply);
    return 0;
}

uint8_t presses_total(pd_user_ctx_t *ctx, const presses_Empty *request, presses_Press *reply)
{
    (void)ctx;
    (void)request;
    fill(reply);
    return 0;
}

bool presses_changes(pd_user_ctx_t *ctx, presses_Press *report)
{
    (void)ctx;
    fill(report);
    return button.watching;
}

uint8_t presses_unwatch(pd_user_ctx_t *ctx, const presses_Empty *request, presses_Press *reply)
{
    (void)request;
    fill(reply);
    if (button.watching) {
        (void)pd_user_release(ctx, button.pin); /* presses_release below does the rest */
    }
    return 0;
}

/* An input has no safe state: the failsafe leaves it as it is. */
void presses_safe(pd_user_ctx_t *ctx, uint8_t pin)
{
    (void)ctx;
    (void)pin;
}

void presses_release(pd_user_ctx_t *ctx, uint8_t pin)
{
    if (pin == button.pin) {
        button.watching = false;
    }
    pd_hal_input_release(ctx->hal, pin);
}

void presses_poll(pd_user_ctx_t *ctx, uint32_t now_ms)
{
    if (!button.watching || !pd_user_owns(ctx, button.pin)) {
        return;
    }
    pd_pinset_t levels = pd_hal_digital_read_all(ctx->hal);
    bool raw = pd_pinset_has(&levels, button.pin);
    if (raw != button.raw) {
        button.raw = raw;
        button.since = now_ms;
    }
    if (raw != button.level && now_ms - button.since >= button.debounce_ms) {
        button.level = raw;
        button.time_ms = now_ms;
        if (!raw) {
            button.count++; /* pressed: pulled to ground */
        }
        presses_publish_changes(ctx);
    }
}

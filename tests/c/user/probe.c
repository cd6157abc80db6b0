/* The probe service's handlers (tests/c/test_user.c reads what they record). */
#include "probe.h"

#include <string.h>

probe_record_t probe_record;

uint8_t probe_echo(pd_user_ctx_t *ctx, const probe_Req *request, probe_Rep *reply)
{
    probe_record.echoes++;
    if (request->value == 0) {
        return probe_ProbeError_PROBE_ERROR_REFUSED;
    }
    if (request->value % 2u == 0) {
        probe_record.level = request->value; /* an even value is a new Level report */
        pd_user_publish(ctx, 4u);
    }
    reply->value = request->value + 1u;
    reply->blob.size = request->blob.size;
    memcpy(reply->blob.bytes, request->blob.bytes, request->blob.size);
    return 0;
}

uint8_t probe_peek(pd_user_ctx_t *ctx, const probe_Empty *request, probe_Rep *reply)
{
    (void)ctx;
    (void)request;
    probe_record.peeks++;
    reply->value = probe_record.echoes;
    return 0;
}

uint8_t probe_claim(pd_user_ctx_t *ctx, const probe_Req *request, probe_Rep *reply)
{
    reply->value = (uint32_t)pd_user_claim(ctx, (uint8_t)request->value);
    if (reply->value == protoduino_Status_STATUS_OK) {
        pd_hal_digital_write(ctx->hal, (uint8_t)request->value, true);
    }
    return 0;
}

/* A handler that leaves its reply beyond the bounds nanopb encodes: each string without
 * room for its terminator, a count and a size larger than their arrays. It ran all the
 * same (the count), and its reply reaches the host within the bounds. */
uint8_t probe_overfill(pd_user_ctx_t *ctx, const probe_Empty *request, probe_Label *reply)
{
    (void)ctx;
    (void)request;
    probe_record.overfills++;
    memset(reply->text, 'x', sizeof(reply->text));
    for (pb_size_t i = 0; i < sizeof(reply->values) / sizeof(reply->values[0]); i++) {
        reply->values[i] = i + 1u;
    }
    reply->values_count = 200;
    reply->has_tag = true;
    memset(reply->tag.text, 'y', sizeof(reply->tag.text));
    memset(reply->tag.blob.bytes, 'z', sizeof(reply->tag.blob.bytes));
    reply->tag.blob.size = 200;
    return 0;
}

bool probe_level(pd_user_ctx_t *ctx, probe_Rep *report)
{
    (void)ctx;
    report->value = probe_record.level;
    report->blob.size = probe_record.report_blob; /* past its 40 B when a test says so */
    memset(report->blob.bytes, 'r', sizeof(report->blob.bytes));
    return probe_record.level != 0;
}

void probe_safe(pd_user_ctx_t *ctx, uint8_t pin)
{
    probe_record.safe_pins |= 1ul << pin;
    pd_hal_digital_write(ctx->hal, pin, false);
}

void probe_release(pd_user_ctx_t *ctx, uint8_t pin)
{
    probe_record.released_pins |= 1ul << pin;
    pd_hal_digital_release(ctx->hal, pin);
}

void probe_poll(pd_user_ctx_t *ctx, uint32_t now_ms)
{
    (void)ctx;
    probe_record.polled_at = now_ms;
}

#include "pd_user.h"

#if PD_FEATURE_USER

#include <stddef.h>
#include <string.h>

#include <pb_common.h>
#include <pb_decode.h>
#include <pb_encode.h>

#include "pd_pintable.h"
#include "pd_state.h"

/* The method `method` (1..), or NULL. */
static const pd_user_method_t *method_of(uint8_t method)
{
    if (method == 0 || method > pd_user_service.method_count) {
        return NULL;
    }
    return &pd_user_service.methods[method - 1u];
}

/* Report method `method`'s bit among the service's reports (PD_USER_MAX_REPORTS: none). */
static uint8_t report_bit(uint8_t method)
{
    uint8_t bit = 0;
    for (uint8_t i = 1; i < method; i++) {
        if (pd_user_service.methods[i - 1u].report != NULL) {
            bit++;
        }
    }
    const pd_user_method_t *m = method_of(method);
    return (m != NULL && m->report != NULL) ? bit : PD_USER_MAX_REPORTS;
}

static uint8_t method_of_bit(uint8_t bit)
{
    for (uint8_t i = 1; i <= pd_user_service.method_count; i++) {
        if (pd_user_service.methods[i - 1u].report != NULL && bit-- == 0) {
            return i;
        }
    }
    return 0;
}

/*
 * A reply or report as the handler left it, brought within the bounds nanopb encodes, so
 * that its encoding cannot fail (docs/services.md, *What a user call guarantees*): nanopb
 * refuses a string with no terminator within its array, a bytes field's size or a repeated
 * field's count beyond its array, and nothing else a message within the 64 B can hold. So a
 * string ends at its last byte at the latest, a size or a count is at most its array's,
 * in every submessage present (the active member of a oneof). Recursion: one level per
 * nesting level, which the generator bounds (servicegen.MAX_USER_DEPTH).
 */
static void bound_message(const pb_msgdesc_t *desc, void *msg)
{
    pb_field_iter_t f;
    if (!pb_field_iter_begin(&f, desc, msg)) {
        return; /* no fields */
    }
    do {
        pb_size_t count = 1;
        if (PB_HTYPE(f.type) == PB_HTYPE_ONEOF && *(const pb_size_t *)f.pSize != f.tag) {
            continue; /* not the member the oneof holds */
        }
        if (PB_HTYPE(f.type) == PB_HTYPE_REPEATED) {
            pb_size_t *n = (pb_size_t *)f.pSize; /* a fixed count's is array_size itself */
            if (*n > f.array_size) {
                *n = f.array_size;
            }
            count = *n;
        }
        for (pb_size_t i = 0; i < count; i++) {
            char *item = (char *)f.pData + (size_t)i * f.data_size;
            if (PB_LTYPE(f.type) == PB_LTYPE_STRING) {
                item[f.data_size - 1u] = '\0';
            } else if (PB_LTYPE(f.type) == PB_LTYPE_BYTES) {
                pb_bytes_array_t *bytes = (pb_bytes_array_t *)(void *)item;
                pb_size_t room = (pb_size_t)(f.data_size - offsetof(pb_bytes_array_t, bytes));
                if (bytes->size > room) {
                    bytes->size = room;
                }
            } else if (PB_LTYPE_IS_SUBMSG(f.type)) {
                bound_message(f.submsg_desc, item);
            }
        }
    } while (pb_field_iter_next(&f));
}

uint8_t pd_user_flags(uint8_t method)
{
    const pd_user_method_t *m = method_of(method);
    return (m != NULL && m->handler != NULL) ? m->flags : 0u;
}

protoduino_Status pd_user_call(pd_core_t *core, const protoduino_UserCall *call,
                               protoduino_Ack *ack)
{
    const pd_user_method_t *m = method_of((uint8_t)call->method);
    if (m == NULL || m->handler == NULL) {
        return protoduino_Status_STATUS_UNKNOWN_COMMAND; /* a report is no call */
    }
    /* The request in the user's schema; one that does not decode runs nothing. */
    pb_istream_t in = pb_istream_from_buffer(call->request.bytes, call->request.size);
    /* Zeroed by memset, not by nanopb's walk over the descriptors (proto3's defaults are
     * zeros): a few hundred of the Uno's cycles less between the frame and its Ack. */
    memset(pd_user_service.request_buf, 0, pd_user_service.request_size);
    if (call->request.size != 0 && /* empty: every field at its default, as zeroed */
        !pb_decode_ex(&in, m->request, pd_user_service.request_buf, PB_DECODE_NOINIT)) {
        return protoduino_Status_STATUS_DECODE_ERROR;
    }
    memset(pd_user_service.reply_buf, 0, pd_user_service.reply_size);
    pd_user_ctx_t ctx = {core, core->hal};
    uint8_t code = m->handler(&ctx, pd_user_service.request_buf, pd_user_service.reply_buf);
    if (code != 0) {
        ack->user_code = code;
        return protoduino_Status_STATUS_USER_ERROR;
    }
    /* The handler ran: from here on the answer is OK. Within its bounds the reply encodes,
     * and fits (the generator checks every reply's nanopb bound against the 64 B). */
    bound_message(m->reply, pd_user_service.reply_buf);
    pb_ostream_t out = pb_ostream_from_buffer(ack->result.user_reply.bytes,
                                              sizeof(ack->result.user_reply.bytes));
    if (pb_encode(&out, m->reply, pd_user_service.reply_buf)) {
        ack->result.user_reply.size = (pb_size_t)out.bytes_written;
    } else { /* unreachable by the above; were it not, OK without a reply: "ran, reply lost" */
        ack->which_result = 0;
    }
    return protoduino_Status_STATUS_OK;
}

protoduino_Status pd_user_claim(pd_user_ctx_t *ctx, uint8_t pin)
{
    uint8_t slot;
    return pd_pins_claim(ctx->core->outputs.owner, ctx->hal, pin, PD_MODE_USER, 0, &slot);
}

protoduino_Status pd_user_release(pd_user_ctx_t *ctx, uint8_t pin)
{
    if (!pd_user_owns(ctx, pin)) {
        return protoduino_Status_STATUS_NOT_INITIALISED;
    }
    /* As a Release command's walk (pd_outputs.c, release_owned): the hook, then the pin is
     * free whatever the hook did. */
    pd_user_pin_release(ctx->core, ctx->core->outputs.owner, ctx->hal, pin);
    ctx->core->outputs.owner[pin] = 0;
    return protoduino_Status_STATUS_OK;
}

bool pd_user_owns(const pd_user_ctx_t *ctx, uint8_t pin)
{
    return pin < PD_MAX_PINS && PD_OWNER_MODE(ctx->core->outputs.owner[pin]) == PD_MODE_USER;
}

bool pd_user_outputs_held(const pd_user_ctx_t *ctx)
{
    return ctx->core->failsafe.fired || ctx->core->outputs.inputs.latched != 0;
}

void pd_user_publish(pd_user_ctx_t *ctx, uint8_t method)
{
    uint8_t bit = report_bit(method);
    if (bit >= PD_USER_MAX_REPORTS) {
        return;
    }
    pd_user_state_t *st = &ctx->core->user;
    if ((st->pending >> bit) & 1u) {
        if (st->coalesced[bit] != 0xFFFFu) {
            st->coalesced[bit]++; /* the value waiting is replaced by this newer one */
        }
    }
    st->pending = (uint8_t)(st->pending | (1u << bit));
    pd_state_report(ctx->core, PD_USER_SLOT);
}

void pd_user_init(pd_core_t *core)
{
    memset(&core->user, 0, sizeof(core->user));
}

void pd_user_poll(pd_core_t *core, uint32_t now)
{
    if (core->user.pending != 0 && !((core->report_pending >> PD_USER_SLOT) & 1u)) {
        pd_state_report(core, PD_USER_SLOT); /* more than one report was pending */
    }
    if (pd_user_service.poll != NULL) {
        pd_user_ctx_t ctx = {core, core->hal};
        pd_user_service.poll(&ctx, now);
    }
}

bool pd_user_report(pd_core_t *core, protoduino_ArduinoOut *out)
{
    pd_user_state_t *st = &core->user;
    while (st->pending != 0) {
        uint8_t bit = 0;
        while (!((st->pending >> bit) & 1u)) {
            bit++;
        }
        const pd_user_method_t *m = method_of(method_of_bit(bit));
        memset(pd_user_service.reply_buf, 0, pd_user_service.reply_size);
        pd_user_ctx_t ctx = {core, core->hal};
        pb_ostream_t os = pb_ostream_from_buffer(out->data.user_report.body.bytes,
                                                 sizeof(out->data.user_report.body.bytes));
        /* Built now, as it goes out: the newest value by construction. */
        if (m != NULL && m->report(&ctx, pd_user_service.reply_buf) &&
            (bound_message(m->reply, pd_user_service.reply_buf), true) &&
            pb_encode(&os, m->reply, pd_user_service.reply_buf)) {
            out->which_data = protoduino_ArduinoOut_user_report_tag;
            out->data.user_report.report = method_of_bit(bit);
            out->data.user_report.body.size = (pb_size_t)os.bytes_written;
            out->data.user_report.coalesced = st->coalesced[bit];
            return true;
        }
        st->pending = (uint8_t)(st->pending & ~(1u << bit)); /* nothing to send after all */
        st->coalesced[bit] = 0;
    }
    return false;
}

void pd_user_sent(pd_core_t *core, const protoduino_ArduinoOut *out)
{
    pd_user_state_t *st = &core->user;
    uint8_t bit = report_bit((uint8_t)out->data.user_report.report);
    if (bit < PD_USER_MAX_REPORTS) {
        st->pending = (uint8_t)(st->pending & ~(1u << bit));
        st->coalesced[bit] = 0;
    }
    /* Other reports still pending: the core clears the slot after this call,
     * and pd_user_poll raises it again on the next pass. */
}

#else
typedef int pd_user_unused_t; /* ISO C: a translation unit declares something */
#endif /* PD_FEATURE_USER */

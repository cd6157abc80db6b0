#include "pd_dispatch.h"

#include <string.h>

#include <pb_decode.h>

#include "pd_core.h"
#include "pd_encode.h"
#include "pd_link.h"
#include "pd_schema.h"

void pd_dedupe_init(pd_dedupe_t *dd)
{
    memset(dd, 0, sizeof(*dd));
}

int pd_dedupe_find(const pd_dedupe_t *dd, uint32_t id)
{
    for (uint8_t i = 0; i < dd->count; i++) {
        if (dd->id[i] == id) {
            return dd->status[i];
        }
    }
    return -1;
}

void pd_dedupe_add(pd_dedupe_t *dd, uint32_t id, uint8_t status)
{
    dd->id[dd->next] = id;
    dd->status[dd->next] = status;
    dd->next = (uint8_t)((dd->next + 1u) % PD_DEDUPE_WINDOW);
    if (dd->count < PD_DEDUPE_WINDOW) {
        dd->count++;
    }
}

bool pd_dispatch_send(pd_core_t *core, const protoduino_ArduinoOut *msg)
{
    uint8_t raw[PD_TX_RAW_MAX];

    if (!core->link.active) {
        return false; /* DATA only while ACTIVE; skip the encoding work */
    }
    size_t len = pd_encode_out(msg, raw + PD_HEADER_SIZE, PD_TX_MAX_PAYLOAD);
    if (len == 0) {
        return false; /* cannot happen: PD_TX_MAX_PAYLOAD is the message's max size */
    }
    return pd_link_send(core, PD_PACKET_DATA, raw, len);
}

bool pd_dispatch_send_failsafe(pd_core_t *core, bool active, protoduino_FailsafeCause cause)
{
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    out.which_data = protoduino_ArduinoOut_failsafe_tag;
    out.data.failsafe.active = active;
    out.data.failsafe.cause = cause;
    return pd_dispatch_send(core, &out);
}

static void copy_string(char *dst, size_t cap, const char *src)
{
    size_t n = strlen(src);
    if (n >= cap) {
        n = cap - 1u;
    }
    memcpy(dst, src, n);
    dst[n] = '\0';
}

static void fill_info(pd_core_t *core, protoduino_DeviceInfo *info)
{
    const pd_board_info_t *board = pd_hal_board_info(core->hal);

    copy_string(info->firmware_version, sizeof(info->firmware_version), PD_FIRMWARE_VERSION);
    copy_string(info->board, sizeof(info->board), board->board);
    info->protocol_version = PD_PROTOCOL_VERSION;
    info->schema_id = PD_SCHEMA_ID;
    info->num_pins = board->num_pins;
    info->max_servos = board->max_servos;
    info->reserved_pins_count = 0;
    for (uint8_t pin = 0; pin < 32u && pin < board->num_pins; pin++) {
        if ((board->reserved_pins >> pin) & 1u) {
            if (info->reserved_pins_count >= sizeof(info->reserved_pins) / sizeof(info->reserved_pins[0])) {
                break;
            }
            info->reserved_pins[info->reserved_pins_count++] = pin;
        }
    }
}

static void send_ack(pd_core_t *core, protoduino_ArduinoOut *out, uint32_t id, uint8_t status)
{
    out->which_data = protoduino_ArduinoOut_ack_tag;
    out->data.ack.message_id = id;
    out->data.ack.status = (protoduino_Status)status;
    pd_dispatch_send(core, out);
}

/* Execute a command that moves outputs; returns the Ack status. */
static protoduino_Status execute(pd_core_t *core, const protoduino_ArduinoIn *in)
{
    void *hal = core->hal;

    switch (in->which_data) {
    case protoduino_ArduinoIn_servo_init_tag:
        return pd_outputs_servo_init(&core->outputs, hal, &in->data.servo_init);
    case protoduino_ArduinoIn_servo_control_tag:
        return pd_outputs_servo_control(&core->outputs, hal, &in->data.servo_control);
    case protoduino_ArduinoIn_digital_init_tag:
        return pd_outputs_digital_init(&core->outputs, hal, &in->data.digital_init);
    case protoduino_ArduinoIn_digital_control_tag:
        return pd_outputs_digital_control(&core->outputs, hal, &in->data.digital_control);
    case protoduino_ArduinoIn_stop_tag:
        pd_outputs_all_safe(&core->outputs, hal);
        pd_failsafe_set(&core->failsafe);
        return protoduino_Status_STATUS_OK;
    default:
        return protoduino_Status_STATUS_UNKNOWN_COMMAND;
    }
}

void pd_dispatch_command(pd_core_t *core, const uint8_t *payload, size_t len)
{
    protoduino_ArduinoIn in = protoduino_ArduinoIn_init_zero;
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    pb_istream_t stream = pb_istream_from_buffer(payload, len);

    if (!pb_decode(&stream, protoduino_ArduinoIn_fields, &in)) {
        /* Nothing is executed; the host learns of it twice if it can. */
        core->decode_errors++;
        out.which_data = protoduino_ArduinoOut_decode_error_tag;
        out.data.decode_error.count = core->decode_errors;
        pd_dispatch_send(core, &out);
        if (in.message_id != 0) {
            memset(&out, 0, sizeof(out));
            send_ack(core, &out, in.message_id, protoduino_Status_STATUS_DECODE_ERROR);
        }
        return;
    }
    if (in.message_id == 0) {
        send_ack(core, &out, 0, protoduino_Status_STATUS_INVALID_ARGUMENT);
        return;
    }

    if (in.which_data == protoduino_ArduinoIn_ping_tag) {
        bool was_safe = pd_failsafe_ping(&core->failsafe, pd_hal_millis(core->hal));
        out.data.ack.which_result = protoduino_Ack_ping_echo_tag;
        out.data.ack.result.ping_echo.size = in.data.ping.payload.size;
        memcpy(out.data.ack.result.ping_echo.bytes, in.data.ping.payload.bytes,
               in.data.ping.payload.size);
        send_ack(core, &out, in.message_id, protoduino_Status_STATUS_OK);
        if (was_safe) {
            pd_dispatch_send_failsafe(core, false, protoduino_FailsafeCause_FAILSAFE_CAUSE_NONE);
        }
        return;
    }
    if (in.which_data == protoduino_ArduinoIn_get_info_tag) {
        out.data.ack.which_result = protoduino_Ack_info_tag;
        fill_info(core, &out.data.ack.result.info);
        send_ack(core, &out, in.message_id, protoduino_Status_STATUS_OK);
        return;
    }

    int seen = pd_dedupe_find(&core->dedupe, in.message_id);
    if (seen >= 0) {
        /* A retransmission whose Ack was lost: answer again, do not repeat it. */
        send_ack(core, &out, in.message_id, (uint8_t)seen);
        return;
    }
    protoduino_Status status = execute(core, &in);
    pd_dedupe_add(&core->dedupe, in.message_id, (uint8_t)status);
    send_ack(core, &out, in.message_id, (uint8_t)status);
    if (in.which_data == protoduino_ArduinoIn_stop_tag) {
        pd_dispatch_send_failsafe(core, true, protoduino_FailsafeCause_FAILSAFE_CAUSE_STOP);
    }
}

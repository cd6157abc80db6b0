#include "pd_dispatch.h"

#include <stddef.h>
#include <string.h>

#include <pb_decode.h>

#include "pd_dedupe.h"
#include "pd_fastdec.h"
#include "pd_inputs.h"
#include "pd_out.h"
#include "pd_rom.h"
#include "pd_schema.h"
#include "pd_state.h"
#include "pd_tables.h"
#include "pd_user.h"

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

    /* In flash: a string literal would be copied into the Uno's SRAM at start-up. */
    static const char version[] PD_ROM = PD_FIRMWARE_VERSION;
    typedef char fits[(sizeof(version) <= sizeof(info->firmware_version)) ? 1 : -1];
    (void)sizeof(fits);
    pd_rom_copy(info->firmware_version, version, sizeof(version));
    copy_string(info->board, sizeof(info->board), board->board);
    info->protocol_version = PD_PROTOCOL_VERSION;
    info->schema_id = PD_SCHEMA_ID;
    info->num_pins = board->num_pins;
    info->max_servos = PD_FEATURE_SERVO ? board->max_servos : 0u;
    info->rx_buffer = board->rx_buffer;
    info->features = PD_FEATURES;
    /* The pin table: the encoder writes it from the board's own (pd_encode.h). */
    info->pins.arg = core->hal;
#if PD_FEATURE_USER
    info->user_fingerprint = pd_user_service.fingerprint;
#endif
    info->reserved_pins_count = 0;
    for (uint8_t pin = 0; pin < PD_MAX_PINS && pin < board->num_pins; pin++) {
        if (pd_pinset_has(&board->reserved_pins, pin)) {
            if (info->reserved_pins_count >= sizeof(info->reserved_pins) / sizeof(info->reserved_pins[0])) {
                break;
            }
            info->reserved_pins[info->reserved_pins_count++] = pin;
        }
    }
}

/* Not inlined at its four calls in respond(): 34 B of the Uno's flash. */
static __attribute__((noinline)) void send_ack(pd_core_t *core, protoduino_ArduinoOut *out,
                                               uint32_t id, uint8_t status)
{
    out->which_data = protoduino_ArduinoOut_ack_tag;
    out->data.ack.message_id = id;
    out->data.ack.status = (protoduino_Status)status;
    if (status == protoduino_Status_STATUS_OK && out->data.ack.which_result == 0 &&
        !out->data.ack.has_failsafe && out->data.ack.refused_item == 0 && out->data.ack.user_code == 0) {
        /* Only the id and STATUS_OK: the short Ack (protocol.md section 7). */
        out->which_data = protoduino_ArduinoOut_ack_ok_tag;
        out->data.ack_ok = id;
    }
    pd_out_send(core, out);
}

/* After a Stop's Ack, or a liveness message's that cleared the flag: the
 * state as it is now (active with the new epoch, or cleared). */
static void notify_failsafe(pd_core_t *core)
{
    pd_out_send_failsafe(core);
}

/* --- command handlers: each returns the Ack status ------------------------ */

/*
 * A liveness message carrying the failsafe epoch its host has seen: restarts
 * the failsafe timer and clears its flag if that is the current epoch (a stale
 * one changes nothing). Its Ack then carries the failsafe state once any safe
 * state was entered since power-up, so that a host that missed the event (or
 * sent the message before it) learns of it and can send the epoch back.
 */
static void alive(pd_core_t *core, pd_cmd_t *cmd, uint8_t epoch, bool counts)
{
    if (counts &&
        pd_failsafe_alive(&core->failsafe, pd_hal_millis(core->hal), epoch) == PD_ALIVE_CLEARED) {
        cmd->then = notify_failsafe;
    }
    if (core->failsafe.epoch != 0) {
        cmd->ack->has_failsafe = true;
        pd_out_failsafe_state(core, &cmd->ack->failsafe);
    }
}

static protoduino_Status cmd_ping(pd_core_t *core, pd_cmd_t *cmd)
{
    const protoduino_Ping *ping = &cmd->in->data.ping;
    /* Liveness unless the session wants the application's Heartbeat. */
    alive(core, cmd, ping->failsafe_epoch, !core->failsafe.heartbeat_only);
    cmd->ack->result.ping_echo.size = ping->payload.size;
    memcpy(cmd->ack->result.ping_echo.bytes, ping->payload.bytes, ping->payload.size);
    return protoduino_Status_STATUS_OK;
}

static protoduino_Status cmd_heartbeat(pd_core_t *core, pd_cmd_t *cmd)
{
    alive(core, cmd, cmd->in->data.heartbeat.failsafe_epoch, true); /* whatever the source */
    return protoduino_Status_STATUS_OK;
}

/* ConfigureFailsafe: this session's timeout and liveness source; restarts the timer. */
static protoduino_Status cmd_configure_failsafe(pd_core_t *core, pd_cmd_t *cmd)
{
    const protoduino_ConfigureFailsafe *msg = &cmd->in->data.configure_failsafe;
    uint32_t timeout = msg->timeout_ms ? msg->timeout_ms : PD_FAILSAFE_TIMEOUT_MS;
    /* One unsigned compare for both bounds: below the minimum wraps above the range. */
    if ((uint32_t)(timeout - PD_FAILSAFE_MIN_MS) > PD_FAILSAFE_MAX_MS - PD_FAILSAFE_MIN_MS ||
        (uint32_t)msg->liveness > protoduino_Liveness_LIVENESS_HEARTBEAT) {
        return protoduino_Status_STATUS_INVALID_ARGUMENT;
    }
    core->failsafe.timeout_ms = timeout;
    core->failsafe.heartbeat_only = msg->liveness != protoduino_Liveness_LIVENESS_PING;
    /* A longer timeout must not count from a liveness message that came under
     * the old one; but a configuration carries no epoch, so it never clears an
     * expired failsafe (one held up on the way could otherwise re-arm it). */
    pd_failsafe_restart(&core->failsafe, pd_hal_millis(core->hal));
    return protoduino_Status_STATUS_OK;
}

static protoduino_Status cmd_release(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_outputs_release(&core->outputs, core->hal, cmd->in->data.release.pin);
}

static protoduino_Status cmd_release_all(pd_core_t *core, pd_cmd_t *cmd)
{
    (void)cmd;
    pd_outputs_release_all(&core->outputs, core->hal);
    return protoduino_Status_STATUS_OK;
}

static protoduino_Status cmd_get_info(pd_core_t *core, pd_cmd_t *cmd)
{
    fill_info(core, &cmd->ack->result.info);
    return protoduino_Status_STATUS_OK;
}

static protoduino_Status cmd_servo_init(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_outputs_servo_init(&core->outputs, core->hal, &cmd->in->data.servo_init);
}

static protoduino_Status cmd_servo_control(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_outputs_servo_control(&core->outputs, core->hal, &cmd->in->data.servo_control);
}

static protoduino_Status cmd_digital_init(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_outputs_digital_init(&core->outputs, core->hal, &cmd->in->data.digital_init);
}

static protoduino_Status cmd_digital_control(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_outputs_digital_control(&core->outputs, core->hal, &cmd->in->data.digital_control);
}

static protoduino_Status cmd_pwm_init(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_outputs_pwm_init(&core->outputs, core->hal, &cmd->in->data.pwm_init);
}

static protoduino_Status cmd_pwm_control(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_outputs_pwm_control(&core->outputs, core->hal, &cmd->in->data.pwm_control);
}

static protoduino_Status cmd_digital_input_init(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_inputs_digital_init(core, &cmd->in->data.digital_input_init);
}

static protoduino_Status cmd_analog_input_init(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_inputs_analog_init(core, &cmd->in->data.analog_input_init);
}

static protoduino_Status cmd_counter_init(pd_core_t *core, pd_cmd_t *cmd)
{
    return pd_inputs_counter_init(core, &cmd->in->data.counter_init);
}

static protoduino_Status cmd_clear_interlock(pd_core_t *core, pd_cmd_t *cmd)
{
    bool cleared;
    protoduino_Status status = pd_inputs_clear_interlock(
        core, cmd->in->data.clear_interlock.failsafe_epoch, &cleared);
    if (cleared) {
        cmd->then = notify_failsafe; /* the state now: cleared, unless the timer ran out */
    }
    return status;
}

static protoduino_Status cmd_pose(pd_core_t *core, pd_cmd_t *cmd)
{
    uint8_t bad;
    protoduino_Status status =
        pd_outputs_pose(&core->outputs, core->hal, &cmd->in->data.pose, &bad);
    if (status != protoduino_Status_STATUS_OK) {
        cmd->ack->refused_item = bad;
    }
    return status;
}

static protoduino_Status cmd_read_outputs(pd_core_t *core, pd_cmd_t *cmd)
{
    pd_outputs_read(&core->outputs, &cmd->ack->result.outputs);
    return protoduino_Status_STATUS_OK;
}

/* A user service's method (pd_user.c): its request decoded with the user's
 * schema, its handler run, its reply (or its own code) in the Ack. Without
 * the feature the table answers STATUS_NOT_SUPPORTED and never calls it. */
static protoduino_Status cmd_user_call(pd_core_t *core, pd_cmd_t *cmd)
{
#if PD_FEATURE_USER
    return pd_user_call(core, &cmd->in->data.user_call, cmd->ack);
#else
    (void)core;
    (void)cmd;
    return protoduino_Status_STATUS_NOT_SUPPORTED;
#endif
}

static protoduino_Status cmd_stop(pd_core_t *core, pd_cmd_t *cmd)
{
    pd_outputs_all_safe(&core->outputs, core->hal);
    pd_failsafe_stop(&core->failsafe); /* the timer keeps running */
    cmd->then = notify_failsafe;
    return protoduino_Status_STATUS_OK;
}

/*
 * The command table, PD_COMMANDS in pd_tables.h: generated by `protoduino gen`
 * from the (command) options on ArduinoIn.data's members and the (pin_mode)
 * options on enum Feature (proto/protoduino.proto; protoduino_options.proto
 * says what each means), the declarations host/protoduino/commands.py is
 * built from too. One X(name, feature, flags, result) per member:
 *   name    the member: its tag is protoduino_ArduinoIn_<name>_tag, its
 *           handler cmd_<name>(core, cmd) above, which returns the Ack status
 *           (anything but OK: nothing changed) and may set cmd->then to send
 *           something after the Ack;
 *   feature 1, or the PD_FEATURE_x switch (pd_features.h) it needs: built
 *           without it, the command is answered STATUS_NOT_SUPPORTED and its
 *           handler is left out of the build;
 *   flags   PD_CMD_IDEMPOTENT: running it twice changes nothing, so it is
 *           neither looked up in nor recorded in the dedupe window (a repeat
 *           is answered in full; the window is left to commands that move
 *           outputs);
 *           PD_CMD_SETS_OUTPUT: it sets an output to a commanded (not safe)
 *           value, so it is refused with STATUS_FAILSAFE_EXPIRED once the
 *           failsafe timer has run out, until the next liveness message
 *           (there is never a commanded output without a running timer), and
 *           with STATUS_INTERLOCK_ACTIVE while an interlock is latched;
 *   result  the Ack.result member its Ack carries (0: none); the handler fills it.
 *
 * Why an X-macro and not an array of structs with function pointers: the
 * array was measured at +800 B of the Uno's flash, because calls through a
 * pointer stop the compiler from inlining the handlers and from folding the
 * board's constant figures into them. Expanded into switches, the table costs
 * what the hand-written switch it replaced cost.
 *
 * How to add a command (the files touched by hand; docs/architecture.md):
 *   1. proto/protoduino.proto: its message and a member of ArduinoIn.data with
 *      a field number from your range, with a (command) option if it is
 *      idempotent, carries an Ack result, needs a feature or sets outputs
 *      (its bounds, if any, in proto/protoduino.options); then `protoduino gen`;
 *   2. here: its handler, cmd_<name>(core, cmd);
 *   3. docs/protocol.md: its wire text;
 *   4. its method on the host (host/protoduino/board.py and aio.py) and its
 *      tests; the fake devices (tests/fakedevice.py, host/protoduino/testing.py) if
 *      the tests that use them send it.
 * A result also needs its encoding in pd_encode.c (the device's encoder writes
 * only the Ack results it knows).
 */
/* The table entry for `tag` (flags and result; the handler is run by run_command). */
static bool find_command(pb_size_t tag, pd_command_t *entry)
{
    switch (tag) {
#define PD_FIND(name, feature_, flags_, result_)                             \
    case protoduino_ArduinoIn_##name##_tag:                                  \
        entry->flags = (flags_);                                             \
        entry->result = (result_);                                           \
        return true;
        PD_COMMANDS(PD_FIND)
#undef PD_FIND
    default:
        return false;
    }
}

static protoduino_Status run_command(pd_core_t *core, pd_cmd_t *cmd)
{
    switch (cmd->in->which_data) {
#define PD_RUN(name, feature_, flags_, result_)                              \
    case protoduino_ArduinoIn_##name##_tag:                                  \
        return (feature_) ? cmd_##name(core, cmd) : protoduino_Status_STATUS_NOT_SUPPORTED;
        PD_COMMANDS(PD_RUN)
#undef PD_RUN
    default:
        return protoduino_Status_STATUS_UNKNOWN_COMMAND;
    }
}

static void respond(pd_core_t *core, const protoduino_ArduinoIn *msg, bool decoded);

/* What pd_dispatch_decode clears: ArduinoIn is its message id and the oneof. */
typedef char pd_assert_in_is_id_and_oneof[
    (offsetof(protoduino_ArduinoIn, message_id) == 0 &&
     offsetof(protoduino_ArduinoIn, which_data) == sizeof(uint32_t) &&
     offsetof(protoduino_ArduinoIn, data) < offsetof(protoduino_ArduinoIn, which_data) + 2u * sizeof(uint32_t) &&
     offsetof(protoduino_ArduinoIn, data) + sizeof(((protoduino_ArduinoIn *)0)->data) ==
         sizeof(protoduino_ArduinoIn)) ? 1 : -1];

/* Each ArduinoIn member's size by its field number (0: not a member), as nanopb's
 * field iterator would find it; in flash. Its descriptor is the one nanopb's
 * ArduinoIn descriptor holds for it: every field but the first is a member, so
 * member N is submessage N - 2 (test_short_decode_descriptors checks it). */
static const uint8_t pd_member_size[] PD_ROM = {
#define PD_MEMBER(name, feature_, flags_, result_)                                   \
    [protoduino_ArduinoIn_##name##_tag] = (uint8_t)sizeof(((protoduino_ArduinoIn *)0)->data.name),
    PD_COMMANDS(PD_MEMBER)
#undef PD_MEMBER
};

#define PD_MEMBER_FITS(name, feature_, flags_, result_)                              \
    && sizeof(((protoduino_ArduinoIn *)0)->data.name) <= 255u
typedef char pd_assert_member_sizes_fit[(1 PD_COMMANDS(PD_MEMBER_FITS)) ? 1 : -1];
#undef PD_MEMBER_FITS

/* nanopb's decode of the whole ArduinoIn: `stream` its bytes; its descriptor. */
static const pb_msgdesc_t *plan_full(pb_istream_t *stream, protoduino_ArduinoIn *in,
                                     const uint8_t *payload, size_t len)
{
    *stream = pb_istream_from_buffer(payload, len);
    /*
     * NOINIT (decode_flags): nanopb would walk every field descriptor of
     * ArduinoIn to set proto3's defaults. Zeros are those defaults, and nanopb
     * zeroes (and sets to defaults) the oneof member it decodes whenever
     * which_data did not name it yet, so only the fields outside the oneof are
     * zeroed here. Zeroing the whole 104 B after every frame instead was 350 of
     * the Uno's cycles per command (and 320 on the Ack's path when it ran before
     * the decode).
     */
    in->message_id = 0;
    in->which_data = 0;
    return protoduino_ArduinoIn_fields;
}

/*
 * The payload as a host writes it: the message id (field 1, a one-byte varint),
 * then one command (field 2..15, length-delimited, a one-byte tag and a one-byte
 * length) that ends the payload. For those (every command a host library sends),
 * the two header fields are read here and nanopb decodes the command's own
 * message alone, with its own descriptor, instead of first walking ArduinoIn's
 * field descriptors to find it: this is framing, the command's fields are still
 * nanopb's to decode. It does exactly what nanopb's decode of the whole
 * ArduinoIn does for such a payload (pb_decode.c: the message id's varint; for
 * the oneof member, decode_static_field zeroes it and sets its defaults when its
 * descriptor has any, then pb_dec_submessage decodes the submessage's bytes with
 * PB_DECODE_NOINIT), so the result, and a decode error, are the same: the unit
 * tests and fuzz_dispatch.c compare the two on every input they make. Anything
 * else (another order, a second field, a longer id, tag or length, a wrong wire
 * type, a member numbered 16 or more) is left to the full decode: NULL, and
 * nothing written. Otherwise: the command's descriptor, `stream` its bytes.
 */
static const pb_msgdesc_t *plan_short(pb_istream_t *stream, protoduino_ArduinoIn *in,
                                      const uint8_t *payload, size_t len)
{
    if (len < 4u || payload[0] != ((protoduino_ArduinoIn_message_id_tag << 3) | PB_WT_VARINT) ||
        payload[1] >= 0x80u || payload[3] >= 0x80u || (size_t)payload[3] + 4u != len ||
        (payload[2] & 0x87u) != PB_WT_STRING) {
        return NULL;
    }
    pb_size_t tag = (pb_size_t)(payload[2] >> 3);
    uint8_t size;
    if (tag >= sizeof(pd_member_size)) {
        return NULL;
    }
    pd_rom_copy(&size, &pd_member_size[tag], 1u);
    if (size == 0) {
        return NULL; /* not a member: field 1 again, or none */
    }
    in->message_id = payload[1];
    in->which_data = tag;
    memset(&in->data, 0, size);
    *stream = pb_istream_from_buffer(payload + 4, payload[3]);
    return protoduino_ArduinoIn_msg.submsg_info[tag - 2u];
}

/* The flags nanopb decodes `desc` with, the whole ArduinoIn (above) or a member: as
 * decode_static_field, a member's defaults are set only when it has any to set
 * (a submessage, a default value or a callback; none of the Controls). */
static unsigned int decode_flags(const pb_msgdesc_t *desc)
{
    if (desc != protoduino_ArduinoIn_fields &&
        (desc->default_value != NULL || desc->field_callback != NULL || desc->submsg_info[0] != NULL)) {
        return 0u;
    }
    return PB_DECODE_NOINIT;
}

/*
 * The steps of the generated decoders (generated/pd_fastdec.h, `protoduino gen`):
 * a member whose fields are all uint32 or bool is decoded by a switch on the field
 * number rather than nanopb's field iterator (about 1,500 of the Uno's cycles a
 * digital write). Each step keeps nanopb's rule: a one-byte varint is read here
 * (a buffer stream's state is its next byte), a longer one, a missing one and an
 * unknown field are nanopb's own (pb_decode_varint's overflow and padding rules,
 * pb_skip_field); a known field takes wire type 0 only, and a field number 0
 * is refused.
 */
/* What pb_decode_varint reads a uint32 field's value into (as pb_dec_varint does). */
#ifdef PB_WITHOUT_64BIT
typedef uint32_t pd_varint_t;
#else
typedef uint64_t pd_varint_t;
#endif

/* The next byte, when it is a whole varint (below 0x80): taken, else left (-1) for
 * nanopb's reader. A buffer stream's state is its next byte. Inlined into the three
 * readers below: their one-byte path then calls nothing and needs no registers saved
 * and no stack frame (under -mcall-prologues each call of them had both: ~100 of the
 * Uno's cycles per command, bench part 5). */
static inline __attribute__((always_inline)) int16_t fast_byte(pb_istream_t *s)
{
    const pb_byte_t *p = (const pb_byte_t *)s->state;
    if (s->bytes_left == 0 || *p >= 0x80u) {
        return -1;
    }
    s->state = (void *)(p + 1);
    s->bytes_left--;
    return *p;
}

/* A tag longer than a byte (or none left), by nanopb's reader, as fast_tag returns it. */
static __attribute__((noinline)) uint8_t fast_tag_long(pb_istream_t *s)
{
    uint32_t t;
    if (!pb_decode_varint32(s, &t) || (t >> 3) == 0u) {
        return 0;
    }
    return (uint8_t)((t >> 3) < 31u ? t : ((31u << 3) | (t & 7u)));
}

/* The next tag in one byte, 0 when refused (a field number 0 is, as by nanopb): field
 * numbers up to 30 as they are (the generator keeps the decoders' fields there), any
 * larger one as 31, which no decoder knows; the wire type kept for the skip. A one-byte
 * tag's field number is below 16. */
static uint8_t fast_tag(pb_istream_t *s)
{
    int16_t b = fast_byte(s);
    if (b < 0) {
        return fast_tag_long(s);
    }
    return (uint8_t)b < 8u ? 0 : (uint8_t)b;
}

/* A uint32 field stored in `size` bytes (the int_size nanopb gave it): stored, then
 * refused if it did not fit, as pb_dec_varint does. */
static __attribute__((noinline)) bool fast_store(void *field, size_t size, pd_varint_t v)
{
    pd_varint_t clamped;
    if (size == sizeof(uint8_t)) {
        clamped = *(uint8_t *)field = (uint8_t)v;
    } else if (size == sizeof(uint16_t)) {
        clamped = *(uint16_t *)field = (uint16_t)v;
    } else {
        clamped = *(uint32_t *)field = (uint32_t)v;
    }
    return clamped == v;
}

/* A uint32 field's value longer than a byte (or none left), by nanopb's reader. */
static __attribute__((noinline)) bool fast_uint_long(pb_istream_t *s, void *field, size_t size)
{
    pd_varint_t v;
    return pb_decode_varint(s, &v) && fast_store(field, size, v);
}

/* A uint32 field (fast_tag's `tag`) into `field` of `size` bytes. */
static bool fast_uint(pb_istream_t *s, uint8_t tag, void *field, size_t size)
{
    if ((tag & 7u) != PB_WT_VARINT) {
        return false;
    }
    int16_t b = fast_byte(s);
    return b < 0 ? fast_uint_long(s, field, size) : fast_store(field, size, (uint8_t)b);
}

/* A bool field's value longer than a byte (or none left), by nanopb's reader. */
static __attribute__((noinline)) bool fast_bool_long(pb_istream_t *s, bool *field)
{
    uint32_t v;
    if (!pb_decode_varint32(s, &v)) {
        return false;
    }
    *field = v != 0u;
    return true;
}

/* A bool field, as pb_dec_bool: any value but 0 is true. */
static bool fast_bool(pb_istream_t *s, uint8_t tag, bool *field)
{
    if ((tag & 7u) != PB_WT_VARINT) {
        return false;
    }
    int16_t b = fast_byte(s);
    if (b < 0) {
        return fast_bool_long(s, field);
    }
    *field = b != 0;
    return true;
}

/* An unknown field, skipped by nanopb. Out of line: LTO copied pb_skip_field into every
 * decoder (about 100 B of the Uno's flash each). */
static __attribute__((noinline)) bool fast_skip(pb_istream_t *s, uint8_t tag)
{
    return pb_skip_field(s, (pb_wire_type_t)(tag & 7u));
}

/*
 * The decoders, one per member of PD_FAST_DECODERS (generated/pd_fastdec.h): a loop
 * over the tags with a case per field of PD_FAST_FIELDS_<member>, an unknown field
 * skipped. A oneof's member is named before its value is read, refused or not, as
 * nanopb's decode_static_field does.
 */
#define FAST_U(n, f)                                                  \
    case n:                                                           \
        if (!fast_uint(s, tag, &m->f, sizeof(m->f))) {                \
            return false;                                             \
        }                                                             \
        break;
#define FAST_B(n, f)                                                  \
    case n:                                                           \
        if (!fast_bool(s, tag, &m->f)) {                              \
            return false;                                             \
        }                                                             \
        break;
#define FAST_OU(n, o, f)                                              \
    case n:                                                           \
        m->which_##o = n;                                             \
        if (!fast_uint(s, tag, &m->o.f, sizeof(m->o.f))) {            \
            return false;                                             \
        }                                                             \
        break;
#define FAST_OB(n, o, f)                                              \
    case n:                                                           \
        m->which_##o = n;                                             \
        if (!fast_bool(s, tag, &m->o.f)) {                            \
            return false;                                             \
        }                                                             \
        break;
#define FAST_DECODER(member, message)                                            \
    static bool fast_##member(pb_istream_t *s, protoduino_##message *m)          \
    {                                                                            \
        while (s->bytes_left != 0) {                                             \
            uint8_t tag = fast_tag(s);                                           \
            if (tag == 0) {                                                      \
                return false;                                                    \
            }                                                                    \
            switch (tag >> 3) {                                                  \
                PD_FAST_FIELDS_##member(FAST_U, FAST_B, FAST_OU, FAST_OB)        \
            default:                                                             \
                if (!fast_skip(s, tag)) {                                        \
                    return false;                                                \
                }                                                                \
            }                                                                    \
        }                                                                        \
        return true;                                                             \
    }
PD_FAST_DECODERS(FAST_DECODER)
#undef FAST_DECODER
#undef FAST_OB
#undef FAST_OU
#undef FAST_B
#undef FAST_U

/* The member plan_short chose, by its generated decoder: 1 decoded, 0 refused, -1
 * none (nanopb decodes it). */
static __attribute__((noinline)) int fast_decode(protoduino_ArduinoIn *in, pb_istream_t *stream)
{
    switch (in->which_data) {
#define PD_FAST_CASE(member, message)                          \
    case protoduino_ArduinoIn_##member##_tag:                  \
        return fast_##member(stream, &in->data.member) ? 1 : 0;
        PD_FAST_DECODERS(PD_FAST_CASE)
#undef PD_FAST_CASE
    default:
        return -1;
    }
}

int pd_dispatch_decode_short(protoduino_ArduinoIn *in, const uint8_t *payload, size_t len)
{
    pb_istream_t stream;
    const pb_msgdesc_t *desc = plan_short(&stream, in, payload, len);
    if (desc == NULL) {
        return -1;
    }
    int fast = fast_decode(in, &stream);
    if (fast >= 0) {
        return fast;
    }
    return pb_decode_ex(&stream, desc, &in->data, decode_flags(desc)) ? 1 : 0;
}

bool pd_dispatch_decode_full(protoduino_ArduinoIn *in, const uint8_t *payload, size_t len)
{
    pb_istream_t stream;
    const pb_msgdesc_t *desc = plan_full(&stream, in, payload, len);
    return pb_decode_ex(&stream, desc, in, decode_flags(desc));
}

bool pd_dispatch_decode(pd_core_t *core, const uint8_t *payload, size_t len)
{
    /* One call of nanopb for both ways, which the Uno's build inlines here as it did the
     * one decode before: a Pose's decode the other way, the deepest stack, stays as deep. */
    pb_istream_t stream;
    void *dest = &core->in.data;
    const pb_msgdesc_t *desc = plan_short(&stream, &core->in, payload, len);
    if (desc == NULL) {
        desc = plan_full(&stream, &core->in, payload, len);
        dest = &core->in;
    } else {
        int fast = fast_decode(&core->in, &stream);
        if (fast >= 0) {
            return fast == 1;
        }
    }
    return pb_decode_ex(&stream, desc, dest, decode_flags(desc));
}

/*
 * The command decoded in core->in (static: it waits there for the packet's
 * check), run and answered in respond(), which is kept out of line so that
 * the ArduinoOut it builds is never on the stack with nanopb's recursion
 * through a Pose (the Uno's deepest stack).
 */
void pd_dispatch_command(pd_core_t *core, bool decoded)
{
    respond(core, &core->in, decoded);
}

static __attribute__((noinline)) void respond(pd_core_t *core, const protoduino_ArduinoIn *msg,
                                              bool decoded)
{
    /* Not zeroed whole: 106 B, 410 of the Uno's cycles between a command's
     * delimiter and its Ack. The Ack's encoder reads which_data, the Ack's
     * scalars and only the result member which_result names; those are set
     * below, and a result union is zeroed before the handler that fills it. */
    protoduino_ArduinoOut out;
    out.data.ack.which_result = 0;
    out.data.ack.refused_item = 0;
    out.data.ack.has_failsafe = false;
    out.data.ack.user_code = 0;
    /* msg is core->in, a constant address once LTO sees the whole program: the
     * AVR would then reach every field with 4-byte lds/sts instead of 2-byte
     * loads relative to a pointer register (108 B of flash). The empty asm
     * hides the constant, nothing else. */
    __asm__("" : "+r"(msg));

    if (!decoded) {
        /* Nothing is executed; the host learns of it twice if it can. */
        core->decode_errors++;
        memset(&out, 0, sizeof(out));
        out.which_data = protoduino_ArduinoOut_decode_error_tag;
        out.data.decode_error.count = core->decode_errors;
        pd_out_send(core, &out);
        if (msg->message_id != 0) {
            memset(&out, 0, sizeof(out));
            send_ack(core, &out, msg->message_id, protoduino_Status_STATUS_DECODE_ERROR);
            if (msg->message_id <= PD_MAX_MESSAGE_ID) {
                /* Its Ack tells the host the device saw this id, so N must have moved
                 * with it (section 7, *Message ids*: every id moves N); not recorded. */
                pd_dedupe_done(&core->dedupe, (uint8_t)msg->message_id, -1);
            }
        }
        return;
    }
    if (msg->message_id == 0 || msg->message_id > PD_MAX_MESSAGE_ID) {
        send_ack(core, &out, msg->message_id, protoduino_Status_STATUS_INVALID_ARGUMENT);
        return;
    }

    pd_command_t entry;
    bool known = find_command(msg->which_data, &entry);
#if PD_FEATURE_USER
    if (msg->which_data == protoduino_ArduinoIn_user_call_tag) {
        /* Each method's own flags (its rpc's idempotency_level, docs/services.md). */
        uint8_t flags = pd_user_flags(msg->data.user_call.method);
        entry.flags = (uint8_t)(((flags & PD_USER_IDEMPOTENT) ? PD_CMD_IDEMPOTENT : 0u) |
                                ((flags & PD_USER_COMMANDS) ? PD_CMD_SETS_OUTPUT : 0u));
    }
#endif
    bool idempotent = known && (entry.flags & PD_CMD_IDEMPOTENT);
    if (!idempotent) {
        /* Only a lookup here: N moves (and old entries go) after the Ack is on its way. */
        int seen = pd_dedupe_lookup(&core->dedupe, (uint8_t)msg->message_id);
        if (seen >= 0) {
            /* A retransmission whose Ack was lost: answer again, do not repeat it. */
            send_ack(core, &out, msg->message_id, (uint8_t)seen);
            return;
        }
    }
    pd_cmd_t cmd = {msg, &out.data.ack, NULL};
    protoduino_Status status = protoduino_Status_STATUS_UNKNOWN_COMMAND;
    if (known && (entry.flags & PD_CMD_SETS_OUTPUT) && core->failsafe.fired) {
        /* The timer ran out (pd_core_poll acts on it within the millisecond) and no
         * liveness message came since. */
        status = protoduino_Status_STATUS_FAILSAFE_EXPIRED;
    } else if (known && (entry.flags & PD_CMD_SETS_OUTPUT) && core->outputs.inputs.latched) {
        /* An interlock tripped: outputs stay safe until ClearInterlock. */
        status = protoduino_Status_STATUS_INTERLOCK_ACTIVE;
    } else if (known) {
        if (entry.result != 0) {
            memset(&out.data.ack.result, 0, sizeof(out.data.ack.result));
        }
        out.data.ack.which_result = entry.result;
        status = run_command(core, &cmd);
        if (status != protoduino_Status_STATUS_OK) {
            out.data.ack.which_result = 0; /* a refusal carries no result */
        }
    }
    send_ack(core, &out, msg->message_id, (uint8_t)status);
    /* The window's bookkeeping while the Ack's bytes go out (pd_dedupe.h): every id
     * moves N (section 7, *Message ids*); only others are recorded. */
    pd_dedupe_done(&core->dedupe, (uint8_t)msg->message_id, idempotent ? -1 : (int)status);
    if (cmd.then != NULL) {
        cmd.then(core);
    }
}

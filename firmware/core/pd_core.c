#include "pd_core.h"

#include <string.h>

#include "pd_dedupe.h"
#include "pd_dispatch.h"
#include "pd_inputs.h"
#include "pd_link.h"
#include "pd_out.h"

#if PD_FEATURE_USER
/* The report callbacks with a user service: the user's slot to the service, the others to
 * the inputs. Here, above both: the service and the inputs know nothing of each other. */
static bool report_user_or_inputs(pd_core_t *core, uint8_t slot, protoduino_ArduinoOut *out)
{
    return slot == PD_USER_SLOT ? pd_user_report(core, out) : pd_inputs_report(core, slot, out);
}

static void sent_user_or_inputs(pd_core_t *core, const protoduino_ArduinoOut *out)
{
    if (out->which_data == protoduino_ArduinoOut_user_report_tag) {
        pd_user_sent(core, out);
    } else {
        pd_inputs_sent(core, out);
    }
}
#endif

void pd_core_init(pd_core_t *core, void *hal)
{
    core->hal = hal;
    core->decode_errors = 0;
    core->report = pd_inputs_report;
    core->report_sent = pd_inputs_sent;
    core->report_pending = 0;
    core->baud = 0; /* the platform opened the line at PD_BAUD */
    core->baud_unconfirmed = false;
#if PD_FEATURE_USER
    core->report = report_user_or_inputs;
    core->report_sent = sent_user_or_inputs;
    pd_user_init(core);
#endif
    uint32_t boot = pd_hal_boot_id(hal);
    for (uint8_t i = 0; i < 4; i++) {
        core->boot_id[i] = (uint8_t)(boot >> (24 - 8 * i));
        core->session[i] = 0;
    }
    pd_link_init(&core->link);
    core->in_decoded = false;
    pd_dedupe_init(&core->dedupe);
    pd_outputs_init(&core->outputs);
#if PD_FEATURE_USER
    core->outputs.core = core;
#endif
    core->failsafe.epoch = 0; /* counts since power-up; a new session keeps it */
    core->failsafe.cause = 0;
    pd_failsafe_init(&core->failsafe, pd_hal_millis(hal));
    pd_link_send_event(&core->link, hal, PD_EVENT_BOOT);
}

/* The RESET_ACK flag bit of a line rate above the opening one (0: none of them). */
static uint8_t baud_flag(uint32_t rate)
{
    if (rate == 250000UL) {
        return PD_RESET_ACK_BAUD_250K;
    }
    if (rate == 500000UL) {
        return PD_RESET_ACK_BAUD_500K;
    }
    return rate == 1000000UL ? PD_RESET_ACK_BAUD_1M : 0u;
}

/*
 * BAUD_SET (docs/protocol.md 5, *Line rate*): a rate this board offers is acked
 * at the rate the line runs at, and then the line switches (after the BAUD_ACK
 * went out: pd_hal_set_baud), unconfirmed until a frame other than a BAUD_SET
 * arrives at the new rate (pd_core_poll goes back otherwise). A BAUD_SET of the
 * rate the line already runs at is the host's probe: acked, nothing changes.
 * Another rate is refused with a BAUD_ACK of 0. Out of line: it runs once or
 * twice a session, and not under the receive loop's stack.
 */
static __attribute__((noinline)) void baud_set(pd_core_t *core, const uint8_t *rate_be)
{
    uint32_t rate = ((uint32_t)rate_be[0] << 24) | ((uint32_t)rate_be[1] << 16) |
                    ((uint32_t)rate_be[2] << 8) | rate_be[3];
    uint8_t flag = (uint8_t)(baud_flag(rate) & pd_hal_baud_rates(core->hal));
    if (flag == 0) {
        const uint8_t refused[4] = {0, 0, 0, 0};
        pd_link_baud_ack(&core->link, core->hal, refused);
        return;
    }
    pd_link_baud_ack(&core->link, core->hal, rate_be);
    if (flag != core->baud) {
        pd_hal_set_baud(core->hal, rate);
        core->baud = flag;
        core->baud_unconfirmed = true;
        core->baud_at = (uint16_t)pd_hal_millis(core->hal);
        core->link.tx_flush = true; /* the host's receiver meets the new rate clean */
    }
}

bool pd_core_rx_byte(pd_core_t *core, uint8_t byte)
{
    pd_link_event_t event = pd_link_rx_byte(&core->link, byte);
    if (event == PD_LINK_NONE) {
        return true; /* most bytes: the frame goes on */
    }
    if (event == PD_LINK_PAYLOAD) {
        /* Decoded now, while the CRC and the delimiter are on the wire; run only on
         * PD_LINK_COMMAND. */
        core->in_decoded = pd_dispatch_decode(core, pd_link_payload(&core->link),
                                              pd_link_payload_len(&core->link));
        return true;
    }
    /* PD_LINK_END: the byte ends a frame. A command first: its Ack is what the host waits for. */
    event = pd_link_rx_end(&core->link, core->hal, byte);
    if (event == PD_LINK_COMMAND) {
        pd_dispatch_command(core, core->in_decoded);
    } else if (event == PD_LINK_HELD) {
        return false;
    } else if (event == PD_LINK_RESET) {
        bool resumed = pd_core_open_session(core, pd_link_session(&core->link),
                                            pd_link_next_id(&core->link));
        pd_link_reset_ack(&core->link, core->hal, core->boot_id, resumed);
    } else if (event == PD_LINK_BAUD) {
        baud_set(core, pd_link_baud(&core->link));
    }
    if (event >= PD_LINK_COMMAND && event <= PD_LINK_HANDLED) {
        /* A valid frame, other than a BAUD_SET, heard at the rate the line runs at:
         * the host follows the switch, which is confirmed. */
        core->baud_unconfirmed = false;
    }
    core->in_decoded = false; /* the frame ended, run or not */
    return true;
}

size_t pd_core_rx(pd_core_t *core, const uint8_t *data, size_t len)
{
    size_t i = 0;
    while (i < len && pd_core_rx_byte(core, data[i])) {
        i++;
    }
    return i;
}

/*
 * The lowest pending report slot, if its message can go out now. Out of line:
 * inlined into the main loop, its ArduinoOut and packet buffer (194 B on the
 * Uno) sat under every command's decode for good, and a Pose's decode is the
 * Uno's deepest stack.
 */
static __attribute__((noinline)) void send_report(pd_core_t *core)
{
    uint8_t slot = 0;
    while (!((core->report_pending >> slot) & 1u)) {
        slot++;
    }
    uint8_t waited = (uint8_t)((uint8_t)pd_hal_millis(core->hal) - core->report_since);
    bool yield = waited < PD_REPORT_MAX_WAIT_MS;
    if (pd_link_spare_blocked(&core->link, core->hal, yield)) {
        /* Not built at all: a command's delimiter arriving meanwhile would wait
         * for the report's build and encoding, which then go nowhere. */
        return;
    }
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    if (core->report(core, slot, &out)) {
        if (!pd_out_send_spare(core, &out, yield)) {
            return; /* no room yet, or a command arriving: the newest value, later */
        }
        if (core->report_sent != NULL) {
            core->report_sent(core, &out);
        }
    }
    core->report_pending = (uint8_t)(core->report_pending & ~(1u << slot));
}

void pd_core_enter_safe(pd_core_t *core, protoduino_FailsafeCause cause)
{
    pd_outputs_all_safe(&core->outputs, core->hal);
    if (cause == protoduino_FailsafeCause_FAILSAFE_CAUSE_STOP) {
        pd_failsafe_stop(&core->failsafe); /* the timer keeps running */
    } else {
        pd_failsafe_fire(&core->failsafe);
    }
    pd_out_send_failsafe(core); /* dropped while IDLE: no one to tell (a Ping's Ack will) */
}

void pd_core_poll(pd_core_t *core)
{
    /* Checked in every state: a RESET of another protocol version makes the
     * link IDLE with outputs still configured. */
    uint32_t now = pd_hal_millis(core->hal);
    if (core->baud_unconfirmed &&
        (uint16_t)((uint16_t)now - core->baud_at) >= (uint16_t)PD_BAUD_CONFIRM_MS) {
        /* The host did not follow the switch: both go back to the opening rate. */
        pd_hal_set_baud(core->hal, PD_BAUD);
        core->baud = 0;
        core->baud_unconfirmed = false;
        core->link.tx_flush = true;
    }
    if (pd_failsafe_due(&core->failsafe, now)) {
        pd_core_enter_safe(core, protoduino_FailsafeCause_FAILSAFE_CAUSE_PING_TIMEOUT);
    }
    if (PD_FEATURE_SERVO) {
        pd_outputs_step(&core->outputs, core->hal, now);
    }
    /* Every pass, whether a host is connected or not: an interlock acts on its own. */
    if (pd_inputs_active(&core->outputs.inputs)) {
        pd_inputs_poll(core, now);
    }
#if PD_FEATURE_USER
    pd_user_poll(core, now);
#endif
    if (core->report_pending != 0 && core->report != NULL && core->link.active) {
        send_report(core);
    }
}

bool pd_core_open_session(pd_core_t *core, const uint8_t session[4], uint8_t next_id)
{
    /* "Not zero" by OR-ing the bytes: a const all-zero array to compare with
     * would sit in the Uno's SRAM (4 B) and take a second memcmp call. */
    uint8_t any = (uint8_t)(session[0] | session[1] | session[2] | session[3]);
    bool resumed = any != 0 && memcmp(session, core->session, 4) == 0;
    /* Either way N follows the host's next id; a new owner's ids start afresh
     * (its id 1 must run), a resumed one's retransmissions are still recognised. */
    pd_dedupe_sync(&core->dedupe, next_id, !resumed);
    if (resumed) {
        return true; /* a re-handshake: not a sign of life, the timer runs on */
    }
    /* Another owner: what the previous one configured is not its to command,
     * and its safe values are not its to choose. Every output returns to the
     * state it has at power-up, which the wiring must tolerate anyway. */
    pd_outputs_release_all(&core->outputs, core->hal);
    core->outputs.inputs.latched = 0; /* the interlocks it latched were released with their inputs */
    core->outputs.inputs.notice = 0;
    pd_failsafe_init(&core->failsafe, pd_hal_millis(core->hal));
    memcpy(core->session, session, 4);
    return false;
}

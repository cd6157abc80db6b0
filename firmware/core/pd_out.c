#include "pd_out.h"

#include "pd_encode.h"
#include "pd_link.h"

bool pd_out_send(pd_core_t *core, const protoduino_ArduinoOut *msg)
{
    uint8_t raw[PD_TX_BUF];

    if (!core->link.active) {
        return false; /* DATA only while ACTIVE; skip the encoding work */
    }
    size_t len = pd_encode_out(msg, raw + PD_TX_PAYLOAD_AT, PD_TX_MAX_PAYLOAD);
    if (len == 0) {
        return false; /* cannot happen: PD_TX_MAX_PAYLOAD is the message's max size */
    }
    return pd_link_send(&core->link, core->hal, PD_PACKET_DATA, raw, len);
}

bool pd_out_send_spare(pd_core_t *core, const protoduino_ArduinoOut *msg, bool yield)
{
    uint8_t raw[PD_TX_BUF];

    if (!core->link.active) {
        return false;
    }
    size_t len = pd_encode_out(msg, raw + PD_TX_PAYLOAD_AT, PD_TX_MAX_PAYLOAD);
    return pd_link_send_spare(&core->link, core->hal, raw, len, yield);
}

void pd_out_failsafe_state(const pd_core_t *core, protoduino_Failsafe *fs)
{
    /* An interlock's latch holds the safe state until ClearInterlock, whatever
     * liveness messages came since; one not told yet is in no state sent
     * (pd_digital_input.c, pd_digital_input_notice: the report of its edge goes first). */
    const pd_inputs_t *in = &core->outputs.inputs;
    fs->active = core->failsafe.active || (in->latched != 0 && !in->notice);
    fs->cause = (protoduino_FailsafeCause)core->failsafe.cause;
    fs->epoch = core->failsafe.epoch;
    if (fs->cause == protoduino_FailsafeCause_FAILSAFE_CAUSE_INTERLOCK) {
        fs->pin = core->failsafe.pin;
    }
}

bool pd_out_send_failsafe(pd_core_t *core)
{
    protoduino_ArduinoOut out = protoduino_ArduinoOut_init_zero;
    out.which_data = protoduino_ArduinoOut_failsafe_tag;
    pd_out_failsafe_state(core, &out.data.failsafe);
    return pd_out_send(core, &out);
}

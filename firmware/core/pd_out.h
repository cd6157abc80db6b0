/*
 * The device's outgoing messages: one ArduinoOut encoded (pd_encode) into a
 * DATA packet and handed to the link, and the failsafe state as a message.
 * Below everything that sends one (the command dispatch, the inputs, the
 * core's reports and failsafe), above the link.
 */
#ifndef PD_OUT_H
#define PD_OUT_H

#include <stdbool.h>

#include "pd_state.h"
#include "protoduino.pb.h"

/* Send one ArduinoOut as a DATA packet (only while ACTIVE). */
bool pd_out_send(pd_core_t *core, const protoduino_ArduinoOut *msg);

/*
 * Send an unsolicited message (a report) if the link has room for it beside a
 * reply (pd_link_send_spare; `yield`: not while a command frame is arriving).
 * Returns whether it was queued.
 */
bool pd_out_send_spare(pd_core_t *core, const protoduino_ArduinoOut *msg, bool yield);

/* The device's failsafe state: the latest safe state entered (its cause and
 * epoch) and whether it still holds. */
void pd_out_failsafe_state(const pd_core_t *core, protoduino_Failsafe *fs);

/* ArduinoOut.failsafe: the failsafe state now (dropped while IDLE: no one to tell). */
bool pd_out_send_failsafe(pd_core_t *core);

#endif /* PD_OUT_H */

/* Helpers shared by the test files: a device plus a scripted host. */
#ifndef TEST_UTIL_H
#define TEST_UTIL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "fake_hal.h"
#include "pd_core.h"
#include "pd_out.h"
#include "protoduino.pb.h"

typedef struct tdev {
    fake_hal_t hal;
    pd_core_t core;
    uint8_t host_seq; /* SEQ of the next packet the host sends */
    uint8_t last_id;  /* the newest message id the host sent (0: none yet): RESET's NEXT_ID follows it */
} tdev_t;

/* The k-th message id of a session (k from 1): 1..127, wrapping to 1 as a host's do. */
#define T_ID(k) ((uint32_t)(((k) - 1u) % PD_MAX_MESSAGE_ID + 1u))

/* Power up (the BOOT frame stays in the fake's log). */
void t_boot(tdev_t *d);
/* Power up and handshake; the frame log is cleared afterwards. */
void t_active(tdev_t *d);

/* Feed raw bytes one at a time, as a UART would. */
void t_feed(tdev_t *d, const uint8_t *bytes, size_t len);
/* Build, encode and feed one packet (with the given SEQ) plus its delimiter. */
void t_send_packet(tdev_t *d, uint8_t type, uint8_t seq, const uint8_t *payload, size_t len);
/* RESET with the given version (SEQ 0); the host's SEQ becomes 1. */
void t_send_reset(tdev_t *d, uint8_t version);
/* The session every test's host uses unless it says otherwise. */
#define T_SESSION 0x5E551011u
void t_send_reset_session(tdev_t *d, uint32_t session);
/* The same with an explicit NEXT_ID (1..127). */
void t_send_reset_next(tdev_t *d, uint32_t session, uint8_t next_id);
/* Encode and send one ArduinoIn as a COMMAND with the host's next SEQ. */
void t_send_in(tdev_t *d, const protoduino_ArduinoIn *in);
/* The same frame, delimiter last, into `wire` (the host's SEQ and ids move on as if
 * sent): its length. For a test that feeds it in parts. */
size_t t_wire_in(tdev_t *d, const protoduino_ArduinoIn *in, uint8_t wire[PD_MAX_ENCODED_FRAME + 1]);

/* Decode frame i as an ArduinoOut; false if it is not a DATA frame that decodes. */
bool t_out(const tdev_t *d, size_t i, protoduino_ArduinoOut *out);
/* Number of Acks for `id` since the last clear; the last one goes to *ack. */
int t_acks(const tdev_t *d, uint32_t id, protoduino_Ack *ack);
/* Status of the single Ack for `id`, or -1 if there is not exactly one. */
int t_status(const tdev_t *d, uint32_t id);
/* Number of CONTROL EVENT frames with this code since the last clear. */
int t_events(const tdev_t *d, uint8_t code);
/* Number of failsafe messages since the last clear; the last one to *fs. */
int t_failsafes(const tdev_t *d, protoduino_Failsafe *fs);

/* Send one command and return its Ack status (-1 if not exactly one Ack). */
int t_cmd(tdev_t *d, const protoduino_ArduinoIn *in);

/* Pin sets (pd_pinset.h) of pins 0..31 as a mask, bit N for pin N: a board table's
 * (T_SET), and the wire's bytes (protocol version 8) written from and read back to one. */
static inline pd_pinset_t T_SET(uint32_t mask)
{
    pd_pinset_t set = {{0}};
    set.w[0] = mask;
    return set;
}
#define T_PUT_MASK(field, mask) ((field).size = t_mask_bytes((field).bytes, (mask)))
#define T_MASK(field) t_bytes_mask((field).bytes, (field).size)
static inline pb_size_t t_mask_bytes(uint8_t *bytes, uint32_t mask)
{
    pb_size_t n = 0;
    for (pb_size_t i = 0; i < 4u; i++) {
        bytes[i] = (uint8_t)(mask >> (8u * i));
        n = bytes[i] != 0 ? (pb_size_t)(i + 1u) : n;
    }
    return n;
}
static inline uint32_t t_bytes_mask(const uint8_t *bytes, pb_size_t size)
{
    uint32_t mask = 0;
    for (pb_size_t i = 0; i < size && i < 4u; i++) {
        mask |= (uint32_t)bytes[i] << (8u * i);
    }
    return mask;
}

/* Message builders. */
protoduino_ArduinoIn m_ping(uint32_t id, const uint8_t *payload, size_t len);
protoduino_ArduinoIn m_servo_init_deg(uint32_t id, uint32_t pin, uint32_t min_us, uint32_t max_us,
                                      uint32_t safe_degrees);
protoduino_ArduinoIn m_servo_init_us(uint32_t id, uint32_t pin, uint32_t min_us, uint32_t max_us,
                                     uint32_t safe_us);
protoduino_ArduinoIn m_servo_deg(uint32_t id, uint32_t pin, uint32_t degrees);
protoduino_ArduinoIn m_servo_us(uint32_t id, uint32_t pin, uint32_t us);
protoduino_ArduinoIn m_digital_init(uint32_t id, uint32_t pin, bool safe);
protoduino_ArduinoIn m_digital(uint32_t id, uint32_t pin, bool level);
protoduino_ArduinoIn m_stop(uint32_t id);
protoduino_ArduinoIn m_info(uint32_t id);

#endif /* TEST_UTIL_H */

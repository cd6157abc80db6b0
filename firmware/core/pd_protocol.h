/*
 * Wire protocol constants (docs/protocol.md section 8) and wire enumerations.
 *
 * Mirrors host/protoduino/constants.py; tests/test_firmware_unit.py parses this
 * header and compares every value with the Python module so the two cannot
 * drift. Durations are in milliseconds here (the host uses seconds): the
 * device's clock is a millisecond counter.
 */
#ifndef PD_PROTOCOL_H
#define PD_PROTOCOL_H

#define PD_PROTOCOL_VERSION 1
#define PD_MAX_PAYLOAD 255
/* COBS-encoded packet of PD_MAX_PAYLOAD bytes, without the 0x00 delimiter. */
#define PD_MAX_ENCODED_FRAME 262
/* TYPE + LEN + SEQ in front of the payload, CRC16 behind it. */
#define PD_HEADER_SIZE 3
#define PD_CRC_SIZE 2
#define PD_MIN_PACKET (PD_HEADER_SIZE + PD_CRC_SIZE)

#define PD_HANDSHAKE_TIMEOUT_MS 5000UL
#define PD_WATCHDOG_TIMEOUT_MS 5000UL
#define PD_PING_INTERVAL_MS 1000UL
#define PD_FAILSAFE_TIMEOUT_MS 10000UL
#define PD_ACK_TIMEOUT_MS 250UL
#define PD_MAX_RETRIES 3
#define PD_SEQ_TOLERANCE 5
#define PD_SEQ_DESYNC_THRESHOLD 50
#define PD_DEDUPE_WINDOW 16

/* Servo pulse defaults when a ServoInit leaves min_us/max_us at 0. */
#define PD_SERVO_DEFAULT_MIN_US 544
#define PD_SERVO_DEFAULT_MAX_US 2400
/* Pulse limits any ServoInit must stay within. */
#define PD_SERVO_LIMIT_MIN_US 400
#define PD_SERVO_LIMIT_MAX_US 2600
#define PD_SERVO_MAX_DEGREES 180

/* Packet TYPE (section 4). */
#define PD_PACKET_CONTROL 0x00
#define PD_PACKET_DATA 0x01
#define PD_PACKET_COMMAND 0x02

/* CONTROL payload CODE (section 5). */
#define PD_CONTROL_RESET 0x00
#define PD_CONTROL_RESET_ACK 0x01
#define PD_CONTROL_HEARTBEAT 0x02
#define PD_CONTROL_EVENT 0x03

/* EVENT codes (section 5). */
#define PD_EVENT_BOOT 0x01
#define PD_EVENT_NOT_ACTIVE 0x02
#define PD_EVENT_DESYNC 0x03
#define PD_EVENT_RX_OVERFLOW 0x04

#endif /* PD_PROTOCOL_H */

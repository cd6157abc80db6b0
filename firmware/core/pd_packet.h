/*
 * Packets: [TYPE][LEN][SEQ][PAYLOAD (LEN)][CRC16 BE], docs/protocol.md sections 3-4.
 * Pure functions: building a packet has no side effects, so a frame that
 * failed to write can be rebuilt with the same SEQ.
 */
#ifndef PD_PACKET_H
#define PD_PACKET_H

#include <stddef.h>
#include <stdint.h>

#include "pd_protocol.h"

typedef enum pd_packet_result {
    PD_PACKET_OK = 0,
    PD_PACKET_ERR_LENGTH, /* fewer than 5 bytes, or size != 5 + LEN */
    PD_PACKET_ERR_CRC,
    PD_PACKET_ERR_TYPE,
    PD_PACKET_ERR_SPACE /* build only: the output buffer is too small */
} pd_packet_result_t;

/* A parsed packet; `payload` points into the buffer that was parsed. */
typedef struct pd_packet {
    uint8_t type;
    uint8_t seq;
    uint8_t len;
    const uint8_t *payload;
} pd_packet_t;

/*
 * Write TYPE, LEN, SEQ, the payload and the CRC into `out` (capacity `cap`).
 * `payload` may already sit at out + PD_HEADER_SIZE (it is then not copied),
 * which lets a caller encode a message in place. Sets *out_len to 5 + len.
 */
pd_packet_result_t pd_packet_build(uint8_t type, uint8_t seq, const uint8_t *payload,
                                   size_t len, uint8_t *out, size_t cap, size_t *out_len);

/* Check length, then CRC, then TYPE (the host's order) and fill `pkt`. */
pd_packet_result_t pd_packet_parse(const uint8_t *raw, size_t len, pd_packet_t *pkt);

/*
 * The same checks for a packet whose CRC was advanced as its bytes arrived:
 * `crc` is CRC-16 over all `len` bytes, its own two included (0 when intact).
 */
pd_packet_result_t pd_packet_check(const uint8_t *raw, size_t len, uint16_t crc, pd_packet_t *pkt);

#endif /* PD_PACKET_H */

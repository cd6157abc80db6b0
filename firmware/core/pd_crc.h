/*
 * CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0),
 * docs/protocol.md section 3. Bitwise rather than a 512-byte table: on the Uno the
 * table would cost a quarter of the flash budget's headroom, and at 115200 baud
 * the loop is far faster than the wire.
 */
#ifndef PD_CRC_H
#define PD_CRC_H

#include <stddef.h>
#include <stdint.h>

#define PD_CRC16_INIT 0xFFFFu

uint16_t pd_crc16_update(uint16_t crc, const uint8_t *data, size_t len);

static inline uint16_t pd_crc16(const uint8_t *data, size_t len)
{
    return pd_crc16_update(PD_CRC16_INIT, data, len);
}

#endif /* PD_CRC_H */

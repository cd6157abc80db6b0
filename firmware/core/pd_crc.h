/*
 * CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0),
 * docs/protocol.md section 3. A byte per step without a table (avr-libc's
 * _crc_xmodem_update on the Uno, pd_crc.c). The receiver advances it one
 * byte at a time as bytes arrive (pd_crc16_byte), so at a frame's delimiter
 * only the comparison remains.
 */
#ifndef PD_CRC_H
#define PD_CRC_H

#include <stddef.h>
#include <stdint.h>

#define PD_CRC16_INIT 0xFFFFu

uint16_t pd_crc16_byte(uint16_t crc, uint8_t byte);
uint16_t pd_crc16_update(uint16_t crc, const uint8_t *data, size_t len);

static inline uint16_t pd_crc16(const uint8_t *data, size_t len)
{
    return pd_crc16_update(PD_CRC16_INIT, data, len);
}

#endif /* PD_CRC_H */

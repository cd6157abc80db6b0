#include "pd_crc.h"

#ifdef __AVR__
#include <util/crc16.h>
#endif

/*
 * One byte per step without a table: the register's top byte and the data
 * byte give x, and the polynomial's three terms (x^12, x^5, 1) are x shifted
 * into place. On the Uno, avr-libc's _crc_xmodem_update is this same step in
 * 19 hand-scheduled instructions (XMODEM is poly 0x1021 unreflected: only its
 * initial value differs, and that is the caller's): about 4x fewer cycles than
 * the 16-entry nibble table it replaced, and no table in flash. The portable
 * form serves the simulated board and the unit tests, whose vectors also pin
 * the Uno's: every frame the emulated Uno sends is checked by the host.
 */
uint16_t pd_crc16_byte(uint16_t crc, uint8_t byte)
{
#ifdef __AVR__
    return _crc_xmodem_update(crc, byte);
#else
    uint8_t x = (uint8_t)((crc >> 8) ^ byte);
    x = (uint8_t)(x ^ (x >> 4));
    return (uint16_t)((crc << 8) ^ ((uint16_t)x << 12) ^ ((uint16_t)x << 5) ^ x);
#endif
}

/*
 * Flattened: the step inlined into the loop (the Uno's -finline-limit=10 keeps
 * avr-libc's inline step out of line otherwise, a call per byte). Every Ack's
 * packet goes through here between a command's delimiter and the Ack's first
 * byte.
 */
__attribute__((flatten)) uint16_t pd_crc16_update(uint16_t crc, const uint8_t *data, size_t len)
{
    for (size_t i = 0; i < len; i++) {
        crc = pd_crc16_byte(crc, data[i]);
    }
    return crc;
}

/*
 * Constant tables in flash. On the Uno a plain `const` table is copied into
 * SRAM at start-up (Harvard architecture), so the command and pin-mode tables
 * would cost RAM for every entry; PD_ROM keeps them in flash and
 * pd_rom_copy() reads one entry out. Elsewhere both are the plain C forms.
 */
#ifndef PD_ROM_H
#define PD_ROM_H

#include <string.h>

#ifdef __AVR__
#include <avr/pgmspace.h>
#define PD_ROM PROGMEM
#define pd_rom_copy(dst, src, n) memcpy_P((dst), (src), (n))
#else
#define PD_ROM
#define pd_rom_copy(dst, src, n) memcpy((dst), (src), (n))
#endif

#endif /* PD_ROM_H */

/*
 * Uno pin numbers to ATmega328P ports: D0-D7 = PORTD0-7, D8-D13 = PORTB0-5,
 * A0-A5 (14-19) = PORTC0-5. Every caller changes a port with interrupts off:
 * the servo interrupt rewrites PORT registers too, and a read-modify-write
 * through a pointer is not atomic.
 */
#ifndef PD_AVR_PINS_H
#define PD_AVR_PINS_H

#include <avr/io.h>
#include <stdint.h>

#if PD_BOARD_MEGA
#include "pd_avr_mega.h"

/* A pin's PORT register; its bit there in *mask: the Mega's map (pd_avr_mega.c). */
static inline volatile uint8_t *pd_avr_port(uint8_t pin, uint8_t *mask)
{
    uint8_t at = pgm_read_byte(&pd_avr_mega_pins[pin]);
    *mask = (uint8_t)(1u << (at & 7u));
    return pd_avr_mega_ports[at >> 3];
}
#else
/* A pin's PORT register; its bit there in *mask. One chain of compares for both. */
static inline volatile uint8_t *pd_avr_port(uint8_t pin, uint8_t *mask)
{
    volatile uint8_t *port = &PORTD;
    if (pin >= 14) {
        pin = (uint8_t)(pin - 14);
        port = &PORTC;
    } else if (pin >= 8) {
        pin = (uint8_t)(pin - 8);
        port = &PORTB;
    }
    *mask = (uint8_t)(1u << pin);
    return port;
}
#endif

/* A port's DDR register, just below its PORT register on every port of the
 * ATmega328P (datasheet, register summary: DDRB 0x24 / PORTB 0x25, DDRC 0x27 /
 * PORTC 0x28, DDRD 0x2A / PORTD 0x2B) and of the ATmega2560 (DDRH 0x101 / PORTH
 * 0x102 ...); its PIN register just below that. */
static inline volatile uint8_t *pd_avr_ddr(volatile uint8_t *port)
{
    return port - 1;
}

#endif /* PD_AVR_PINS_H */

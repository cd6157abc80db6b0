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

static inline volatile uint8_t *pd_avr_port(uint8_t pin)
{
    return pin < 8 ? &PORTD : (pin < 14 ? &PORTB : &PORTC);
}

/* Each port's DDR register sits just below its PORT register (ATmega328P
 * datasheet, register summary: DDRB 0x24 / PORTB 0x25, DDRC 0x27 / PORTC 0x28,
 * DDRD 0x2A / PORTD 0x2B): one lookup instead of a second chain of compares. */
static inline volatile uint8_t *pd_avr_ddr(uint8_t pin)
{
    return pd_avr_port(pin) - 1;
}

static inline uint8_t pd_avr_mask(uint8_t pin)
{
    return (uint8_t)(1u << (pin < 8 ? pin : (pin < 14 ? pin - 8 : pin - 14)));
}

#endif /* PD_AVR_PINS_H */

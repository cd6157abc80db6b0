/*
 * The Arduino Mega 2560 (ATmega2560, make avr BOARD=mega): its pin map, the one
 * declaration of which Arduino pin is which port bit (pd_avr_mega.c), and the names
 * its vectors have where the ATmega328P's differ, and the 16-bit timers' PWM outputs.
 * The Uno's drivers do the rest: UART0 is the link (pins 0, 1), Timer0 the clock,
 * Timer1 and Timer5 the servo pulses (12 channels each, on any pin: they are written
 * through the port; pd_avr_servo.c), Timer2, Timer3 and Timer4 PWM (and Timer1 while no
 * servo runs; pd_avr_pwm.c).
 *
 * The build serves every pin, 0 .. PD_MAX_PINS - 1 (70: 0 .. 69, A0..A15 being 54..69): the
 * core's pin sets and the wire's are of any width (pd_pinset.h; protocol version 8).
 */
#ifndef PD_AVR_MEGA_H
#define PD_AVR_MEGA_H

#include <avr/io.h>
#include <avr/pgmspace.h>
#include <stdint.h>

#include "pd_hal.h"

#define PD_AVR_MEGA_PINS 70u

/* The board's table (pd_hal.h), pd_avr_mega.c. */
extern const pd_board_info_t pd_avr_mega_info;

/* The ports by index (pd_avr_mega_ports): A=0 .. H=7, J=8, K=9, L=10. */
enum { PD_PA, PD_PB, PD_PC, PD_PD, PD_PE, PD_PF, PD_PG, PD_PH, PD_PJ, PD_PK, PD_PL };

/* Pin N's port index << 3 | its bit there (PROGMEM); the ports' PORT registers. */
extern const uint8_t pd_avr_mega_pins[PD_AVR_MEGA_PINS] PROGMEM;
extern volatile uint8_t *const pd_avr_mega_ports[11];

/* The pins of the 8-bit timers' outputs the PWM driver uses (pd_avr_pwm.c): Timer2's. */
#define PD_AVR_PIN_OC2B 9u
#define PD_AVR_PIN_OC2A 10u
/*
 * The 16-bit timers' outputs it runs (pd_avr_mega.c): a pin, its timer (1, 3, 4, 5) and
 * the timer's output, 0..2 for A..C. A row is the whole of an output's driver: the four
 * timers' registers lie alike (pd_avr_pwm.c), so another output is one more row.
 */
typedef struct pd_avr_pwm16 {
    uint8_t pin;
    uint8_t timer;
    uint8_t output;
} pd_avr_pwm16_t;
extern const pd_avr_pwm16_t pd_avr_mega_pwm16[];
extern const uint8_t pd_avr_mega_pwm16_count;
/* Timer0's: the clock's timer; the Mega's board table keeps them from PWM (clock_timer_pins). */
#define PD_AVR_PIN_OC0B 4u
#define PD_AVR_PIN_OC0A 13u

/* The counters' external interrupts (pd_avr_inputs.c): INT0..INT3 on pins 21..18, INT4 and
 * INT5 on pins 2 and 3 (INT6, INT7 have no pin on the Mega). */
#define PD_AVR_COUNTERS 6u
#define PD_AVR_INT_OF(pin) ((pin) >= 18u ? (uint8_t)(21u - (pin)) : (uint8_t)((pin) + 2u))

/* The ATmega2560 has four USARTs: the link is USART0 (pins 0, 1, the USB bridge). */
#define USART_RX_vect USART0_RX_vect
#define USART_UDRE_vect USART0_UDRE_vect

#endif /* PD_AVR_MEGA_H */

/*
 * Inputs on the Uno (pd_hal.h, pd_inputs.c).
 *
 * - Digital inputs read PINx. A configured input also wakes the main loop on
 *   every change (its pin-change interrupt): the loop sleeps between
 *   interrupts, and without this an input's edge would wait for the next 1 ms
 *   clock tick to be seen. An interlock reacts within one pass of the loop
 *   (tens of microseconds), not within a millisecond.
 * - Analog inputs: one conversion at a time, never waited for; the ADC's
 *   interrupt wakes the loop when it is done, so conversions follow each other
 *   at the ADC's pace (13 ADC clocks at 125 kHz: 104 us) rather than the clock
 *   tick's. AVCC reference, 10 bits.
 * Both interrupts only set pd_avr_wake: an interrupt that lands after the
 * loop's pass has read the inputs but before it sleeps must still keep it
 * awake for one more pass (pd_avr_loop checks the flag with interrupts off),
 * or the change would wait for the next clock tick after all.
 * - Counters: INT0 (pin 2) and INT1 (pin 3), each edge counted in its
 *   interrupt (rising, falling or both, chosen in EICRA). What rate loses no
 *   edge is measured (docs/protocol.md, Counters): an edge is lost only when
 *   two come before the handler has run once.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <stdbool.h>
#include <util/atomic.h>

#include "pd_avr.h"
#include "pd_avr_pins.h"
#include "pd_features.h"
#include "pd_hal.h"

volatile uint8_t pd_avr_wake;

#if PD_FEATURE_DIGITAL_INPUT || PD_FEATURE_ANALOG_INPUT || PD_FEATURE_COUNTER

/* The pin's pin-change mask register and its bit there (PCINT0..23 follow the ports). */
static volatile uint8_t *pcmsk(uint8_t pin, uint8_t *bit, uint8_t *group)
{
    volatile uint8_t *port = pd_avr_port(pin, bit);
#if PD_BOARD_MEGA
    /* The Mega's pin changes: port B (PCINT0..7: pins 10-13, 50-53) and K (PCINT16..23:
     * A8-A15); of the rest only PE0 and PJ0..6 (PCINT8..15, pins 0, 15, 14), and pin 0
     * is the link. A pin without one is read at the next 1 ms clock tick: no wake-up. */
    if (port == &PORTJ) {
        *bit = (uint8_t)(*bit << 1);
        *group = _BV(PCIE1);
        return &PCMSK1;
    }
    if (port == &PORTK) {
        *group = _BV(PCIE2);
        return &PCMSK2;
    }
    if (port != &PORTB) {
        static uint8_t none; /* a mask no interrupt reads */
        *group = 0;
        return &none;
    }
#endif
    if (port == &PORTB) {
        *group = _BV(PCIE0);
        return &PCMSK0;
    }
    if (port == &PORTC) {
        *group = _BV(PCIE1);
        return &PCMSK1;
    }
    *group = _BV(PCIE2);
    return &PCMSK2;
}

void pd_avr_input_config(uint8_t pin, bool pull_up, bool wake)
{
    uint8_t bit;
    uint8_t group;
#if PD_BOARD_NANO
    if (pin >= 20u) {
        return; /* A6, A7: the ADC's inputs only, no port behind them */
    }
#endif
    volatile uint8_t *mask = pcmsk(pin, &bit, &group);
    pd_avr_pin_set(pin, false, pull_up); /* an input; PORT's bit is the pull-up */
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        if (pin >= PD_AVR_FIRST_ANALOG) {
            /* Its digital input buffer back on (an analog input's conversions turn it off). */
            DIDR0 &= (uint8_t)~bit;
        }
        if (wake) {
            *mask |= bit;
            PCICR |= group;
        } else {
            *mask &= (uint8_t)~bit;
        }
    }
}

#if PD_BOARD_MEGA
uint32_t pd_avr_pins_read(void)
{
    /* The Mega's pins are spread over eight ports: each read at its PIN register (its
     * PORT's address less 2, pd_avr_pins.h). */
    uint32_t levels = 0;
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t bit;
        volatile uint8_t *port = pd_avr_port(pin, &bit);
        if (*(port - 2) & bit) {
            levels |= 1UL << pin;
        }
    }
    return levels;
}
#else
uint32_t pd_avr_pins_read(void)
{
    /* Uno pins: D0..D7 = PIND, D8..D13 = PINB0..5, A0..A5 (14..19) = PINC0..5. */
    return (uint32_t)PIND | (uint32_t)(PINB & 0x3Fu) << 8 | (uint32_t)(PINC & 0x3Fu) << 14;
}
#endif

/* pd_avr_wake = 1, touching no flag of SREG: 4 B of stack, 9 cycles. */
#define PD_WAKE_ISR(vector)                                                  \
    ISR(vector, ISR_NAKED)                                                   \
    {                                                                        \
        __asm__ volatile("push r24\n\t"                                      \
                         "ldi r24, 1\n\t"                                    \
                         "sts %[wake], r24\n\t"                              \
                         "pop r24\n\t"                                       \
                         "reti\n\t"                                          \
                         :                                                   \
                         : [wake] "i"(&pd_avr_wake));                        \
    }

PD_WAKE_ISR(PCINT0_vect)
PD_WAKE_ISR(PCINT1_vect)
PD_WAKE_ISR(PCINT2_vect)

#endif

#if PD_FEATURE_ANALOG_INPUT

void pd_avr_analog_start(uint8_t pin)
{
    ADMUX = (uint8_t)(_BV(REFS0) | ((pin - 14u) & 0x07u)); /* AVCC, channel A0..A5 (A7) */
#if PD_BOARD_NANO
    if (pin < 20u) /* A6, A7 have no digital input buffer (DIDR0's bits 6, 7 are reserved) */
#endif
        DIDR0 |= (uint8_t)_BV((pin - 14u) & 0x07u); /* no digital input buffer there */
    ADCSRA = _BV(ADEN) | _BV(ADSC) | _BV(ADIE) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
}

bool pd_avr_analog_done(uint16_t *counts)
{
    if (ADCSRA & _BV(ADSC)) {
        return false;
    }
    *counts = ADC;
    return true;
}

PD_WAKE_ISR(ADC_vect)

#endif

#if PD_FEATURE_COUNTER

volatile uint32_t pd_avr_counts[PD_AVR_COUNTERS]; /* per INTn (PD_AVR_INT_OF: pd_avr.h) */
#define counts pd_avr_counts

/*
 * count += 1 with one register: subtracting 0xFF adds one, and the borrow is
 * set unless that byte wrapped, so each next byte subtracts 0xFF with it (adds
 * one only after a wrap). The compiler's handler saved seven registers for
 * the same: every byte of an interrupt's frame can land on the deepest stack
 * (test_stack_margin), and 36 cycles instead of 53 is a higher edge rate
 * counted without a loss.
 */
#define PD_COUNT_ISR(vector, n)                                              \
    ISR(vector, ISR_NAKED)                                                   \
    {                                                                        \
        __asm__ volatile("push r24\n\t"                                      \
                         "in r24, __SREG__\n\t"                              \
                         "push r24\n\t"                                      \
                         "lds r24, %[c0]\n\t"                                \
                         "subi r24, 0xFF\n\t"                                \
                         "sts %[c0], r24\n\t"                                \
                         "lds r24, %[c1]\n\t"                                \
                         "sbci r24, 0xFF\n\t"                                \
                         "sts %[c1], r24\n\t"                                \
                         "lds r24, %[c2]\n\t"                                \
                         "sbci r24, 0xFF\n\t"                                \
                         "sts %[c2], r24\n\t"                                \
                         "lds r24, %[c3]\n\t"                                \
                         "sbci r24, 0xFF\n\t"                                \
                         "sts %[c3], r24\n\t"                                \
                         "pop r24\n\t"                                       \
                         "out __SREG__, r24\n\t"                             \
                         "pop r24\n\t"                                       \
                         "reti\n\t"                                          \
                         :                                                   \
                         : [c0] "i"((uint8_t *)&counts[n] + 0),              \
                           [c1] "i"((uint8_t *)&counts[n] + 1),              \
                           [c2] "i"((uint8_t *)&counts[n] + 2),              \
                           [c3] "i"((uint8_t *)&counts[n] + 3));             \
    }

PD_COUNT_ISR(INT0_vect, 0)
PD_COUNT_ISR(INT1_vect, 1)
#if PD_BOARD_MEGA
PD_COUNT_ISR(INT2_vect, 2)
PD_COUNT_ISR(INT3_vect, 3)
PD_COUNT_ISR(INT4_vect, 4)
PD_COUNT_ISR(INT5_vect, 5)
#endif

/* EICRA's ISCn1:ISCn0 for an Edge (protoduino.proto): rising 11, falling 10, both 01. */
static const uint8_t sense[3] = {3u, 2u, 1u};

void pd_avr_counter_start(uint8_t pin, uint8_t edge)
{
    uint8_t n = PD_AVR_INT_OF(pin);
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        /* No wake-up per edge (pd_avr_input_config gave it one): the loop reads the
         * count once per report interval, and at 40,000 edges a second a loop pass
         * per edge would take the whole CPU. PD2, PD3 are PCINT18, PCINT19. */
#if PD_BOARD_MEGA
        /* The Mega's INTn pins have no pin-change interrupt; INT4..INT7 sense in EICRB. */
        volatile uint8_t *eicr = n < 4u ? &EICRA : &EICRB;
        uint8_t at = (uint8_t)(2u * (n & 3u));
        EIMSK &= (uint8_t)~_BV(n);
        *eicr = (uint8_t)((*eicr & ~(3u << at)) | (sense[edge < 3u ? edge : 2u] << at));
#else
        PCMSK2 &= (uint8_t)~_BV(pin);
        EIMSK &= (uint8_t)~_BV(n);
        EICRA = (uint8_t)((EICRA & ~(3u << (2u * n))) | (sense[edge < 3u ? edge : 2u] << (2u * n)));
#endif
        EIFR = _BV(n); /* an edge from before does not count */
        counts[n] = 0;
        EIMSK |= _BV(n);
    }
}

uint32_t pd_avr_counter_read(uint8_t pin)
{
    uint32_t n;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        n = counts[PD_AVR_INT_OF(pin)];
    }
    return n;
}

void pd_avr_counter_stop(uint8_t pin)
{
    EIMSK &= (uint8_t)~_BV(PD_AVR_INT_OF(pin));
}

#endif

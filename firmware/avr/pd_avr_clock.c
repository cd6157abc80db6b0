/* millis() on Timer0: CTC mode, 16 MHz / 64 / 250 = exactly 1 kHz. */
#ifndef ARDUINO /* the Arduino IDE's core owns Timer0 and provides millis() */

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#include "pd_avr.h"

static volatile uint32_t ms;

void pd_avr_clock_init(void)
{
    TCCR0A = _BV(WGM01);
    OCR0A = PD_AVR_T0_TOP;
    TCCR0B = _BV(CS01) | _BV(CS00);
    TIMSK0 = _BV(OCIE0A);
}

/* Interruptible (its flag clears on entry): a servo edge never waits for it. */
ISR(TIMER0_COMPA_vect, ISR_NOBLOCK)
{
    ms++;
}

uint32_t pd_avr_millis(void)
{
    uint32_t now;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        now = ms;
    }
    return now;
}

uint8_t pd_avr_millis8(void)
{
    return (uint8_t)ms; /* one byte: read whole, whatever the interrupt does */
}

#endif

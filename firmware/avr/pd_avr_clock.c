/*
 * millis() on Timer0 as Arduino's wiring.c makes it: fast PWM, TOP 255, clk / 64,
 * so the timer overflows every 1,024 us (976.5625 Hz) and its compare outputs
 * OC0A (pin 6) and OC0B (pin 5) do PWM at that frequency (pd_avr_pwm.c). The
 * overflow interrupt adds 1 ms and 24 us of fraction, counted in 8 us units (3 of
 * 125): the clock gains the extra millisecond when the fraction reaches one, so
 * millis() never drifts (it steps by 2 once every 41 or 42 overflows, as the
 * Arduino core's does).
 */
#ifndef ARDUINO /* the Arduino IDE's core owns Timer0 and provides millis() */

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#include "pd_avr.h"

static volatile uint32_t ms;
static volatile uint8_t fract; /* of the next millisecond, in 8 us units (0..124) */

void pd_avr_clock_init(void)
{
    TCCR0A = _BV(WGM01) | _BV(WGM00); /* fast PWM, TOP 255 (mode 3) */
    TCCR0B = _BV(CS01) | _BV(CS00);   /* clk / 64: 976.5625 Hz */
    TIMSK0 = _BV(TOIE0);
}

/*
 * ms += 1 (or 2 when the fraction wraps), fract += 3 (mod 125), in two registers,
 * interrupts on from the first instruction (a servo edge never waits behind
 * it). Subtracting -n adds n, and the borrow is set unless that byte wrapped, so
 * each next byte subtracts 0xFF with it (adds one only after a wrap): 7 B of
 * stack where the compiler's frame took 11.
 */
ISR(TIMER0_OVF_vect, ISR_NAKED)
{
    __asm__ volatile("sei\n\t"
                     "sbi %[pass], %[bit]\n\t" /* a pass is due: the failsafe's check */
                     "push r24\n\t"
                     "in r24, __SREG__\n\t"
                     "push r24\n\t"
                     "push r25\n\t"
                     "ldi r25, 0xFF\n\t" /* -1 */
                     "lds r24, %[f]\n\t"
                     "subi r24, 0xFD\n\t" /* + 3 */
                     "cpi r24, %[fmax]\n\t"
                     "brlo 1f\n\t"
                     "subi r24, %[fmax]\n\t"
                     "ldi r25, 0xFE\n\t" /* -2 */
                     "1:\n\t"
                     "sts %[f], r24\n\t"
                     "lds r24, %[c0]\n\t"
                     "sub r24, r25\n\t"
                     "sts %[c0], r24\n\t"
                     "lds r24, %[c1]\n\t"
                     "sbci r24, 0xFF\n\t"
                     "sts %[c1], r24\n\t"
                     "lds r24, %[c2]\n\t"
                     "sbci r24, 0xFF\n\t"
                     "sts %[c2], r24\n\t"
                     "lds r24, %[c3]\n\t"
                     "sbci r24, 0xFF\n\t"
                     "sts %[c3], r24\n\t"
                     "pop r25\n\t"
                     "pop r24\n\t"
                     "out __SREG__, r24\n\t"
                     "pop r24\n\t"
                     "reti\n\t"
                     :
                     : [pass] "I"(_SFR_IO_ADDR(PD_AVR_PASS)), [bit] "I"(PD_AVR_PASS_BIT),
                       [f] "i"(&fract), [fmax] "M"(125),
                       [c0] "i"((uint8_t *)&ms + 0), [c1] "i"((uint8_t *)&ms + 1),
                       [c2] "i"((uint8_t *)&ms + 2), [c3] "i"((uint8_t *)&ms + 3));
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
    /* One byte, read whole whatever the interrupt does; only that byte: `(uint8_t)ms`
     * read all four of the volatile (6 cycles more on every pass of the main loop). */
    return *(volatile const uint8_t *)&ms;
}

#endif

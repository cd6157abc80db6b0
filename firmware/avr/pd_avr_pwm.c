/*
 * PWM outputs on the Uno, as Arduino's analogWrite makes them: fast PWM with
 * TOP 255 and prescaler 64 (976 Hz), high for OCR + 1 of every 256 ticks.
 * Unlike analogWrite, duty d (of 255) gets the OCR whose (OCR + 1) / 256 is
 * the closest to d / 255: d - 1 below 128, d from 128 (so a duty is within
 * half a step of what was asked, and the emulated Uno's trace, which rounds
 * 255 x high / period, reads d back). Phase-correct PWM would be exact, but
 * simavr 1.6 makes no compare-output edges in it, so nothing could judge it at
 * the pin. Duties 0 and 255 disconnect the timer and drive the pin's level, as
 * analogWrite does.
 *
 *   pins 3 (OC2B) and 11 (OC2A): Timer2, free for PWM;
 *   pins 9 (OC1A) and 10 (OC1B): Timer1, which otherwise makes the servo
 *     pulses. The core lets them do PWM only while no servo is configured
 *     (pd_board_info_t.servo_timer_pins): the first takes the timer over from
 *     the servo driver, and the last one released gives it back.
 *   pins 6 (OC0A) and 5 (OC0B): Timer0, which also keeps the millisecond
 *     clock from its overflow as Arduino's wiring.c does (pd_avr_clock.c): it
 *     runs in this same mode from power-up, so its outputs only connect.
 */
#include <avr/io.h>
#include <stdbool.h>
#include <util/atomic.h>

#include "pd_avr.h"
#include "pd_features.h"

#if PD_FEATURE_PWM

/*
 * The pins this driver runs, one bit per pin number: tools/avrsim reads it from the MCU's
 * RAM (by its symbol) to trace them as PWM, duties 0 and 255 included (the timer is
 * disconnected for those, and the pin looks like any digital output). Keep its name and
 * its layout, or change the runner with it.
 */
static volatile uint8_t pd_avr_pwm_pins[3]; /* pin n: bit n % 8 of byte n / 8 */

/* The pin's output-compare register and its compare-output bit (COMxy1) in *com. */
static volatile uint8_t *pwm_ocr(uint8_t pin, volatile uint8_t **tccra, uint8_t *com)
{
    switch (pin) {
    case PD_AVR_PIN_OC2B:
        *tccra = &TCCR2A;
        *com = _BV(COM2B1);
        return &OCR2B;
    case PD_AVR_PIN_OC2A:
        *tccra = &TCCR2A;
        *com = _BV(COM2A1);
        return &OCR2A;
    case PD_AVR_PIN_OC0B:
        *tccra = &TCCR0A;
        *com = _BV(COM0B1);
        return &OCR0B;
    case PD_AVR_PIN_OC0A:
        *tccra = &TCCR0A;
        *com = _BV(COM0A1);
        return &OCR0A;
    case PD_AVR_PIN_OC1A:
        *tccra = &TCCR1A;
        *com = _BV(COM1A1);
        return (volatile uint8_t *)&OCR1AL;
    case PD_AVR_PIN_OC1B:
        *tccra = &TCCR1A;
        *com = _BV(COM1B1);
        return (volatile uint8_t *)&OCR1BL;
    default:
        return 0;
    }
}

void pd_avr_pwm_write(uint8_t pin, uint8_t duty)
{
    volatile uint8_t *tccra;
    uint8_t com;
    volatile uint8_t *ocr = pwm_ocr(pin, &tccra, &com);
    if (ocr == 0) {
        return;
    }
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        pd_avr_pwm_pins[pin >> 3] |= (uint8_t)(1u << (pin & 7u)); /* before the pin turns output */
        if (tccra == &TCCR1A && !(TCCR1A & _BV(WGM10))) {
            /* Timer1 leaves the servos (none is configured: the core checked), or
             * starts from its power-up state in a build without servos. */
            TIMSK1 &= (uint8_t)~_BV(OCIE1A);
            /* Compares and count below TOP, written while the mode has no double
             * buffer: a compare time the servos left above 255 (up to 0xFFFF) stayed
             * in simavr's OCR1A, and a count above TOP would first run to 0xFFFF. */
            OCR1A = 0;
            OCR1B = 0;
            TCNT1 = 0;
            TCCR1A = _BV(WGM10); /* fast PWM, 8-bit (mode 5) */
            TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10);
        } else if (tccra == &TCCR2A && !(TCCR2A & _BV(WGM20))) {
            TCCR2A = _BV(WGM21) | _BV(WGM20); /* fast PWM, TOP 255 */
            TCCR2B = _BV(CS22); /* clk / 64 on Timer2 */
        }
        if (duty == 0 || duty == 255) {
            *tccra &= (uint8_t)~com; /* a steady level: the port drives it */
            pd_avr_pin_set(pin, true, duty != 0);
        } else {
            if (tccra == &TCCR1A) {
                OCR1AH = 0; /* 16-bit registers: the high byte is written first */
            }
            *ocr = duty < 128u ? (uint8_t)(duty - 1u) : duty;
            *tccra |= com;
            pd_avr_pin_set(pin, true, false);
        }
    }
}

void pd_avr_pwm_release(uint8_t pin)
{
    volatile uint8_t *tccra;
    uint8_t com;
    if (pwm_ocr(pin, &tccra, &com) == 0) {
        return;
    }
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        *tccra &= (uint8_t)~com;
        pd_avr_pin_set(pin, false, false);
        pd_avr_pwm_pins[pin >> 3] &= (uint8_t)~(1u << (pin & 7u)); /* once an input */
        if (tccra == &TCCR1A && !(TCCR1A & (_BV(COM1A1) | _BV(COM1B1)))) {
            /* The last PWM pin of Timer1: the servos may have it back. */
            pd_avr_servo_init();
        }
    }
}

#endif /* PD_FEATURE_PWM */

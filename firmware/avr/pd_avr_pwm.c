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
 *
 * The Mega's: Timer2 on 9 (OC2B), 10 (OC2A); its 16-bit timers' outputs from the rows
 * of pd_avr_mega_pwm16 (pd_avr_mega.c), each timer in Timer1's mode: Timer3 on 5, 2, 3,
 * Timer4 on 6, 7, 8, free for PWM; Timer1 on 11, 12 and Timer5 on 44..46 (beyond the
 * pins served), the servos' timers, taken over and given back as the Uno's Timer1.
 */
#include <avr/io.h>
#include <stdbool.h>
#include <util/atomic.h>

#include "pd_avr.h"
#include "pd_features.h"
#include "pd_hal.h"

#if PD_FEATURE_PWM

/*
 * The pins this driver runs, one bit per pin number: tools/avrsim reads it from the MCU's
 * RAM (by its symbol) to trace them as PWM, duties 0 and 255 included (the timer is
 * disconnected for those, and the pin looks like any digital output). Keep its name and
 * its layout, or change the runner with it.
 */
static volatile uint8_t pd_avr_pwm_pins[(PD_MAX_PINS + 7u) / 8u]; /* pin n: bit n % 8 of byte n / 8 */

/*
 * A 16-bit timer's registers from its TCCRnA, alike on Timers 1, 3, 4 and 5 (the
 * datasheets' register summaries: TCCRnB next, TCNTn 4 bytes on, OCRnA, OCRnB and OCRnC 8,
 * 10 and 12 bytes on, each low byte first) and its interrupt mask; the servos' timers,
 * whose compare interrupts the PWM takes over (Timer1; the Mega's Timer5 too).
 */
#if PD_BOARD_MEGA
#define PWM_WIDE(tccra) ((tccra) != &TCCR2A && (tccra) != &TCCR0A)
#define PWM_TIMSK(tccra)                                                                    \
    ((tccra) == &TCCR1A ? &TIMSK1 : (tccra) == &TCCR3A ? &TIMSK3 : (tccra) == &TCCR4A ? &TIMSK4 \
                                                                                       : &TIMSK5)
#define PWM_SERVO_TIMER(tccra) ((tccra) == &TCCR1A || (tccra) == &TCCR5A)
#else
#define PWM_WIDE(tccra) ((tccra) == &TCCR1A)
#define PWM_TIMSK(tccra) (&TIMSK1)
#define PWM_SERVO_TIMER(tccra) ((tccra) == &TCCR1A)
#endif
#define PWM_OCR(tccra, output) ((volatile uint16_t *)((tccra) + 8u + 2u * (output)))
/* COMnA1, COMnB1, COMnC1: bits 7, 5 and 3 of TCCRnA. */
#define PWM_COM(output) ((uint8_t)(0x80u >> (2u * (output))))
#define PWM_COMS (PWM_COM(0) | PWM_COM(1) | PWM_COM(2))

/* The pin's output-compare register and its compare-output bit (COMxy1) in *com. */
static volatile uint8_t *pwm_ocr(uint8_t pin, volatile uint8_t **tccra, uint8_t *com)
{
#if PD_BOARD_MEGA
    for (uint8_t i = 0; i < pd_avr_mega_pwm16_count; i++) {
        const pd_avr_pwm16_t *o = &pd_avr_mega_pwm16[i];
        if (o->pin == pin) {
            static volatile uint8_t *const tccras[] = {&TCCR1A, &TCCR3A, &TCCR4A, &TCCR5A};
            *tccra = tccras[o->timer == 1 ? 0 : o->timer - 2u];
            *com = PWM_COM(o->output);
            return (volatile uint8_t *)PWM_OCR(*tccra, o->output);
        }
    }
#endif
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
#if !PD_BOARD_MEGA
    case PD_AVR_PIN_OC1A:
        *tccra = &TCCR1A;
        *com = _BV(COM1A1);
        return (volatile uint8_t *)&OCR1AL;
    case PD_AVR_PIN_OC1B:
        *tccra = &TCCR1A;
        *com = _BV(COM1B1);
        return (volatile uint8_t *)&OCR1BL;
#endif
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
        if (PWM_WIDE(tccra) && !(*tccra & _BV(WGM10))) {
            /* A 16-bit timer starts PWM: Timer1 (the Mega's Timer5 too) leaves the
             * servos (none is configured: the core checked), or it starts from its
             * power-up state (in a build without servos; the Mega's Timers 3, 4). */
            *PWM_TIMSK(tccra) &= (uint8_t)~_BV(OCIE1A);
            /* Compares and count below TOP, written while the mode has no double
             * buffer: a compare time the servos left above 255 (up to 0xFFFF) stayed
             * in simavr's OCR1A, and a count above TOP would first run to 0xFFFF. */
            *PWM_OCR(tccra, 0) = 0;
            *PWM_OCR(tccra, 1) = 0;
#if PD_BOARD_MEGA
            *PWM_OCR(tccra, 2) = 0;
#endif
            *(volatile uint16_t *)(tccra + 4) = 0;             /* TCNTn */
            *tccra = _BV(WGM10);                                /* fast PWM, 8-bit (mode 5) */
            tccra[1] = _BV(WGM12) | _BV(CS11) | _BV(CS10);     /* TCCRnB: clk / 64 */
        } else if (tccra == &TCCR2A && !(TCCR2A & _BV(WGM20))) {
            TCCR2A = _BV(WGM21) | _BV(WGM20); /* fast PWM, TOP 255 */
            TCCR2B = _BV(CS22); /* clk / 64 on Timer2 */
        }
        if (duty == 0 || duty == 255) {
            /* A steady level: the port drives it. Its bit first, while the compare output
             * still overrides it: disconnected first, the pin showed the old PORT bit for a
             * few cycles (a glitch low on the way from a PWM high to 255, seen at the pin by
             * tools/avrsim once it sampled at each timer register write). */
            pd_avr_pin_set(pin, true, duty != 0);
            *tccra &= (uint8_t)~com;
        } else {
            if (PWM_WIDE(tccra)) {
                ocr[1] = 0; /* 16-bit registers: the high byte is written first */
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
        /* An input first (a compare output reaches only an output pin), then disconnected:
         * the other order drove the PORT bit for a few cycles (pd_avr_pwm_write). */
        pd_avr_pin_set(pin, false, false);
        *tccra &= (uint8_t)~com;
        pd_avr_pwm_pins[pin >> 3] &= (uint8_t)~(1u << (pin & 7u)); /* once an input */
        if (PWM_SERVO_TIMER(tccra) && !(*tccra & PWM_COMS)) {
            /* The last PWM pin of a servos' timer: the servos may have it back. */
            pd_avr_servo_init();
        }
    }
}

#endif /* PD_FEATURE_PWM */

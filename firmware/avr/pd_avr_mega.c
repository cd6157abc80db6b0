/*
 * The Mega 2560's pin map (pd_avr_mega.h): Arduino's numbering of the ATmega2560's
 * ports, as the Mega's pins_arduino.h has it; its 16-bit timers' PWM outputs (a row
 * each); and its board table, which DeviceInfo states: 24 servos on Timer1 and Timer5,
 * PWM on Timers 2, 3, 4 (and 1, and 5), the clock on Timer0 (firmware/README.md, The Mega
 * 2560). Built for make avr BOARD=mega; its board table also for the simulated board (make
 * sim: `pd_sim --board mega`, firmware/posix/pd_sim.c), which serves the Mega's pins from this
 * one declaration of them.
 */
#ifdef __AVR__
#include "pd_avr.h"
#define PD_MEGA_RX_BUFFER (PD_AVR_RX_SIZE - 1u) /* a ring keeps one slot free */
#else
#include "pd_hal.h"
extern const pd_board_info_t pd_avr_mega_info;
#define PD_BOARD_MEGA 1
#define PD_MEGA_RX_BUFFER 0u /* the simulated board's link has its own (pd_sim.c) */
#endif

#if PD_BOARD_MEGA

#ifdef __AVR__
#define P(port, bit) (uint8_t)((PD_##port) << 3 | (bit))

const uint8_t pd_avr_mega_pins[PD_AVR_MEGA_PINS] PROGMEM = {
    P(PE, 0), P(PE, 1), P(PE, 4), P(PE, 5), P(PG, 5), P(PE, 3), P(PH, 3), P(PH, 4), /* 0-7 */
    P(PH, 5), P(PH, 6), P(PB, 4), P(PB, 5), P(PB, 6), P(PB, 7), P(PJ, 1), P(PJ, 0), /* 8-15 */
    P(PH, 1), P(PH, 0), P(PD, 3), P(PD, 2), P(PD, 1), P(PD, 0), P(PA, 0), P(PA, 1), /* 16-23 */
    P(PA, 2), P(PA, 3), P(PA, 4), P(PA, 5), P(PA, 6), P(PA, 7), P(PC, 7), P(PC, 6), /* 24-31 */
    P(PC, 5), P(PC, 4), P(PC, 3), P(PC, 2), P(PC, 1), P(PC, 0), P(PD, 7), P(PG, 2), /* 32-39 */
    P(PG, 1), P(PG, 0), P(PL, 7), P(PL, 6), P(PL, 5), P(PL, 4), P(PL, 3), P(PL, 2), /* 40-47 */
    P(PL, 1), P(PL, 0), P(PB, 3), P(PB, 2), P(PB, 1), P(PB, 0),                     /* 48-53 */
    P(PF, 0), P(PF, 1), P(PF, 2), P(PF, 3), P(PF, 4), P(PF, 5), P(PF, 6), P(PF, 7), /* A0-A7 */
    P(PK, 0), P(PK, 1), P(PK, 2), P(PK, 3), P(PK, 4), P(PK, 5), P(PK, 6), P(PK, 7), /* A8-A15 */
};

volatile uint8_t *const pd_avr_mega_ports[11] = {
    &PORTA, &PORTB, &PORTC, &PORTD, &PORTE, &PORTF, &PORTG, &PORTH, &PORTJ, &PORTK, &PORTL,
};

/*
 * PWM on the 16-bit timers (pd_avr_pwm.c): Timer1's 11, 12 (13, OC1C, is also Timer0's
 * OC0A: the clock's), Timer3's 5, 2, 3, Timer4's 6, 7, 8 and Timer5's 46, 45, 44 (Timer5
 * makes servo pulses, so they are servo_timer_2_pins below, as Timer1's 11 and 12 are
 * servo_timer_pins).
 */
const pd_avr_pwm16_t pd_avr_mega_pwm16[] = {
    {11, 1, 0}, {12, 1, 1},            /* OC1A, OC1B */
    {5, 3, 0},  {2, 3, 1},  {3, 3, 2}, /* OC3A, OC3B, OC3C */
    {6, 4, 0},  {7, 4, 1},  {8, 4, 2}, /* OC4A, OC4B, OC4C */
#if PD_MAX_PINS > 46
    {46, 5, 0}, {45, 5, 1}, {44, 5, 2}, /* OC5A, OC5B, OC5C */
#endif
};
const uint8_t pd_avr_mega_pwm16_count = sizeof pd_avr_mega_pwm16 / sizeof pd_avr_mega_pwm16[0];
#endif /* __AVR__ */

/*
 * The board's one declaration of its pins (pd_hal.h): DeviceInfo's pin table is written
 * from it, and the host refuses from that. Pins 0 .. 69 (PD_MAX_PINS, pd_avr_mega.h); its pin
 * sets (pd_pinset.h) are three words, pins 0..31, 32..63 and 64..69.
 * - PWM: Timer2 on pins 9 (OC2B) and 10 (OC2A); Timer3 on 5, 2, 3 (OC3A..C) and Timer4
 *   on 6, 7, 8 (OC4A..C), free whatever the servos do; Timer1 on 11 (OC1A) and 12 (OC1B)
 *   and Timer5 on 46, 45, 44 (OC5A..C), servo timers (as the Uno's 9 and 10): only while no
 *   servo runs on that timer. Timer0 runs the clock: 4 (OC0B) and 13 (OC0A, also OC1C) are
 *   refused with TIMER_IN_USE. Six PWM outputs at once (PD_MAX_PWM: OutputStates.pwm_duties'
 *   bound).
 * - Servos: 24 (PD_MAX_SERVOS, firmware/Makefile), on any digital pin, written through
 *   the port by two timers' compare interrupts as the Arduino Servo library does:
 *   channels 0 .. 11 on Timer1, 12 .. 23 on Timer5 (pd_avr_servo.c). While a servo runs
 *   on a timer that timer makes no PWM: Timer1's 11 and 12 (servo_timer_pins) and Timer5's
 *   44 .. 46 (servo_timer_2_pins).
 * - Counters on the six external interrupts: pins 21, 20, 19, 18 (INT0..INT3), 2 and 3
 *   (INT4, INT5).
 * - Analog inputs A0..A15, pins 54..69 (ADC0..ADC15; pd_avr_inputs.c).
 */
const pd_board_info_t pd_avr_mega_info = {
    .board = "mega",
    .num_pins = PD_MAX_PINS,
    .max_servos = 24,
    .reserved_pins = PD_PINSET(PD_PIN(0) | PD_PIN(1), 0, 0), /* RX0, TX0: the link itself */
    .rx_buffer = PD_MEGA_RX_BUFFER,
    .pwm_pins = PD_PINSET(PD_PIN(2) | PD_PIN(3) | (0x3FUL << 5) | PD_PIN(11) | PD_PIN(12), /* 5..10 */
                          PD_PIN(44 - 32) | PD_PIN(45 - 32) | PD_PIN(46 - 32), 0),
    .analog_pins = PD_PINSET(0, 0xFFC00000UL, 0x3FUL), /* A0..A15: 54..63, 64..69 */
    .counter_pins = PD_PINSET(PD_PIN(2) | PD_PIN(3) | (0xFUL << 18), 0, 0), /* INT4, INT5; INT3..INT0 */
    .servo_timer_pins = PD_PINSET(PD_PIN(11) | PD_PIN(12), PD_PIN(44 - 32) | PD_PIN(45 - 32) | PD_PIN(46 - 32), 0),
    .clock_timer_pins = PD_PINSET(PD_PIN(4) | PD_PIN(13), 0, 0),
    .servo_timer = 1,
    .clock_timer = 0,
    .servo_timer_2 = 5,
    .servo_timer_2_pins = PD_PINSET(0, PD_PIN(44 - 32) | PD_PIN(45 - 32) | PD_PIN(46 - 32), 0), /* OC5C..A */
};
#ifdef __AVR__
typedef char pd_assert_mega_pins[PD_MAX_PINS == PD_AVR_MEGA_PINS ? 1 : -1];
#endif

#endif /* PD_BOARD_MEGA */

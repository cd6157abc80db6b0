/*
 * ATmega328P (Arduino Uno) drivers behind the core's HAL: an interrupt-driven
 * UART, a millisecond clock on Timer0's overflow (its outputs do PWM), servo pulses from Timer1 compare
 * interrupts, and the Uno's pin numbering. Plain avr-libc, no Arduino core.
 */
#ifndef PD_AVR_H
#define PD_AVR_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_pinset.h" /* PD_MAX_PINS; PD_BOARD_* in the Arduino library (its pd_config.h) */

#if PD_BOARD_MEGA
#include "pd_avr_mega.h" /* the Mega 2560's pin map and vector names */
#define PD_AVR_FIRST_ANALOG 54u /* A0 */
#else
#define PD_AVR_FIRST_ANALOG 14u /* A0 */
/* The Uno's pins of the timer outputs the PWM driver runs (pd_avr_pwm.c). */
#define PD_AVR_PIN_OC2B 3u
#define PD_AVR_PIN_OC2A 11u
#define PD_AVR_PIN_OC1A 9u
#define PD_AVR_PIN_OC1B 10u
#define PD_AVR_PIN_OC0B 5u
#define PD_AVR_PIN_OC0A 6u
/* The counters' external interrupts: INT0 on pin 2, INT1 on pin 3 (pd_avr_inputs.c). */
#define PD_AVR_COUNTERS 2u
#define PD_AVR_INT_OF(pin) ((pin) == 3u ? 1u : 0u)
#endif

/* UART receive ring: 8 ms of line time at 115200 baud, five servo commands
 * in flight (DeviceInfo.rx_buffer: the host keeps its frames in flight within
 * it, and a single frame of any length still streams through, the core taking
 * its bytes as they come). 96 rather than 128: the pin modes took the rest of
 * the RAM budget; the 48 B that protocol version 5's one-byte message ids freed
 * in the dedupe window came here (firmware/README.md). The one place its size is set:
 * at PD_AVR_RX_FAST_1M (96) or more the board also offers 1,000,000 baud
 * (pd_avr_main.c). */
#ifndef PD_AVR_RX_SIZE
#define PD_AVR_RX_SIZE 96u
#endif
/* UART transmit ring: the most one received frame can make the device send
 * (PD_TX_RESERVE, pd_link.h: 116 B on the Uno, a ring keeps one byte free), and no
 * more; a report goes only into an empty ring (pd_link_send_spare), so it needs no
 * room of its own. */
#define PD_AVR_TX_SIZE (PD_TX_RESERVE + 1u)

void pd_avr_uart_init(uint32_t baud);
/* Switch to `baud` once every queued byte went out (waits for them). */
void pd_avr_uart_set_baud(uint32_t baud);
/* The oldest received byte, left in the ring, or -1 if none. */
int16_t pd_avr_uart_peek(void);
/* Remove the oldest received byte (after a successful peek). */
void pd_avr_uart_drop(void);
bool pd_avr_uart_rx_empty(void);
/* Whether every queued byte has gone to the UART. */
bool pd_avr_uart_tx_empty(void);
/* Bytes the transmit ring can take now. */
uint8_t pd_avr_uart_tx_room(void);
/* Queue `len` bytes for transmission, all or none (false: no room); never waits. */
bool pd_avr_uart_write(const uint8_t *data, uint16_t len);

/* Timer0 in fast PWM at 976 Hz, its overflow counting the milliseconds as
 * Arduino's wiring.c does (pd_avr_clock.c). Not used inside the Arduino IDE
 * build, whose core owns Timer0 and provides millis() the same way. */
void pd_avr_clock_init(void);
uint32_t pd_avr_millis(void);
/* The clock's low byte: one load, no interrupt lock (the main loop's tick test). */
uint8_t pd_avr_millis8(void);

void pd_avr_servo_init(void);
/* Start or update pulses on `pin` for `channel`; first call attaches the pin. */
void pd_avr_servo_write(uint8_t channel, uint8_t pin, uint16_t us);
/* Hold servo writes (true) until the release (false), then apply them all at
 * the next frame start (pd_hal_servo_hold; on the Mega each servo timer's next frame
 * start, Timer1's for channels 0..11 and Timer5's for 12..23). */
void pd_avr_servo_hold(bool hold);
/* Whether a channel's written width waits for its frame start (pd_hal_servo_pending). */
bool pd_avr_servo_pending(void);
/* Stop the channel's pulses after the one under way; a later write attaches again. */
void pd_avr_servo_detach(uint8_t channel);
/* Start the next servo frame as soon as possible (failsafe, Stop). */
void pd_avr_servo_expedite(void);

/* PWM (pd_avr_pwm.c): duty 0..255 on pins 3, 5, 6, 9, 10, 11 (the Mega's: 2, 3, 5..12);
 * release: an input again. */
void pd_avr_pwm_write(uint8_t pin, uint8_t duty);
void pd_avr_pwm_release(uint8_t pin);

/* A pass of the main loop is due: bit 0 of GPIOR0, set with one `sbi` (no register, no flag
 * of SREG touched) by the interrupts whose news the loop waits for: a received delimiter,
 * every second received byte, a byte lost to a full ring, the transmit ring emptied, the
 * clock tick, an input's (a pin change, an analog conversion done). Any other interrupt
 * wakes the MCU, and the loop sleeps again at once (pd_avr_loop). In the Arduino IDE's
 * build the core's own clock interrupt cannot set it: there every interrupt makes a pass,
 * as before. */
#define PD_AVR_PASS GPIOR0
#define PD_AVR_PASS_BIT 0
/* Bit 1 beside it: news for the core's poll, a delimiter came in (a command ran, a Ping fed
 * the failsafe) or an input's interrupt (its handler sets both bits). */
#define PD_AVR_NEWS_BIT 1

/* Inputs (pd_avr_inputs.c). wake: a change of the pin wakes the main loop. */
void pd_avr_input_config(uint8_t pin, bool pull_up, bool wake);
/* Every pin's level, bit N for Uno pin N. */
pd_pinset_t pd_avr_pins_read(void);
void pd_avr_analog_start(uint8_t pin);
bool pd_avr_analog_done(uint16_t *counts);
void pd_avr_counter_start(uint8_t pin, uint8_t edge);
uint32_t pd_avr_counter_read(uint8_t pin);
void pd_avr_counter_stop(uint8_t pin);

/* output: make `pin` an output at `level` (the level is set before the
 * direction); else an input, without pull-up when level is false (power-up). */
void pd_avr_pin_set(uint8_t pin, bool output, bool level);
#define pd_avr_digital_write(pin, level) pd_avr_pin_set((pin), true, (level))
#define pd_avr_digital_release(pin) pd_avr_pin_set((pin), false, false)

/* Everything at power-up, then one iteration of the main loop. */
void pd_avr_setup(void);
void pd_avr_loop(void);

#endif /* PD_AVR_H */

/*
 * The only boundary between the portable core and hardware.
 *
 * Each platform (firmware/avr, firmware/posix, the unit tests' fake board in
 * tests/c) provides these functions at link time. Binding at link time rather
 * than through a table of function pointers costs the Uno nothing; the `hal`
 * argument is the opaque pointer given to pd_core_init(), so a test can run
 * several independent boards in one process.
 *
 * Receiving is not part of this header: the platform's main loop reads bytes
 * however suits it (ISR ring buffer, poll() on a pty, a fuzzer's input) and
 * offers them to the core with pd_core_rx(), which may leave some for later
 * (while the transmit queue is too full for their replies).
 */
#ifndef PD_HAL_H
#define PD_HAL_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_pinset.h" /* PD_MAX_PINS (and, in the Arduino library, its pd_config.h), the pin sets */

/* What the board is; reported in DeviceInfo and used to validate pins. */
typedef struct pd_board_info {
    const char *board;            /* "uno", "sim"; at most 11 characters */
    uint8_t num_pins;             /* pins are 0 .. num_pins - 1, at most PD_MAX_PINS */
    uint8_t max_servos;           /* at most PD_MAX_SERVOS */
    pd_pinset_t reserved_pins;    /* pin N reserved (the Uno's UART: 0, 1); sets: pd_pinset.h */
    uint16_t rx_buffer;           /* bytes of received frames it buffers (DeviceInfo.rx_buffer) */
    pd_pinset_t pwm_pins;         /* pin N can do PWM (PIN_PWM in DeviceInfo.pins) */
    pd_pinset_t analog_pins;      /* pin N is an analog input */
    pd_pinset_t counter_pins;     /* pin N can count pulses */
    /* Counter pins whose counter is a pin-change interrupt, not an external one
     * (the Uno's 4..13): DeviceInfo's PIN_PIN_CHANGE, a lower lossless edge rate. */
    pd_pinset_t pin_change_pins;
    /* Analog inputs and nothing else (the Nano's A6, A7: the ADC's inputs, no port
     * behind them): every other mode is refused with STATUS_NOT_SUPPORTED. */
    pd_pinset_t analog_only_pins;
    /* PWM pins whose timer drives the servos (the Uno's Timer1: 9, 10): no PWM
     * there while a servo runs, no servo while one of them does PWM. */
    pd_pinset_t servo_timer_pins;
    /* Pins with a timer output whose timer runs the millisecond clock in a mode
     * that leaves no PWM (the Mega's Timer0: 4, 13): refused with
     * STATUS_TIMER_IN_USE, never in pwm_pins. The Uno's Timer0 runs the clock
     * in fast PWM, as wiring.c does, so its 5 and 6 are PWM pins and none of these. */
    pd_pinset_t clock_timer_pins;
    /* The numbers of those two timers (the Uno's 1 and 0), at most
     * PD_INFO_TIMERS_MAX - 1: DeviceInfo.timers names them to the host. */
    uint8_t servo_timer;
    uint8_t clock_timer;
    /* A second timer that makes servo pulses, for the channels after the first timer's
     * (the Mega's Timer5: channels 12 .. 23), 0: none; its PWM pins, also in
     * servo_timer_pins (the rule is the same: no PWM on any of them while a servo runs),
     * are these (the Mega's Timer5 outputs 44 .. 46). */
    uint8_t servo_timer_2;
    pd_pinset_t servo_timer_2_pins;
} pd_board_info_t;
/*
 * This table is the board's one declaration of its pins: the core checks every
 * command against it, and DeviceInfo's pin table (pins, timers: pd_encode.h,
 * pd_encode_pin) is written from it, so the host refuses what the device would
 * from what the device says.
 */

/*
 * Transmit is a queue the platform drains on its own (the Uno: the UART's
 * data-register-empty interrupt), so the core never waits for the line.
 *
 * pd_hal_tx_room: how many bytes pd_hal_write would accept now.
 * pd_hal_write: queue one whole encoded frame, all or nothing, without
 * waiting. Returns false, having queued nothing, if it does not fit (or the
 * port is gone). The core asks for room first and holds back received frames
 * while the queue cannot take their replies (pd_link.h, PD_TX_RESERVE), so a
 * refusal is rare; it makes the core keep its SEQ (the next frame reuses it,
 * docs/protocol.md section 6) and send a lone 0x00 before its next frame.
 */
uint16_t pd_hal_tx_room(void *hal);
bool pd_hal_write(void *hal, const uint8_t *data, uint16_t len);

/*
 * The line rate (docs/protocol.md section 5, *Line rate*). pd_hal_baud_rates:
 * the RESET_ACK FLAGS bits (PD_RESET_ACK_BAUD_*) of the rates above the opening
 * one that this board can switch to (0: none). pd_hal_set_baud: switch the line
 * to `baud` (the opening rate or one of those), once every byte queued before
 * the call has gone out at the old rate: the BAUD_ACK that announces a switch
 * is the last of them. It may wait for them (on the Uno at most the transmit
 * ring's drain, a few ms, as the switch is rare).
 */
uint8_t pd_hal_baud_rates(void *hal);
void pd_hal_set_baud(void *hal, uint32_t baud);

/* Milliseconds since an arbitrary origin; wraps modulo 2^32. */
uint32_t pd_hal_millis(void *hal);

/*
 * Drive servo channel `channel` (0 .. max_servos - 1, allocated by the core)
 * on `pin` with pulses of `us` microseconds. The first call for a channel
 * attaches the pin; later calls change the pulse width only.
 */
void pd_hal_servo_write(void *hal, uint8_t channel, uint8_t pin, uint16_t us);

/*
 * Hold (true) servo writes until the release (false), then let them all take
 * effect at the same servo frame: a Pose's joints, or one speed step of every
 * moving servo, start together at the pins. A HAL whose writes take effect at
 * once may do nothing. Never nested.
 */
void pd_hal_servo_hold(void *hal, bool hold);

/*
 * Whether a width written to a servo channel has yet to reach its pins (it is
 * taken at the channel's next frame start). A HAL whose writes take effect at
 * once returns false. The speed limit's steps ask it so that no frame carries
 * two steps: the millisecond clock and the servo frames are two clocks.
 */
bool pd_hal_servo_pending(void *hal);

/*
 * Stop the pulses of servo channel `channel` on `pin` (a servo whose safe
 * state is "detach", or a released servo): the pulse under way, if any, ends
 * at its normal time (a cut pulse would be a position of its own), then the
 * pin stays low, as between two pulses. A later pd_hal_servo_write attaches
 * the channel again.
 */
void pd_hal_servo_detach(void *hal, uint8_t channel, uint8_t pin);

/* Make `pin` a digital output (if it is not yet one) at `level`. */
void pd_hal_digital_write(void *hal, uint8_t pin, bool level);

/* A released digital output: the pin becomes an input (no pull-up), as at power-up. */
void pd_hal_digital_release(void *hal, uint8_t pin);

/*
 * Make `pin` (in pwm_pins) a PWM output at `duty` 0..255, as Arduino's
 * analogWrite: 0 and 255 are a steady low and high. The first call for a pin
 * sets its timer up; later calls change the duty only.
 */
void pd_hal_pwm_write(void *hal, uint8_t pin, uint8_t duty);

/* A released PWM output: its timer lets go of it and the pin becomes an input (no pull-up). */
void pd_hal_pwm_release(void *hal, uint8_t pin);

/*
 * Inputs (pd_inputs.c and its modes). pd_hal_input_config makes `pin` an input, with its
 * pull-up if asked, and (where the board can) lets a change of it wake the
 * main loop; pd_hal_input_release: an input without pull-up, as at power-up.
 * pd_hal_digital_read_all: the level at every pin now, a pin set (one read per
 * poll (pd_core_poll), whatever the number of inputs: the Uno reads its three PIN
 * registers).
 */
void pd_hal_input_config(void *hal, uint8_t pin, bool pull_up);
void pd_hal_input_release(void *hal, uint8_t pin);
pd_pinset_t pd_hal_digital_read_all(void *hal);

/*
 * Analog inputs (pins in analog_pins), one conversion at a time and never
 * waited for: pd_hal_analog_start begins one, pd_hal_analog_done is true, with
 * the 10-bit counts, once it has finished (the loop asks again on its next pass).
 */
void pd_hal_analog_start(void *hal, uint8_t pin);
bool pd_hal_analog_done(void *hal, uint16_t *counts);

/*
 * Pulse counters (pins in counter_pins): count the pin's edges (`edge`: the
 * Edge enum) from 0, in an interrupt; read the count (wraps at 2^32); stop.
 */
void pd_hal_counter_start(void *hal, uint8_t pin, uint8_t edge);
uint32_t pd_hal_counter_read(void *hal, uint8_t pin);
void pd_hal_counter_stop(void *hal, uint8_t pin);

/*
 * An identifier of this power-up, read once by pd_core_init(): it must differ
 * from the previous power-up's, so that a host can tell a reboot from a
 * reconnect (docs/protocol.md section 5). The Uno counts its boots in EEPROM.
 */
uint32_t pd_hal_boot_id(void *hal);

/*
 * Every configured output was just driven to its safe value (failsafe or
 * Stop). A HAL whose outputs take effect only later should apply them now:
 * a servo's new width otherwise waits for the next 20 ms frame, which would
 * put the failsafe pulse at the pin up to 20 ms behind the deadline.
 */
void pd_hal_outputs_safe(void *hal);

/* The board's description; must stay valid for the program's lifetime. */
const pd_board_info_t *pd_hal_board_info(void *hal);

#endif /* PD_HAL_H */

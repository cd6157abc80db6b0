/*
 * The Uno firmware: the portable core behind the ATmega328P HAL.
 *
 * The main loop offers every received byte to the core, lets it check the
 * failsafe, and sleeps (idle mode) until a pass is due (PD_AVR_PASS): a frame's
 * delimiter or every second received byte, the transmit ring emptied, an
 * input's change, the clock tick (Timer0's overflow, every 1,024 us), so the
 * failsafe is checked at least that often. It never waits for the UART: frames
 * go into a transmit ring that an interrupt drains.
 */
#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <util/atomic.h>

#include "pd_avr.h"
#include "pd_core.h"

#ifdef ARDUINO
#include <Arduino.h> /* the IDE's core owns Timer0 and provides millis() */
#endif

static pd_core_t core;

/* The board's pins (pd_hal.h: its one declaration). The Nano (make avr BOARD=nano) is the
 * Uno's ATmega328P in another package, with two more ADC inputs and nothing else behind
 * them: A6 and A7, pins 20 and 21, analog inputs only. */
#if PD_BOARD_NANO
typedef char pd_assert_nano_pins[PD_MAX_PINS >= 22 ? 1 : -1];
#endif
#if PD_BOARD_MEGA
#define uno pd_avr_mega_info /* the Mega's table: pd_avr_mega.c */
#else
static const pd_board_info_t uno = {
#if PD_BOARD_NANO
    .board = "nano",
    .num_pins = 22,
    .analog_pins = PD_PINSET(0xFFUL << 14, 0, 0),     /* A0..A7 */
    .analog_only_pins = PD_PINSET(0x3UL << 20, 0, 0), /* A6, A7 */
#else
    .board = "uno",
    .num_pins = 20,
    .analog_pins = PD_PINSET(0x3FUL << 14, 0, 0),     /* A0..A5 */
#endif
    .max_servos = 8,
    .reserved_pins = PD_PINSET(PD_PIN(0) | PD_PIN(1), 0, 0), /* RX, TX: the link itself */
    .rx_buffer = PD_AVR_RX_SIZE - 1u,         /* a ring keeps one slot free */
    /* PWM on 5 and 6 too: Timer0 runs the clock in fast PWM, as wiring.c does. */
    .pwm_pins = PD_PINSET(PD_PIN(3) | PD_PIN(5) | PD_PIN(6) | PD_PIN(9) | PD_PIN(10) | PD_PIN(11),
                         0, 0),
    .counter_pins = PD_PINSET(0x3FFCUL, 0, 0),        /* 2..13 */
    .pin_change_pins = PD_PINSET(0x3FF0UL, 0, 0), /* 4..13: pin-change interrupts; 2, 3: INT0, INT1 */
    .servo_timer_pins = PD_PINSET(PD_PIN(9) | PD_PIN(10), 0, 0),
    .servo_timer = 1,
    .clock_timer = 0,
};
#endif

uint16_t pd_hal_tx_room(void *hal)
{
    (void)hal;
    return pd_avr_uart_tx_room();
}

bool pd_hal_write(void *hal, const uint8_t *data, uint16_t len)
{
    (void)hal;
    return pd_avr_uart_write(data, len);
}

/*
 * 16 MHz divides 250,000, 500,000 and 1,000,000 baud exactly with U2X (UBRR 7,
 * 3, 1). The host keeps the frames in flight within rx_buffer (the receive
 * ring) but always lets one frame go alone, whatever its size (docs/protocol.md
 * 7, *Flow control*): a frame longer than the ring holds only while the main
 * loop takes its bytes faster than the line brings them, that is while no work
 * of the loop's (an input report's encoding, a command's decode) outlasts the
 * ring's line time. The ring of before protocol version 5, 48 B, was 15,360 cycles at 500,000: enough on the emulated
 * Uno (64-byte Pings and GetInfo at windows 4 to 16; 6-item Poses while six
 * analog inputs sampled at 500 Hz report every 10 ms: no retransmission). At
 * 1,000,000 they are 7,680 cycles, and a 6-item Pose (a 64-byte frame) arriving
 * while reports were built lost bytes at every retransmission; so 1,000,000 is
 * offered only with a ring of PD_AVR_RX_FAST_1M, which holds every frame a host
 * sends for a valid command (at most 88 B: an 8-item Pose of microsecond values;
 * a 64-byte Ping's is 85 B) within rx_buffer, so that the host's flow control
 * never lets a frame go alone past it and the ring cannot overflow however long
 * the loop works (tests/e2e/test_line_rate.py; firmware/README.md).
 * (The losses once seen at 500,000, a frame in a few hundred, were the
 * receive interrupt nesting on itself: pd_avr_uart.c.)
 */
#define PD_AVR_RX_FAST_1M 96u

uint8_t pd_hal_baud_rates(void *hal)
{
    (void)hal;
#if F_CPU == 16000000UL
    return (uint8_t)(PD_RESET_ACK_BAUD_250K | PD_RESET_ACK_BAUD_500K |
                     (PD_AVR_RX_SIZE >= PD_AVR_RX_FAST_1M ? PD_RESET_ACK_BAUD_1M : 0u));
#else
    return 0;
#endif
}

void pd_hal_set_baud(void *hal, uint32_t baud)
{
    (void)hal;
    pd_avr_uart_set_baud(baud);
}

uint32_t pd_hal_millis(void *hal)
{
    (void)hal;
#ifdef ARDUINO
    return millis();
#else
    return pd_avr_millis();
#endif
}

void pd_hal_servo_write(void *hal, uint8_t channel, uint8_t pin, uint16_t us)
{
    (void)hal;
    pd_avr_servo_write(channel, pin, us);
}

void pd_hal_servo_hold(void *hal, bool hold)
{
    (void)hal;
    pd_avr_servo_hold(hold);
}

bool pd_hal_servo_pending(void *hal)
{
    (void)hal;
    return pd_avr_servo_pending();
}

void pd_hal_digital_write(void *hal, uint8_t pin, bool level)
{
    (void)hal;
    pd_avr_digital_write(pin, level);
}

void pd_hal_pwm_write(void *hal, uint8_t pin, uint8_t duty)
{
    (void)hal;
#if PD_FEATURE_PWM
    pd_avr_pwm_write(pin, duty);
#else
    (void)pin;
    (void)duty;
#endif
}

void pd_hal_pwm_release(void *hal, uint8_t pin)
{
    (void)hal;
#if PD_FEATURE_PWM
    pd_avr_pwm_release(pin);
#else
    (void)pin;
#endif
}

/* Inputs: only the features built reach the drivers (pd_avr_inputs.c). */
void pd_hal_input_config(void *hal, uint8_t pin, bool pull_up)
{
    (void)hal;
#if PD_FEATURE_DIGITAL_INPUT || PD_FEATURE_ANALOG_INPUT || PD_FEATURE_COUNTER
    pd_avr_input_config(pin, pull_up, true);
#else
    (void)pin;
    (void)pull_up;
#endif
}

void pd_hal_input_release(void *hal, uint8_t pin)
{
    (void)hal;
#if PD_FEATURE_DIGITAL_INPUT || PD_FEATURE_ANALOG_INPUT || PD_FEATURE_COUNTER
    pd_avr_input_config(pin, false, false);
#else
    (void)pin;
#endif
}

pd_pinset_t pd_hal_digital_read_all(void *hal)
{
    (void)hal;
#if PD_FEATURE_DIGITAL_INPUT
    return pd_avr_pins_read();
#else
    pd_pinset_t none = {{0}};
    return none;
#endif
}

void pd_hal_analog_start(void *hal, uint8_t pin)
{
    (void)hal;
#if PD_FEATURE_ANALOG_INPUT
    pd_avr_analog_start(pin);
#else
    (void)pin;
#endif
}

bool pd_hal_analog_done(void *hal, uint16_t *counts)
{
    (void)hal;
#if PD_FEATURE_ANALOG_INPUT
    return pd_avr_analog_done(counts);
#else
    *counts = 0;
    return true;
#endif
}

void pd_hal_counter_start(void *hal, uint8_t pin, uint8_t edge)
{
    (void)hal;
#if PD_FEATURE_COUNTER
    pd_avr_counter_start(pin, edge);
#else
    (void)pin;
    (void)edge;
#endif
}

uint32_t pd_hal_counter_read(void *hal, uint8_t pin)
{
    (void)hal;
#if PD_FEATURE_COUNTER
    return pd_avr_counter_read(pin);
#else
    (void)pin;
    return 0;
#endif
}

void pd_hal_counter_stop(void *hal, uint8_t pin)
{
    (void)hal;
#if PD_FEATURE_COUNTER
    pd_avr_counter_stop(pin);
#else
    (void)pin;
#endif
}

void pd_hal_servo_detach(void *hal, uint8_t channel, uint8_t pin)
{
    (void)hal;
    (void)pin;
    pd_avr_servo_detach(channel);
}

void pd_hal_digital_release(void *hal, uint8_t pin)
{
    (void)hal;
    pd_avr_digital_release(pin);
}

/*
 * A boot counter in the first byte of EEPROM: read, add one, write back. One
 * byte is enough: the id only has to differ from the previous power-up's (a
 * host that misses 256 reboots in a row still sees its session not resumed,
 * protocol.md section 5), and it is the smallest code. At one write per
 * power-up the cell's 100,000 cycles last 100,000 boots; an erased EEPROM
 * (0xFF) starts the count at 0.
 */
uint32_t pd_hal_boot_id(void *hal)
{
    (void)hal;
    uint8_t id = (uint8_t)(eeprom_read_byte((const uint8_t *)0) + 1u);
    eeprom_write_byte((uint8_t *)0, id);
    return id;
}

void pd_hal_outputs_safe(void *hal)
{
    (void)hal;
    pd_avr_servo_expedite();
}

const pd_board_info_t *pd_hal_board_info(void *hal)
{
    (void)hal;
    return &uno;
}

void pd_avr_setup(void)
{
#ifndef ARDUINO
    pd_avr_clock_init();
#endif
    pd_avr_uart_init(PD_BAUD);
    if (PD_FEATURE_SERVO) {
        pd_avr_servo_init();
    }
    /* Idle sleep, set once here rather than on every pass (the sketch's own code may set
     * another between two passes in the Arduino IDE's build: pd_avr_loop sets it there).
     * Sleep stays enabled (SE) in our own build: its one SLEEP instruction is the loop's,
     * so the datasheet's advice (SE just before SLEEP, cleared after) guards nothing, and
     * it cost 6 cycles of every pass, 24 passes an acked digital write. */
    set_sleep_mode(SLEEP_MODE_IDLE);
#ifndef ARDUINO
    sleep_enable();
#endif
    sei();
    pd_core_init(&core, NULL);
}

/* The loop's two bytes of state in general-purpose I/O registers, not in the
 * RAM the stack needs (firmware/README.md, the RAM budget): millis8() at the
 * last poll, and whether the transmit ring was empty at the end of the last pass. */
#define POLLED_MS GPIOR1
#define WAS_EMPTY GPIOR2

/* The clock's low byte: a tick since the last poll when it differs. */
static uint8_t millis8(void)
{
#ifdef ARDUINO
    return (uint8_t)millis();
#else
    return pd_avr_millis8();
#endif
}

/*
 * One pass: the received bytes into the core, then pd_core_poll when the pass
 * has news for it: a clock tick, an input's interrupt (PD_AVR_NEWS_BIT), a frame's
 * delimiter (a command ran, a session opened, a Ping fed the failsafe), or the
 * transmit ring just emptied while a report waits for that (it empties after
 * every Ack: a poll there was about 110 cycles of every command). A poll (the
 * failsafe's, the servo steps' and the inputs' clock tests, the report slots) is
 * about 150 cycles; what it reads changes only with those news, so a pass without any
 * skips it. With a user service built in, every pass polls: its poll hook may
 * work in slices, one a pass (docs/services.md).
 */
void pd_avr_loop(void)
{
    uint8_t flags;
    ATOMIC_BLOCK(ATOMIC_FORCEON)
    {
        flags = PD_AVR_PASS; /* a flag set from now on makes one more pass */
        PD_AVR_PASS = 0;
    }
    /* The inputs are read below: a change from now on makes another pass due. */
    bool news = flags & _BV(PD_AVR_NEWS_BIT);
    int16_t byte;
    while ((byte = pd_avr_uart_peek()) >= 0 && pd_core_rx_byte(&core, (uint8_t)byte)) {
        pd_avr_uart_drop();
    }
    uint8_t ms = millis8();
    bool empty = pd_avr_uart_tx_empty();
    if (PD_FEATURE_USER || news || ms != POLLED_MS ||
        (empty && !WAS_EMPTY && pd_core_report_waiting(&core))) {
        POLLED_MS = ms;
        pd_core_poll(&core);
        empty = pd_avr_uart_tx_empty(); /* a report it sent: the next poll when that is out */
    }
    WAS_EMPTY = empty;

    /* Sleep until a pass is due; `sei; sleep` cannot miss the wake-up,
     * because the instruction after sei always runs before any interrupt. An
     * input's interrupt since the pass began means one more pass first. A
     * byte the core left (byte >= 0: its replies need transmit room) waits for
     * the transmit ring to empty, which makes a pass due.
     *
     * Our own build sleeps on through every interrupt that makes no pass due
     * (PD_AVR_PASS): every other received byte, a byte sent, a servo edge. A pass
     * for each of them (the ring's checks, the clock's, the sleep's: about 60
     * cycles) was 23 passes of an acked digital write, the bytes of a frame taken
     * one a pass; now its bytes come two at a time (bench part 5). Four at a time
     * saved 200 cycles more a write, but a command's payload was then decoded
     * after its delimiter more often: its answer time (delimiter in to the Ack's
     * first byte out) grew by 313 cycles a servo write where two at a time adds
     * 82, and the round trip beyond the wire is one of issue 35's goals (bench
     * part 9). In the Arduino IDE's build the core's clock cannot make a
     * pass due: every interrupt makes one there, and received bytes are taken as
     * they come. */
#ifdef ARDUINO
    set_sleep_mode(SLEEP_MODE_IDLE);
    cli();
    if (!(PD_AVR_PASS & _BV(PD_AVR_NEWS_BIT)) && (byte >= 0 || pd_avr_uart_rx_empty())) {
        sleep_enable();
        sei();
        sleep_cpu();
        sleep_disable();
    }
    sei();
#else
    (void)byte;
    cli();
    while (!(PD_AVR_PASS & _BV(PD_AVR_PASS_BIT))) {
        sei();
        sleep_cpu();
        cli();
    }
    sei();
#endif
}

#ifndef ARDUINO
/* OS_main: main never returns, so it saves none of the registers it uses. Left to
 * itself avr-gcc saved 13 through -mcall-prologues once the receive loop inlined
 * into main used that many: 11 B more under every command's decode, the Uno's
 * deepest stack. */
__attribute__((OS_main)) int main(void)
{
    pd_avr_setup();
    for (;;) {
        pd_avr_loop();
    }
}
#endif

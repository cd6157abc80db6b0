/*
 * avrsim.c: an emulated Arduino Uno (ATmega328P, simavr) on a pseudo-terminal; with
 * --mcu atmega2560 a Mega 2560 (its pins: pd_boards).
 *
 *   avrsim [--trace FILE] [--link PATH] [--control PATH] [--hex FILE]...
 *          [--boot ADDR] [--auto-reset] [--glitch PIN] [--stats FILE]
 *          [--profile FILE] [--mcu NAME] [--freq HZ] [--owner-fd FD] [FIRMWARE.elf]
 *
 * The command-line contract is the native simulated board's (firmware/posix/pd_sim.c, as
 * protoduino.simboard runs both):
 * the first stdout line is the port to open (the pty's slave, or --link),
 * SIGINT/SIGTERM (and SIGHUP unless ignored) exit cleanly (status 0; 130 after a
 * SIGINT, 128 + SIGINT as a shell reports a Ctrl-C), so does the end of
 * the owner with --owner-fd (firmware/simcontrol/pd_owner.h), SIGUSR1 resets the
 * MCU while keeping the pty,
 * and --trace writes one JSON line per output change, measured at the pins
 * (servo pulse widths, digital levels, and the duty of the timers' PWM, read
 * from their compare-output IRQs: PWM never goes through the PORT register),
 * each pin in the mode the firmware configured, as its RAM records it (the
 * PWM driver's pins, PD_PWM_TABLE; the servo driver's channels, PD_SERVO_TABLE;
 * a program without these: its timers' modes and its waveforms).
 *
 * --control PATH (firmware/simcontrol) drives the MCU's inputs the way the
 * outside world would, so the firmware's own input code is what runs: a level
 * is raised on the port pin's IRQ (PIN register, pin-change and external
 * interrupts) and held there as the port's "external" level, so that simavr
 * does not overwrite it with the pull-up whenever the firmware writes the
 * port; an analog value is raised on the ADC's input IRQ in millivolts
 * (AVCC = 5000 mV, rounded up so that the 10-bit result is exactly the
 * counts asked for); pulses are toggled by a simavr cycle timer, so their
 * edges are on the emulated clock to the cycle.
 *
 * Why a runner of our own rather than simavr's uart_pty part: uart_pty always
 * makes the same symlink (parallel boards clobber each other) and its stop
 * can hang in pthread_join. Here the pty is ours, UART0 is bridged through
 * simavr's UART IRQs from the one emulation thread, and emulation is paced
 * against CLOCK_MONOTONIC so that the firmware's millis() is real time.
 *
 * --stats FILE (for the benchmarks): on SIGUSR2 and at exit, append one JSON
 * line of counters to FILE: emulated cycles, the cycles the MCU spent asleep
 * (simavr skips a sleeping core ahead to its next timer and reports the jump
 * to the sleep callback), and the UART bytes each way. Awake cycles divided
 * by the commands sent in between is the firmware's cost per command.
 * The line also carries the lowest stack pointer seen since the start (sp_min,
 * checked after every instruction, interrupts included): the Uno has no MMU, and
 * a stack that grows into the static variables corrupts them silently, so the
 * tests compare it with the firmware's end of static data (_end); sp_min_pc is
 * the flash byte address of the instruction after the one that reached it.
 * passes counts the main loop's passes (a batch of emulation and a wait each):
 * the pacing bounds them per emulated second, so many more mean a loop that
 * does not wait (as when a full input buffer left the pty readable forever).
 * The stats line also states UART0's byte time and rate as the firmware set
 * them last (uart_byte_cycles, uart_baud: they follow a mid-run UBRR0 write,
 * the line rate's agreement), and the bytes --line-* options lost each way.
 * extint counts the edges the control socket drives on INT0 and INT1, those
 * lost, and the cycles each waited for its vector (pd_extint_t).
 *
 * --line-check, --line-max BAUD, --line-max-out BAUD (firmware/simcontrol/pd_linerate.h,
 * as the native board): a byte crosses the pty only if the host's termios rate is
 * UART0's (within 3 %) and, with --line-max, UART0's is at most BAUD (both ways;
 * --line-max-out: from the MCU to the host only). Host bytes are judged as they
 * are read, MCU bytes as UART0 starts to send them.
 *
 * --profile FILE: each SIGUSR2 also replaces FILE with the awake cycles spent
 * at each flash address since the previous SIGUSR2 (a flat profile the
 * benchmarks map to the ELF's symbols), written before the --stats line.
 *
 * Flashing flow (--boot, --auto-reset): the reset vector points into
 * the boot section (BOOTRST), power-up shows the external-reset flag so that
 * the bootloader (Optiboot, or the Mega's stk500v2) stays in it, and a client's
 * open() of the port while no other holds it resets the MCU as the DTR
 * auto-reset of a real Uno or Mega does.
 */
#include <errno.h>
#include <fcntl.h>
#include <getopt.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/inotify.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <avr_adc.h>
#include <avr_extint.h>
#include <avr_ioport.h>
#include <avr_timer.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_hex.h>
#include <sim_regbit.h>

#include "pd_control.h"
#include "pd_linerate.h"
#include "pd_owner.h"
#include "pd_pins.h"

#define PD_DEFAULT_MCU "atmega328p"
#define PD_DEFAULT_FREQ 16000000U
#define PD_DEFAULT_BAUD 115200U
#define PD_MAX_HEX 4
#define PD_BUF_SIZE 4096U
/* Emulated time runs at most this far ahead of the wall clock, a sleeping MCU
 * included (pd_pace_timer). A host byte enters the UART no earlier than the
 * wall-clock time it was read at, and no later than the emulated time then, so
 * being ahead delays every byte from the host by up to that much: a sleeping
 * MCU that skipped to its next timer event (the 1 ms tick) added 280 us at the
 * median to every round trip, which the firmware did not cost. The runner
 * sleeps until the wall clock catches up, with nanosecond timeouts, so the
 * bound can be small. */
#define PD_AHEAD_NS 50000ULL
/* At most this much emulated time per batch, so that a board catching up
 * after a stall (a loaded machine) keeps exchanging bytes meanwhile. */
#define PD_BATCH_NS 1000000ULL
/* Shorter waits are not worth a system call; the next batch makes up for them. */
#define PD_MIN_WAIT_NS 20000ULL
/* A stream with no pause goes to the host in chunks of at most this much. */
#define PD_STREAM_NS 1000000ULL
#define PD_MCUSR_ADDR 0x54     /* ATmega328P MCUSR in data space (the ATmega2560's too) */
#define PD_MCUSR_EXTRF 0x02
/* ATmega328P external interrupts in data space: EIFR, EIMSK, EICRA (ISCn1:ISCn0 per INTn). */
#define PD_EIFR_ADDR 0x3C
#define PD_EIMSK_ADDR 0x3D
#define PD_EICRA_ADDR 0x69
#define PD_EXTINTS 2 /* INT0 on D2, INT1 on D3: their vectors are 1 and 2 */
/* The port is announced after this much emulated time: whatever the firmware
 * sends at power-up (EVENT BOOT) is then already in the pty and is flushed by
 * the client's open(), as with the native board, instead of being cut in half
 * by an open() that lands while it is being sent. */
#define PD_ANNOUNCE_MS 50U
#define PD_VCC_MV 5000U /* VCC, AVCC and AREF of the emulated Uno */
/* The ATmega328P's ADC6 and ADC7, a Nano's A6 and A7 (pins 20, 21): inputs of the ADC with
 * no port behind them, so they take analog values and nothing else. */
#define PD_ADC_ONLY_PINS 2
#define PD_MAX_PORTS 11 /* the ATmega2560's A..L (no I) */

/*
 * A board's pins as Arduino numbers them, chosen by the MCU (--mcu or the ELF's .mmcu):
 * pin N is bit map[N][1] of port map[N][0]; the analog inputs are pins first_analog ..
 * first_analog + analog_count - 1 (ADC0 ..). The Uno: D0..D7 = PD0..7, D8..D13 = PB0..5,
 * A0..A5 = PC0..5. The Mega 2560: its pins_arduino.h (firmware/avr/pd_avr_mega.c has the
 * same map).
 */
typedef struct {
    const char *mcu;
    const char *name;
    int num_pins;
    int first_analog;
    int analog_count;
    const char (*map)[2];
} pd_board_t;

static const char pd_uno_map[][2] = {
    {'D', 0}, {'D', 1}, {'D', 2}, {'D', 3}, {'D', 4}, {'D', 5}, {'D', 6}, {'D', 7},
    {'B', 0}, {'B', 1}, {'B', 2}, {'B', 3}, {'B', 4}, {'B', 5},
    {'C', 0}, {'C', 1}, {'C', 2}, {'C', 3}, {'C', 4}, {'C', 5},
};
static const char pd_mega_map[][2] = {
    {'E', 0}, {'E', 1}, {'E', 4}, {'E', 5}, {'G', 5}, {'E', 3}, {'H', 3}, {'H', 4}, /* 0-7 */
    {'H', 5}, {'H', 6}, {'B', 4}, {'B', 5}, {'B', 6}, {'B', 7}, {'J', 1}, {'J', 0}, /* 8-15 */
    {'H', 1}, {'H', 0}, {'D', 3}, {'D', 2}, {'D', 1}, {'D', 0}, {'A', 0}, {'A', 1}, /* 16-23 */
    {'A', 2}, {'A', 3}, {'A', 4}, {'A', 5}, {'A', 6}, {'A', 7}, {'C', 7}, {'C', 6}, /* 24-31 */
    {'C', 5}, {'C', 4}, {'C', 3}, {'C', 2}, {'C', 1}, {'C', 0}, {'D', 7}, {'G', 2}, /* 32-39 */
    {'G', 1}, {'G', 0}, {'L', 7}, {'L', 6}, {'L', 5}, {'L', 4}, {'L', 3}, {'L', 2}, /* 40-47 */
    {'L', 1}, {'L', 0}, {'B', 3}, {'B', 2}, {'B', 1}, {'B', 0},                     /* 48-53 */
    {'F', 0}, {'F', 1}, {'F', 2}, {'F', 3}, {'F', 4}, {'F', 5}, {'F', 6}, {'F', 7}, /* A0-A7 */
    {'K', 0}, {'K', 1}, {'K', 2}, {'K', 3}, {'K', 4}, {'K', 5}, {'K', 6}, {'K', 7}, /* A8-A15 */
};
static const pd_board_t pd_boards[] = {
    {"atmega2560", "mega", 70, 54, 16, pd_mega_map},
    {NULL, "uno", 20, 14, 6, pd_uno_map}, /* every other MCU: the Uno's pins */
};

/* A port of the board: the pin of each of its bits (-1: none). */
typedef struct {
    char name;
    int8_t pin[8];
    avr_ioport_t *io;
} pd_port_t;

/* An input pin as the control socket drives it. */
typedef struct {
    int pin;
    uint8_t driven; /* a level is held on the pin */
    uint8_t level;
    uint32_t edges_left; /* pulse train: level changes still to make */
    uint64_t start;      /* pulse train: cycle of its first edge */
    uint64_t edges_done;
    uint32_t hz;
    int timer; /* the cycle timer is registered */
} pd_input_t;

/* A pin a timer's compare output can drive (OCnA/OCnB). */
typedef struct {
    int pin;
    char timer_name;
    int comp;
    avr_timer_t *timer;
    uint8_t oc_level;  /* the compare output's last level */
    uint8_t connected; /* its compare output was connected since the pin last was an input */
} pd_pwm_pin_t;

static pd_pwm_pin_t g_uno_pwm_pins[] = {
    {6, '0', AVR_TIMER_COMPA, NULL, 0, 0},  {5, '0', AVR_TIMER_COMPB, NULL, 0, 0},
    {9, '1', AVR_TIMER_COMPA, NULL, 0, 0},  {10, '1', AVR_TIMER_COMPB, NULL, 0, 0},
    {11, '2', AVR_TIMER_COMPA, NULL, 0, 0}, {3, '2', AVR_TIMER_COMPB, NULL, 0, 0},
};
/* The Mega's: Timer0's OC0A 13 and OC0B 4 (OC1C, also pin 13, is left out: the clock's
 * timer holds that pin), Timer1's 11, 12, Timer2's 10, 9, and Timers 3, 4 and 5's A, B, C:
 * 5, 2, 3; 6, 7, 8; 46, 45, 44 (the firmware's pd_avr_mega_pwm16). */
static pd_pwm_pin_t g_mega_pwm_pins[] = {
    {13, '0', AVR_TIMER_COMPA, NULL, 0, 0}, {4, '0', AVR_TIMER_COMPB, NULL, 0, 0},
    {11, '1', AVR_TIMER_COMPA, NULL, 0, 0}, {12, '1', AVR_TIMER_COMPB, NULL, 0, 0},
    {10, '2', AVR_TIMER_COMPA, NULL, 0, 0}, {9, '2', AVR_TIMER_COMPB, NULL, 0, 0},
    {5, '3', AVR_TIMER_COMPA, NULL, 0, 0},  {2, '3', AVR_TIMER_COMPB, NULL, 0, 0},
    {3, '3', AVR_TIMER_COMPC, NULL, 0, 0},  {6, '4', AVR_TIMER_COMPA, NULL, 0, 0},
    {7, '4', AVR_TIMER_COMPB, NULL, 0, 0},  {8, '4', AVR_TIMER_COMPC, NULL, 0, 0},
    {46, '5', AVR_TIMER_COMPA, NULL, 0, 0}, {45, '5', AVR_TIMER_COMPB, NULL, 0, 0},
    {44, '5', AVR_TIMER_COMPC, NULL, 0, 0},
};
/* The board's (the Mega's once the runner knows it runs one: pd_setup). */
static pd_pwm_pin_t *g_pwm_pins = g_uno_pwm_pins;
static size_t g_pwm_count = sizeof g_uno_pwm_pins / sizeof g_uno_pwm_pins[0];
#define PD_PWM_PINS g_pwm_count

typedef struct {
    uint8_t data[PD_BUF_SIZE];
    size_t head; /* next byte to take */
    size_t len;
} pd_fifo_t;

#define PD_MAX_MARKS 8 /* --mark addresses */

/*
 * protoduino's servo channel table (firmware/avr/pd_avr_servo.c, which asserts this
 * layout), found by its ELF symbol (LTO may add a ".lto_priv.N" suffix): per channel the
 * data address of the pin's PORT register (2 bytes, little-endian), then the pin's bit
 * (0: detached), in PD_SERVO_CHANNEL_BYTES. A pin carries a servo while a channel names
 * its port and bit: the trace's mode is that, not a guess from the waveform. Its size is
 * the distance to the next symbol.
 */
#define PD_SERVO_TABLE "pd_avr_servos"
/* protoduino's PWM pins (firmware/avr/pd_avr_pwm.c): pin n is bit n % 8 of byte n / 8 while
 * the PWM driver runs it, duties 0 and 255 included (its timer disconnected then). */
#define PD_PWM_TABLE "pd_avr_pwm_pins"
#define PD_SERVO_CHANNEL_BYTES 7U
#define PD_SERVO_CHANNELS_MAX 64U
#define PD_ELF_DATA 0x800000U /* avr-ld's data space in the ELF's addresses */

/*
 * An external interrupt (INT0, INT1) as the inputs the control socket drives meet it (in
 * --stats: "extint"): the edges that set its flag, those lost (one came while the flag of
 * the one before was still set: its vector not reached yet, so the hardware merged them),
 * and the cycles from an edge to its vector, the most of them with the flash byte address
 * the MCU was at when that edge came (what held the interrupt off: map it with avr-nm).
 */
typedef struct {
    uint64_t edges;
    uint64_t lost;
    uint64_t served;
    uint64_t latency_sum;
    uint64_t latency_max;
    uint32_t latency_max_pc;
    uint64_t raised_at; /* cycle of the edge waiting for its vector; 0: none */
    uint32_t raised_pc;
} pd_extint_t;

typedef struct {
    avr_t *avr;
    avr_uart_t *uart;
    const pd_board_t *board;
    pd_port_t ports[PD_MAX_PORTS];
    int port_count;
    int8_t port_of[PD_PINS_COUNT]; /* pin -> its index in ports */
    pd_pins_t pins;
    FILE *trace;
    uint16_t servo_table;    /* data address of the firmware's servo channels; 0: none */
    uint16_t servo_channels; /* their count */
    uint16_t pwm_table;      /* data address of the firmware's PWM pins; 0: none */
    int master;
    int slave;
    int inotify;
    int clients; /* --auto-reset: clients holding the port open (the DTR line) */
    char slave_path[128];
    const char *link;
    uint32_t boot_addr;
    int boot;
    uint64_t cycle_base; /* cycles banked across resets that zero avr->cycle */
    /* The PWM timers' control registers (TCCRnA, TCCRnB: compare outputs, mode, clock) and
     * their values when last seen: pd_timer_regs_check. */
    uint16_t tccr_addr[2 * 6];
    uint8_t tccr_seen[2 * 6];
    int tccr_count;
    uint64_t last_cycle;
    int reset_seen;
    void (*core_reset)(struct avr_t *avr);
    pd_fifo_t rx; /* host -> MCU */
    pd_fifo_t tx; /* MCU -> host */
    uint64_t tx_due[PD_BUF_SIZE]; /* per byte in tx: the cycle its last bit has left the UART */
    int rx_timer; /* pd_rx_timer is registered */
    int crashed;
    FILE *port_out; /* the real stdout, for the one port line */
    const char *port_name;
    int glitch_pin; /* --glitch: -1 when off */
    uint64_t next_glitch;
    FILE *stats;           /* --stats: NULL when off */
    uint64_t sleep_cycles; /* cycles skipped while the MCU slept, across resets */
    uint64_t uart_rx;      /* bytes fed into UART0 */
    uint64_t uart_tx;      /* bytes UART0 sent */
    uint64_t tx_last;      /* cycle of the last byte UART0 sent */
    uint64_t byte_cycles;  /* one byte on the line before the firmware sets a baud (10 bits at 115200) */
    uint64_t pace_at;      /* pd_pace_timer's cycle, in pd_cycles terms; 0 when not set */
    uint64_t rx_read_at;   /* wall clock (in cycles) when the burst now entering was read */
    int rx_first;          /* the next byte pd_rx_timer feeds starts a burst */
    uint64_t rx_lag_max;   /* most cycles a burst's first byte entered after rx_read_at */
    uint64_t rx_last_at;   /* cycle the last byte of a host burst was ready in UDR0; 0: none */
    uint64_t answers;      /* UART bytes sent first after a host burst's last byte */
    uint64_t answer_cycles; /* their cycles since that last byte: the MCU's answer time */
    uint32_t mark_pc[PD_MAX_MARKS]; /* --mark: flash byte addresses */
    int mark_count;
    uint32_t mark_from; /* --mark-from: arm at this flash byte address instead (0: at a burst's end) */
    uint64_t mark_at;      /* cycle a host burst's last byte was ready, until a mark is reached; 0: none */
    uint64_t marks;        /* marks reached first after a host burst's last byte */
    uint64_t mark_cycles;  /* their cycles since that last byte */
    int tx_blocked;        /* the pty took no more of tx: wait for it to be writable */
    size_t tx_ready;       /* leading bytes of tx already due (their due cycles only grow) */
    uint64_t passes;       /* passes of the main loop: batches and waits */
    uint16_t sp_min;       /* lowest stack pointer seen since start, a data address */
    uint32_t sp_min_pc;    /* the flash byte address that reached it */
    int sp_split;          /* between an OUT to SPH and the OUT to SPL that completes it */
    const char *stack_path; /* --stack: NULL when off */
    uint8_t sp_min_stack[4096]; /* the stack's bytes, SP + 1 .. RAMEND, when sp_min was reached */
    size_t sp_min_len;
    const char *profile_path; /* --profile: NULL when off */
    uint64_t *profile;        /* awake cycles per flash word */
    size_t profile_words;
    pd_control_t control;
    pd_input_t input[PD_PINS_COUNT];
    pd_extint_t extint[PD_EXTINTS];
    uint8_t ext_mask[PD_MAX_PORTS]; /* per port: pins held by the control socket */
    uint8_t ext_value[PD_MAX_PORTS];
    int owner_fd; /* --owner-fd: the owner's pipe, or -1 */
    pd_line_t line; /* --line-check, --line-max, --line-max-out (pd_linerate.h) */
} pd_sim_t;

static pd_sim_t g_sim;
static void pd_start_rx(pd_sim_t *sim);
static uint64_t g_start_ns; /* trace and pacing time zero: the process start */
static volatile sig_atomic_t g_stop; /* the signal that stopped it, 0 while running */
static volatile sig_atomic_t g_reset;
static volatile sig_atomic_t g_dump_stats;

static void pd_on_signal(int sig)
{
    if (sig == SIGUSR1) {
        g_reset = 1;
    } else if (sig == SIGUSR2) {
        g_dump_stats = 1;
    } else {
        g_stop = sig;
    }
}

/* simavr logs through this: everything goes to stderr, so that stdout carries
 * the port line only. */
static void pd_logger(avr_t *avr, const int level, const char *format, va_list ap)
{
    if (level > LOG_ERROR && (!avr || avr->log < level)) {
        return;
    }
    vfprintf(stderr, format, ap);
}

static uint64_t pd_now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ULL + (uint64_t)ts.tv_nsec;
}

/* Emulated cycles since the runner started, monotonic across resets. */
static uint64_t pd_cycles(const pd_sim_t *sim)
{
    return sim->cycle_base + sim->avr->cycle;
}

static void pd_fifo_push(pd_fifo_t *f, uint8_t b)
{
    if (f->len == PD_BUF_SIZE) {
        return; /* full: dropped, as a UART with nobody listening would */
    }
    f->data[(f->head + f->len) % PD_BUF_SIZE] = b;
    f->len++;
}

static void pd_trace_emit(void *ctx, uint64_t cycle, int pin, enum pd_pin_mode mode,
                          unsigned value)
{
    pd_sim_t *sim = ctx;
    if (!sim->trace) {
        return;
    }
    double t = (double)cycle / (double)sim->avr->frequency;
    const char *name = mode == PD_PIN_MODE_SERVO ? "servo"
                       : mode == PD_PIN_MODE_PWM ? "pwm"
                                                 : "digital";
    fprintf(sim->trace, "{\"t\": %.6f, \"pin\": %d, \"mode\": \"%s\", \"value\": %u}\n", t, pin,
            name, value);
    fflush(sim->trace);
}

static pd_pwm_pin_t *pd_pwm_pin(int pin)
{
    for (size_t i = 0; i < PD_PWM_PINS; i++) {
        if (g_pwm_pins[i].pin == pin) {
            return &g_pwm_pins[i];
        }
    }
    return NULL;
}

/* The port's bits a channel of the firmware's servo table drives (none: 0). */
static uint8_t pd_servo_bits(const pd_sim_t *sim, const pd_port_t *port)
{
    const uint8_t *data = sim->avr->data;
    uint8_t bits = 0;
    for (uint16_t ch = 0; ch < sim->servo_channels; ch++) {
        const uint8_t *c = data + sim->servo_table + ch * PD_SERVO_CHANNEL_BYTES;
        if ((uint16_t)(c[0] | (c[1] << 8)) == port->io->r_port) {
            bits |= c[2];
        }
    }
    return bits;
}

/* The ELF address of a variable in RAM named `table` (LTO may add a ".lto_priv.N"
 * suffix), or 0. */
static uint32_t pd_find_data(const elf_firmware_t *fw, const char *table)
{
    const size_t len = strlen(table);
    for (uint32_t i = 0; i < fw->symbolcount; i++) {
        const char *name = fw->symbol[i]->symbol;
        if (strncmp(name, table, len) == 0 && (name[len] == '\0' || name[len] == '.') &&
            fw->symbol[i]->addr > PD_ELF_DATA) {
            return fw->symbol[i]->addr;
        }
    }
    return 0;
}

/* Finds the firmware's servo table (PD_SERVO_TABLE) and PWM pins (PD_PWM_TABLE) among
 * the ELF's symbols. */
static void pd_find_tables(pd_sim_t *sim, const elf_firmware_t *fw)
{
    uint32_t pwm = pd_find_data(fw, PD_PWM_TABLE);
    if (pwm && pwm - PD_ELF_DATA + (PD_PINS_COUNT + 7U) / 8U <= (uint32_t)sim->avr->ramend + 1U) {
        sim->pwm_table = (uint16_t)(pwm - PD_ELF_DATA);
    }
    uint32_t at = pd_find_data(fw, PD_SERVO_TABLE);
    if (!at) {
        return;
    }
    uint32_t end = UINT32_MAX;
    for (uint32_t i = 0; i < fw->symbolcount; i++) {
        uint32_t addr = fw->symbol[i]->addr;
        if (addr > at && addr < end) {
            end = addr;
        }
    }
    uint32_t channels = (end - at) / PD_SERVO_CHANNEL_BYTES;
    if (channels > PD_SERVO_CHANNELS_MAX) {
        channels = PD_SERVO_CHANNELS_MAX;
    }
    if (at - PD_ELF_DATA + channels * PD_SERVO_CHANNEL_BYTES > (uint32_t)sim->avr->ramend + 1U) {
        return; /* not a table that fits the RAM: none */
    }
    sim->servo_table = (uint16_t)(at - PD_ELF_DATA);
    sim->servo_channels = (uint16_t)channels;
}

static void pd_port_sample(pd_sim_t *sim, pd_port_t *port, uint8_t ddr)
{
    if (!port->io) {
        return;
    }
    uint8_t out = sim->avr->data[port->io->r_port];
    uint8_t servo_bits = sim->servo_table ? pd_servo_bits(sim, port) : 0;
    uint64_t now = pd_cycles(sim);
    for (int b = 0; b < 8; b++) {
        int pin = port->pin[b];
        if (pin < 2) { /* no pin, or D0/D1 */
            continue; /* D0/D1 are the UART */
        }
        int level = (out >> b) & 1;
        uint32_t pwm_tick = 0;
        pd_pwm_pin_t *w = pd_pwm_pin(pin);
        if (w && w->timer) {
            if (!((ddr >> b) & 1)) {
                w->connected = 0; /* an input: whatever the pin did has ended */
            }
            int kind = w->timer->wgm_op_mode_kind;
            int pwm_mode = kind == avr_timer_wgm_pwm || kind == avr_timer_wgm_fast_pwm ||
                           kind == avr_timer_wgm_fc_pwm;
            int connected = avr_regbit_get(sim->avr, w->timer->comp[w->comp].com) != 0;
            /* A connected compare output overrides the PORT bit. */
            if (connected) {
                level = w->oc_level;
                w->connected = 1;
            }
            int pwm;
            if (sim->pwm_table) {
                /* The firmware says which pins it runs as PWM: a digital output on the
                 * other pin of a timer that makes PWM (or keeps the clock) is digital. */
                pwm = (sim->avr->data[sim->pwm_table + pin / 8] >> (pin % 8)) & 1U;
            } else {
                /* A program without that record: PWM once its compare output drove the
                 * pin (duties 0 and 255 disconnect it and drive the level), since Timer0
                 * runs fast PWM for the clock from power-up. */
                pwm = w->connected && pwm_mode;
            }
            if (pwm) {
                pwm_tick = w->timer->cs_div_value ? w->timer->cs_div_value : 1U; /* prescaler */
                if (sim->pwm_table && !connected) {
                    pwm_tick = PD_PINS_PWM_LEVEL; /* duty 0 or 255: the port drives it */
                }
            }
        }
        /* 1 while a servo channel drives the pin, 0 while none does, -1: no table. */
        int servo = sim->servo_table ? (servo_bits >> b) & 1 : -1;
        pd_pins_sample(&sim->pins, pin, (ddr >> b) & 1, level, pwm_tick, servo, now);
    }
}

static pd_port_t *pd_port_of(pd_sim_t *sim, int pin)
{
    return &sim->ports[sim->port_of[pin]];
}

/* The pin's bit in its port. */
static int pd_bit_of(const pd_sim_t *sim, int pin)
{
    return sim->board->map[pin][1];
}

/* Every port sampled now (pd_port_sample). */
static void pd_ports_sample(pd_sim_t *sim)
{
    for (int i = 0; i < sim->port_count; i++) {
        if (sim->ports[i].io) {
            pd_port_sample(sim, &sim->ports[i], sim->avr->data[sim->ports[i].io->r_ddr]);
        }
    }
}

/* Note a PWM timer's control register (once). */
static void pd_timer_reg_add(pd_sim_t *sim, uint16_t addr)
{
    for (int i = 0; i < sim->tccr_count; i++) {
        if (sim->tccr_addr[i] == addr) {
            return;
        }
    }
    if (addr && sim->tccr_count < (int)(sizeof sim->tccr_addr / sizeof sim->tccr_addr[0])) {
        sim->tccr_addr[sim->tccr_count] = addr;
        sim->tccr_seen[sim->tccr_count++] = sim->avr->data[addr];
    }
}

/* After each instruction: a write to a PWM timer's control register (a duty of 0 or 255
 * disconnects the compare output, a timer stops) changes a pin with no port IRQ. The ports
 * are sampled at that instruction; sampled only at the pass's end, such a change was dated
 * up to a pass late (PD_BATCH_NS, 1 ms, when the runner is behind the wall clock: a
 * bumper's trip measured 1,000 us at the pin on a loaded machine, 65 us otherwise). */
static void pd_timer_regs_check(pd_sim_t *sim)
{
    int changed = 0;
    for (int i = 0; i < sim->tccr_count; i++) {
        uint8_t v = sim->avr->data[sim->tccr_addr[i]];
        if (v != sim->tccr_seen[i]) {
            sim->tccr_seen[i] = v;
            changed = 1;
        }
    }
    if (changed) {
        pd_ports_sample(sim);
    }
}

/* A timer's compare output changed (its IRQ carries the new level). */
static void pd_oc_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    pd_pwm_pin_t *w = param;
    w->oc_level = (value & 0xffU) ? 1U : 0U;
    pd_port_t *port = pd_port_of(&g_sim, w->pin);
    if (port->io) {
        pd_port_sample(&g_sim, port, g_sim.avr->data[port->io->r_ddr]);
    }
}

/* --- inputs driven through the control socket -------------------------- */

static uint8_t pd_pin_reads(pd_sim_t *sim, int pin);

/* INTn's pin went from `was` to `level`: an edge its sense (EICRA) counts, if enabled. */
static void pd_extint_edge(pd_sim_t *sim, int n, uint8_t was, uint8_t level)
{
    const uint8_t *data = sim->avr->data;
    uint8_t bit = (uint8_t)(1U << n);
    uint8_t sense = (uint8_t)((data[PD_EICRA_ADDR] >> (2 * n)) & 3U); /* 1 any, 2 fall, 3 rise */
    if (!(data[PD_EIMSK_ADDR] & bit) || sense == 0 || was == level ||
        (sense == 2 && level) || (sense == 3 && !level)) {
        return;
    }
    pd_extint_t *x = &sim->extint[n];
    if (x->raised_at && !(data[PD_EIFR_ADDR] & bit)) {
        x->raised_at = 0; /* the firmware cleared the flag (EIFR): no vector to wait for */
    }
    x->edges++;
    if (x->raised_at) {
        x->lost++;
        return;
    }
    x->raised_at = pd_cycles(sim);
    x->raised_pc = sim->avr->pc;
}

/* The MCU is at `pc`: an INTn vector there serves its waiting edge. */
static void pd_extint_check(pd_sim_t *sim, avr_flashaddr_t pc)
{
    for (int n = 0; n < PD_EXTINTS; n++) {
        pd_extint_t *x = &sim->extint[n];
        if (x->raised_at && pc == (avr_flashaddr_t)(n + 1) * sim->avr->vector_size) {
            uint64_t latency = pd_cycles(sim) - x->raised_at;
            x->served++;
            x->latency_sum += latency;
            if (latency > x->latency_max) {
                x->latency_max = latency;
                x->latency_max_pc = x->raised_pc;
            }
            x->raised_at = 0;
        }
    }
}

/* Hold `pin` at `level` as the outside world would. */
static void pd_drive(pd_sim_t *sim, int pin, uint8_t level)
{
    int idx = sim->port_of[pin];
    pd_port_t *port = &sim->ports[idx];
    if (!port->io) {
        return;
    }
    int bit = pd_bit_of(sim, pin);
    uint8_t mask = (uint8_t)(1U << bit);
    sim->ext_mask[idx] |= mask;
    sim->ext_value[idx] = (uint8_t)((sim->ext_value[idx] & ~mask) | (level ? mask : 0U));
    avr_ioport_external_t ext = {.name = (unsigned)port->name & 0x7fU,
                                 .mask = sim->ext_mask[idx],
                                 .value = sim->ext_value[idx]};
    avr_ioctl(sim->avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(port->name), &ext);
    uint8_t was = pd_pin_reads(sim, pin);
    sim->input[pin].driven = 1;
    sim->input[pin].level = level;
    avr_raise_irq(avr_io_getirq(sim->avr, AVR_IOCTL_IOPORT_GETIRQ(port->name), bit), level);
    if ((pin == 2 || pin == 3) && sim->board->map == pd_uno_map) { /* INT0, INT1 */
        pd_extint_edge(sim, pin - 2, was, level);
    }
}

/* The level the MCU reads on `pin` now (PIN register bit). */
static uint8_t pd_pin_reads(pd_sim_t *sim, int pin)
{
    pd_port_t *port = pd_port_of(sim, pin);
    if (!port->io) {
        return 0;
    }
    avr_ioport_state_t st;
    if (avr_ioctl(sim->avr, AVR_IOCTL_IOPORT_GETSTATE(port->name), &st) != 0) {
        return 0;
    }
    int bit = pd_bit_of(sim, pin);
    uint8_t pull = (uint8_t)((st.port & ~st.ddr) >> bit) & 1U; /* pull-up of an input */
    return sim->input[pin].driven ? sim->input[pin].level : (uint8_t)(((st.pin >> bit) & 1U) | pull);
}

/* Cycle of a train's edge k (k = 0 is the first): exact on average for any
 * rate, by integer arithmetic from the train's start. */
static uint64_t pd_edge_cycle(const pd_sim_t *sim, const pd_input_t *in, uint64_t k)
{
    return in->start + k * (uint64_t)sim->avr->frequency / (2U * (uint64_t)in->hz);
}

static avr_cycle_count_t pd_pulse_timer(struct avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)avr;
    pd_input_t *in = param;
    pd_sim_t *sim = &g_sim;
    if (!in->edges_left) {
        in->timer = 0;
        return 0;
    }
    pd_drive(sim, in->pin, in->level ? 0U : 1U);
    in->edges_left--;
    in->edges_done++;
    if (!in->edges_left) {
        in->timer = 0;
        return 0;
    }
    uint64_t next = pd_edge_cycle(sim, in, in->edges_done);
    uint64_t now = pd_cycles(sim);
    return when + (next > now ? next - now : 1U);
}

/* (Re)arm a pulse train's cycle timer for its next edge. */
static void pd_arm_pulses(pd_sim_t *sim, pd_input_t *in)
{
    if (!in->edges_left || sim->crashed) {
        return;
    }
    uint64_t next = pd_edge_cycle(sim, in, in->edges_done);
    uint64_t now = pd_cycles(sim);
    avr_cycle_timer_cancel(sim->avr, pd_pulse_timer, in);
    avr_cycle_timer_register(sim->avr, next > now ? next - now : 1U, pd_pulse_timer, in);
    in->timer = 1;
}

/*
 * simavr 1.6 (Debian bookworm's) holds the values of ADC0..ADC7 only (avr_adc_t.adc_values[8];
 * 1.7 has 16): an ATmega2560's ADC8..ADC15 (the Mega's A8..A15), which the firmware selects
 * with ADCSRB's MUX5 (mux codes 32..39, single-ended), would read past that array. There the
 * runner sets the mux code's entry to a fixed voltage (ADC_MUX_REF: the conversion reads its
 * millivolts, scaled as a pin's), which converts the same as the pin's value would.
 */
#define PD_SIMAVR_ADC_VALUES (sizeof(((avr_adc_t *)0)->adc_values) / sizeof(uint16_t))
#define PD_ADC8_MUX 32 /* MUX5:0 = 100000: ADC8, single-ended (ATmega2560 datasheet, 26.8.1) */

static avr_adc_t *pd_adc(pd_sim_t *sim)
{
    for (avr_io_t *io = sim->avr->io_port; io != NULL; io = io->next) {
        if (io->kind != NULL && strcmp(io->kind, "adc") == 0) {
            return (avr_adc_t *)io; /* its avr_io_t is its first member */
        }
    }
    return NULL;
}

static void pd_set_analog(pd_sim_t *sim, int pin, unsigned counts)
{
    /* simavr converts mV * 1023 / AVCC, truncating: the smallest mV that
     * gives `counts` is ceil(counts * AVCC / 1023). */
    uint32_t mv = (counts * PD_VCC_MV + 1022U) / 1023U;
    int channel = pin - sim->board->first_analog;
    avr_adc_t *adc = channel >= (int)PD_SIMAVR_ADC_VALUES ? pd_adc(sim) : NULL;
    if (adc != NULL) {
        adc->muxmode[PD_ADC8_MUX + channel - 8] =
            (avr_adc_mux_t){.kind = ADC_MUX_REF, .src = mv & 0x1FFFU};
        return;
    }
    avr_raise_irq(
        avr_io_getirq(sim->avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + (pin - sim->board->first_analog)),
        mv);
}

static const char *pd_control_apply(void *ctx, const pd_control_cmd_t *cmd, double *t)
{
    pd_sim_t *sim = ctx;
    const pd_board_t *board = sim->board;
    if (board->map == pd_uno_map && cmd->pin >= board->num_pins &&
        cmd->pin < board->num_pins + PD_ADC_ONLY_PINS && cmd->kind == PD_CONTROL_ANALOG) {
        pd_set_analog(sim, cmd->pin, (unsigned)cmd->value); /* ADC6, ADC7 */
        *t = (double)pd_cycles(sim) / (double)sim->avr->frequency;
        return NULL;
    }
    if (cmd->pin >= board->num_pins) {
        return board->map == pd_uno_map
                   ? "no such pin on this board (pins 2..19; 20 and 21, A6 and A7, take only analog values)"
                   : "no such pin on this board (pins 2..69)";
    }
    if (cmd->pin < 2) {
        return "pins 0 and 1 carry the serial link";
    }
    pd_input_t *in = &sim->input[cmd->pin];
    switch (cmd->kind) {
    case PD_CONTROL_LEVEL:
        in->edges_left = 0; /* a level ends any train */
        avr_cycle_timer_cancel(sim->avr, pd_pulse_timer, in);
        in->timer = 0;
        pd_drive(sim, cmd->pin, (uint8_t)cmd->value);
        break;
    case PD_CONTROL_ANALOG:
        if (cmd->pin < board->first_analog) {
            return board->map == pd_uno_map ? "analog inputs are pins 14..19 (A0..A5)"
                                            : "analog inputs are pins 54..69 (A0..A15)";
        }
        pd_set_analog(sim, cmd->pin, (unsigned)cmd->value);
        break;
    case PD_CONTROL_PULSES:
        /* From the level the pin is at: the first edge leaves it at once. */
        pd_drive(sim, cmd->pin, pd_pin_reads(sim, cmd->pin));
        in->edges_left = 2U * cmd->pulses;
        in->edges_done = 0;
        in->hz = cmd->hz;
        in->start = pd_cycles(sim) + 1U;
        pd_arm_pulses(sim, in);
        break;
    }
    *t = (double)pd_cycles(sim) / (double)sim->avr->frequency;
    return NULL;
}

/* After a reset: simavr cleared the PIN registers and every cycle timer, but
 * the outside world still drives its pins. */
static void pd_restore_inputs(pd_sim_t *sim)
{
    for (int pin = 2; pin < sim->board->num_pins; pin++) {
        pd_input_t *in = &sim->input[pin];
        if (in->driven) {
            pd_port_t *port = pd_port_of(sim, pin);
            if (port->io) {
                uint8_t mask = (uint8_t)(1U << pd_bit_of(sim, pin));
                sim->avr->data[port->io->r_pin] =
                    (uint8_t)((sim->avr->data[port->io->r_pin] & ~mask) | (in->level ? mask : 0U));
            }
        }
        in->timer = 0;
        pd_arm_pulses(sim, in);
    }
}

/* Any pin IRQ of a port: re-read the registers rather than trusting the IRQ
 * value, and let pd_pins drop samples that change nothing. */
static void pd_pin_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    pd_port_t *port = param;
    pd_port_sample(&g_sim, port, g_sim.avr->data[port->io->r_ddr]);
}

/* The DDR IRQ is raised before the register is written: use its value. */
static void pd_ddr_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    pd_port_sample(&g_sim, param, (uint8_t)value);
}

/* The receive-complete interrupt raised: a byte is ready in UDR0. The last one
 * of a host burst (none left here, none more in simavr's FIFO) starts the
 * clock that the next byte the UART sends stops (pd_uart_out_hook). */
static void pd_rxc_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    pd_sim_t *sim = param;
    const uart_fifo_t *in = &sim->uart->input;
    if (value && sim->rx.len == 0 &&
        ((in->write - in->read) & (uart_fifo_fifo_size - 1U)) <= 1U) {
        sim->rx_last_at = pd_cycles(sim);
        if (!sim->mark_from) {
            sim->mark_at = sim->rx_last_at;
        }
    }
}

/* UART0's rate now, from the registers the firmware set (UBRR0, U2X0): the rate a
 * byte it sends or receives is at, which it may change mid-run (the line rate's
 * agreement); simavr's byte time follows the same UBRR0L write. */
static uint32_t pd_uart_baud(const pd_sim_t *sim)
{
    const uint8_t *data = sim->avr->data;
    uint32_t ubrr = ((uint32_t)(data[0xC5] & 0x0FU) << 8) | data[0xC4]; /* UBRR0H, UBRR0L */
    uint32_t per_bit = (data[0xC0] & 0x02U) ? 8U : 16U;                 /* UCSR0A U2X0 */
    return (uint32_t)(sim->avr->frequency / (per_bit * (ubrr + 1U)));
}

static void pd_uart_out_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    pd_sim_t *sim = param;
    if (!pd_line_carries(&sim->line, sim->master, pd_uart_baud(sim), true)) {
        sim->line.lost_out++; /* sent at a rate the host or the line does not take */
        return;
    }
    sim->uart_tx++;
    sim->tx_last = pd_cycles(sim);
    if (sim->rx_last_at) {
        sim->answers++;
        sim->answer_cycles += sim->tx_last - sim->rx_last_at;
        sim->rx_last_at = 0;
    }
    if (sim->tx.len < PD_BUF_SIZE) {
        /* simavr raises the byte as UDR is written, when it starts to go out; it
         * is on the line for the UART's own byte time (11 bits in simavr 1.6). */
        uint64_t per_byte = sim->uart && sim->uart->cycles_per_byte ? sim->uart->cycles_per_byte
                                                                     : sim->byte_cycles;
        sim->tx_due[(sim->tx.head + sim->tx.len) % PD_BUF_SIZE] = sim->tx_last + per_byte;
    }
    pd_fifo_push(&sim->tx, (uint8_t)value);
}

/* Wraps the core's reset so that every reset (ours, the watchdog's) is seen. */
static void pd_core_reset(struct avr_t *avr)
{
    /* Before simavr clears the registers (and the cycle count): every pin is released. */
    pd_pins_reset(&g_sim.pins, pd_cycles(&g_sim));
    if (g_sim.core_reset) {
        g_sim.core_reset(avr);
    }
    g_sim.reset_seen = 1;
}

static void pd_sleep_hook(avr_t *avr, avr_cycle_count_t how_long)
{
    /* The main loop paces emulation; simavr's own usleep() would stall it.
     * simavr then advances the clock by 1 + how_long cycles of sleep. */
    (void)avr;
    g_sim.sleep_cycles += 1U + how_long;
}

/* One line of counters for --stats. A stopped (crashed) MCU's time counts as
 * awake: it is not asleep, and nothing measures a crashed board's cost. */
static void pd_write_stats(pd_sim_t *sim)
{
    if (!sim->stats) {
        return;
    }
    if (sim->stack_path) {
        /* --stack: the deepest stack's bytes, for protoduino_dev.stackwalk (replaced),
         * before the line that says it is there. */
        FILE *f = fopen(sim->stack_path, "wb");
        if (f) {
            fwrite(sim->sp_min_stack, 1, sim->sp_min_len, f);
            fclose(f);
        }
    }
    uint64_t cycles = pd_cycles(sim);
    uint64_t sleep = sim->sleep_cycles < cycles ? sim->sleep_cycles : cycles;
    fprintf(sim->stats,
            "{\"t\": %.6f, \"freq\": %u, \"cycles\": %llu, \"sleep_cycles\": %llu, "
            "\"awake_cycles\": %llu, \"uart_rx_bytes\": %llu, \"uart_tx_bytes\": %llu, "
            "\"sp_min\": %u, \"sp_min_pc\": %lu, \"ramend\": %u, \"passes\": %llu, "
            "\"rx_lag_max\": %llu, \"answers\": %llu, \"answer_cycles\": %llu, "
            "\"start_ns\": %llu, \"uart_byte_cycles\": %llu, \"uart_baud\": %u, "
            "\"line_lost_in\": %llu, \"line_lost_out\": %llu, \"marks\": %llu, "
            "\"mark_cycles\": %llu, \"extint\": [",
            (double)cycles / (double)sim->avr->frequency, (unsigned)sim->avr->frequency,
            (unsigned long long)cycles, (unsigned long long)sleep,
            (unsigned long long)(cycles - sleep), (unsigned long long)sim->uart_rx,
            (unsigned long long)sim->uart_tx, (unsigned)sim->sp_min, (unsigned long)sim->sp_min_pc,
            (unsigned)sim->avr->ramend, (unsigned long long)sim->passes,
            (unsigned long long)sim->rx_lag_max, (unsigned long long)sim->answers,
            (unsigned long long)sim->answer_cycles, (unsigned long long)g_start_ns,
            (unsigned long long)(sim->uart ? sim->uart->cycles_per_byte : 0U),
            (unsigned)pd_uart_baud(sim), (unsigned long long)sim->line.lost_in,
            (unsigned long long)sim->line.lost_out, (unsigned long long)sim->marks,
            (unsigned long long)sim->mark_cycles);
    for (int n = 0; n < PD_EXTINTS; n++) {
        const pd_extint_t *x = &sim->extint[n];
        fprintf(sim->stats,
                "%s{\"edges\": %llu, \"lost\": %llu, \"served\": %llu, \"latency_sum\": %llu, "
                "\"latency_max\": %llu, \"latency_max_pc\": %lu}",
                n ? ", " : "", (unsigned long long)x->edges, (unsigned long long)x->lost,
                (unsigned long long)x->served, (unsigned long long)x->latency_sum,
                (unsigned long long)x->latency_max, (unsigned long)x->latency_max_pc);
    }
    fprintf(sim->stats, "]}\n");
    fflush(sim->stats);
}

/* --profile: replace the file (atomically, by rename) and start counting again. */
static void pd_write_profile(pd_sim_t *sim)
{
    if (!sim->profile) {
        return;
    }
    char tmp[4096];
    if (snprintf(tmp, sizeof tmp, "%s.tmp", sim->profile_path) >= (int)sizeof tmp) {
        return;
    }
    FILE *f = fopen(tmp, "w");
    if (!f) {
        perror("avrsim: profile file");
        return;
    }
    for (size_t i = 0; i < sim->profile_words; i++) {
        if (sim->profile[i]) {
            fprintf(f, "0x%05zx %llu\n", i * 2U, (unsigned long long)sim->profile[i]);
        }
    }
    if (fclose(f) == 0) {
        rename(tmp, sim->profile_path);
    }
    memset(sim->profile, 0, sim->profile_words * sizeof *sim->profile);
}

/* One avr_run; with --profile, its awake cycles go to the address it ran
 * (an interrupt taken meanwhile is charged its entry there, its body at its
 * own addresses; the cycles of a sleep are not awake). */
static int pd_run_one(pd_sim_t *sim)
{
    avr_t *avr = sim->avr;
    if (!sim->profile) {
        return avr_run(avr);
    }
    avr_flashaddr_t pc = avr->pc; /* a byte address */
    int running = avr->state == cpu_Running;
    uint64_t cycle = avr->cycle;
    uint64_t slept = sim->sleep_cycles;
    int state = avr_run(avr);
    uint64_t spent = avr->cycle >= cycle ? avr->cycle - cycle : 0; /* 0: a reset */
    uint64_t asleep = sim->sleep_cycles - slept;
    spent = spent > asleep ? spent - asleep : 0;
    if (running && pc / 2U < sim->profile_words) {
        sim->profile[pc / 2U] += spent;
    }
    return state;
}

/* The I/O address an OUT instruction at `pc` writes, or -1 for another instruction
 * (OUT A, Rr is 1011 1AAr rrrr AAAA). */
static int pd_out_address(const avr_t *avr, avr_flashaddr_t pc)
{
    if (pc + 1U > avr->flashend) {
        return -1;
    }
    uint16_t op = (uint16_t)(avr->flash[pc] | (avr->flash[pc + 1U] << 8));
    if ((op & 0xF800U) != 0xB800U) {
        return -1;
    }
    return (int)(((op >> 5) & 0x30U) | (op & 0x0FU));
}

/* The stack's low-water mark, after the instruction at `pc` ran. A frame is
 * allocated by writing SP's two halves one after the other (SPH first, with
 * interrupts held off): in between, SP reads as the new high byte with the old
 * low byte, up to 255 bytes below anything the program uses; that value is
 * not a stack depth, so SP is sampled only when both halves agree. */
static void pd_track_sp(pd_sim_t *sim, avr_flashaddr_t pc)
{
    int out = pd_out_address(sim->avr, pc);
    if (out == R_SPH - 32) {
        sim->sp_split = 1;
    } else if (out == R_SPL - 32) {
        sim->sp_split = 0;
    }
    if (sim->sp_split) {
        return;
    }
    uint16_t sp = (uint16_t)(sim->avr->data[R_SPL] | (sim->avr->data[R_SPH] << 8));
    if (sp < sim->sp_min) {
        sim->sp_min = sp;
        sim->sp_min_pc = sim->avr->pc;
        if (sim->stack_path && sp < sim->avr->ramend) {
            /* New lows are rare after the first moments: the copy costs nothing then. */
            size_t n = (size_t)(sim->avr->ramend - sp);
            if (n <= sizeof sim->sp_min_stack) {
                memcpy(sim->sp_min_stack, &sim->avr->data[sp + 1], n);
                sim->sp_min_len = n;
            }
        }
    }
}

/* --mark: the first time the MCU is about to run one of the marked addresses after a
 * host burst's last byte was ready in UDR0, the cycles since then are counted. */
static void pd_check_mark(pd_sim_t *sim, avr_flashaddr_t pc)
{
    for (int i = 0; i < sim->mark_count; i++) {
        if (sim->mark_pc[i] == pc) {
            sim->marks++;
            sim->mark_cycles += pd_cycles(sim) - sim->mark_at;
            sim->mark_at = 0;
            return;
        }
    }
}

static void pd_set_extrf(pd_sim_t *sim)
{
    avr_t *avr = sim->avr;
    if (avr->reset_flags.extrf.reg) {
        avr_regbit_clear(avr, avr->reset_flags.porf);
        avr_regbit_set(avr, avr->reset_flags.extrf);
    } else {
        avr->data[PD_MCUSR_ADDR] = PD_MCUSR_EXTRF;
    }
}

/* simavr 1.6 emulates every INTn's low-level trigger by polling the pin on
 * every cycle, through a new cycle timer per falling edge, while the pin is
 * low, enabled or not: a servo on D2 or D3 (low 90 % of the time) made the
 * emulator slower than real time, and on the Mega the same on pins 2 and 3
 * (INT4, INT5; two outputs there left the board silent to the host after a few
 * commands). Level triggering then acts like a falling edge, which nothing on
 * protoduino's boards relies on. Each INTn the MCU has is tamed (simavr skips
 * the others); extint's reset turns the polling back on, so this runs after
 * every reset. */
static void pd_tame_extint(pd_sim_t *sim)
{
    for (uint8_t n = 0; n < EXTINT_COUNT; n++) {
        avr_extint_set_strict_lvl_trig(sim->avr, n, 0);
    }
}

static void pd_after_reset(pd_sim_t *sim)
{
    sim->reset_seen = 0;
    pd_tame_extint(sim);
    for (int n = 0; n < PD_EXTINTS; n++) {
        sim->extint[n].raised_at = 0; /* a reset clears the flags */
    }
    /* The clock first: pd_start_rx places host bytes by it. */
    if (sim->avr->cycle < sim->last_cycle) {
        sim->cycle_base += sim->last_cycle;
    }
    sim->last_cycle = sim->avr->cycle;
    sim->rx_timer = 0; /* a reset cancels every cycle timer */
    sim->pace_at = 0;
    pd_start_rx(sim);
    pd_restore_inputs(sim);
    pd_ports_sample(sim);
}

/* Reset as the reset pin does (SIGUSR1, or a client opening the port). */
static void pd_reset_mcu(pd_sim_t *sim)
{
    sim->last_cycle = sim->avr->cycle;
    avr_reset(sim->avr);
    if (sim->boot) {
        sim->avr->pc = sim->boot_addr;
    }
    sim->avr->state = cpu_Running;
    pd_set_extrf(sim);
    sim->crashed = 0;
    pd_after_reset(sim);
}

static int pd_open_pty(pd_sim_t *sim)
{
    sim->master = posix_openpt(O_RDWR | O_NOCTTY);
    if (sim->master < 0 || grantpt(sim->master) < 0 || unlockpt(sim->master) < 0) {
        perror("avrsim: posix_openpt");
        return -1;
    }
    const char *name = ptsname(sim->master);
    if (!name || strlen(name) >= sizeof sim->slave_path) {
        perror("avrsim: ptsname");
        return -1;
    }
    strcpy(sim->slave_path, name);
    /* Hold the slave open ourselves: the master then never sees EIO or a
     * hangup when the host closes and reopens the port. */
    sim->slave = open(sim->slave_path, O_RDWR | O_NOCTTY);
    if (sim->slave < 0) {
        perror("avrsim: open slave");
        return -1;
    }
    struct termios tio;
    if (tcgetattr(sim->slave, &tio) == 0) {
        cfmakeraw(&tio);
        cfsetispeed(&tio, B115200);
        cfsetospeed(&tio, B115200);
        tcsetattr(sim->slave, TCSANOW, &tio);
    }
    int flags = fcntl(sim->master, F_GETFL);
    fcntl(sim->master, F_SETFL, flags | O_NONBLOCK);
    return 0;
}

static avr_io_t *pd_find_io(avr_t *avr, const char *kind, char name)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next) {
        if (!strcmp(io->kind, kind)) {
            /* avr_uart_t, avr_ioport_t and avr_timer_t all start with the
             * io, then the name. */
            char io_name = !strcmp(kind, "uart")    ? ((avr_uart_t *)io)->name
                           : !strcmp(kind, "timer") ? ((avr_timer_t *)io)->name
                                                    : ((avr_ioport_t *)io)->name;
            if (io_name == name) {
                return io;
            }
        }
    }
    return NULL;
}

static void pd_connect(pd_sim_t *sim)
{
    avr_t *avr = sim->avr;
    sim->board = &pd_boards[0];
    while (sim->board->mcu && strcmp(sim->board->mcu, avr->mmcu) != 0) {
        sim->board++;
    }
    /* The board's ports, in the order its pins first name them. */
    sim->port_count = 0;
    for (int pin = 0; pin < sim->board->num_pins; pin++) {
        char name = sim->board->map[pin][0];
        int i = 0;
        while (i < sim->port_count && sim->ports[i].name != name) {
            i++;
        }
        if (i == sim->port_count) {
            sim->ports[i].name = name;
            memset(sim->ports[i].pin, -1, sizeof sim->ports[i].pin);
            sim->port_count++;
        }
        sim->ports[i].pin[(int)sim->board->map[pin][1]] = (int8_t)pin;
        sim->port_of[pin] = (int8_t)i;
    }
    for (int i = 0; i < sim->port_count; i++) {
        pd_port_t *port = &sim->ports[i];
        port->io = (avr_ioport_t *)pd_find_io(avr, "port", port->name);
        if (!port->io) {
            continue;
        }
        for (int b = 0; b < 8; b++) {
            if (port->pin[b] < 0) {
                continue;
            }
            avr_irq_t *irq = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(port->name), b);
            if (irq) {
                avr_irq_register_notify(irq, pd_pin_hook, port);
            }
        }
        avr_irq_t *ddr =
            avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(port->name), IOPORT_IRQ_DIRECTION_ALL);
        if (ddr) {
            avr_irq_register_notify(ddr, pd_ddr_hook, port);
        }
    }

    if (sim->board->map == pd_mega_map) {
        g_pwm_pins = g_mega_pwm_pins;
        g_pwm_count = sizeof g_mega_pwm_pins / sizeof g_mega_pwm_pins[0];
    }
    for (size_t i = 0; i < PD_PWM_PINS; i++) {
        pd_pwm_pin_t *w = &g_pwm_pins[i];
        w->timer = (avr_timer_t *)pd_find_io(avr, "timer", w->timer_name);
        avr_irq_t *oc =
            avr_io_getirq(avr, AVR_IOCTL_TIMER_GETIRQ(w->timer_name), TIMER_IRQ_OUT_COMP + w->comp);
        if (w->timer && oc) {
            avr_irq_register_notify(oc, pd_oc_hook, w);
            pd_timer_reg_add(sim, w->timer->comp[w->comp].com.reg);
            pd_timer_reg_add(sim, w->timer->wgm[0].reg);
            pd_timer_reg_add(sim, w->timer->wgm[2].reg);
            pd_timer_reg_add(sim, w->timer->cs[0].reg);
        } else {
            w->timer = NULL;
        }
    }
    for (int pin = 0; pin < PD_PINS_COUNT; pin++) {
        sim->input[pin].pin = pin;
    }
    avr->vcc = avr->avcc = avr->aref = PD_VCC_MV;

    sim->uart = (avr_uart_t *)pd_find_io(avr, "uart", '0');
    uint32_t flags = 0; /* no stdio echo of the UART, no usleep when polled */
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    if (sim->uart) {
        avr_irq_register_notify(&sim->uart->rxc.irq[AVR_INT_IRQ_PENDING], pd_rxc_hook, sim);
    }
    avr_irq_t *out = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT);
    if (out) {
        avr_irq_register_notify(out, pd_uart_out_hook, sim);
    }
}

/* Wall-clock time as a cycle count of the emulated MCU. */
static uint64_t pd_wall_cycles(const pd_sim_t *sim)
{
    return (uint64_t)((double)(pd_now_ns() - g_start_ns) * (double)sim->avr->frequency / 1e9);
}

/* One byte from the host into the UART per byte time, as a wire would. It
 * runs as a simavr cycle timer, so bytes arrive on time even while the MCU
 * sleeps (a sleeping core skips ahead to its next timer event). */
static avr_cycle_count_t pd_rx_timer(struct avr_t *avr, avr_cycle_count_t when, void *param)
{
    pd_sim_t *sim = param;
    /* At the rate the firmware set (UBRR, U2X), as a wire at that rate would
     * carry host bytes: a firmware at 57600 baud must not be fed at 115200.
     * simavr's byte time counts 11 bits for 8N1; a host's byte is 10. Before the
     * firmware sets a rate, the default baud's. */
    const avr_cycle_count_t per_byte = sim->uart && sim->uart->cycles_per_byte
                                           ? sim->uart->cycles_per_byte * 10U / 11U
                                           : sim->byte_cycles;
    if (!sim->rx.len) {
        sim->rx_timer = 0;
        return 0;
    }
    if (sim->uart) {
        /* simavr's receive FIFO (avr_uart.h); full means the firmware lags. */
        const uart_fifo_t *in = &sim->uart->input;
        if (((in->write + 1U) & (uart_fifo_fifo_size - 1U)) == in->read) {
            return when + per_byte;
        }
    }
    avr_irq_t *in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    if (sim->rx_first) {
        sim->rx_first = 0;
        uint64_t at = sim->cycle_base + when;
        if (at > sim->rx_read_at && at - sim->rx_read_at > sim->rx_lag_max) {
            sim->rx_lag_max = at - sim->rx_read_at;
        }
    }
    uint8_t b = sim->rx.data[sim->rx.head];
    sim->rx.head = (sim->rx.head + 1) % PD_BUF_SIZE;
    sim->rx.len--;
    if (in) {
        avr_raise_irq(in, b);
        sim->uart_rx++;
    }
    return when + per_byte;
}

/* Host bytes start into the UART at the emulated time that matches the wall
 * clock's now, or at once if emulation is ahead of it: never at an emulated
 * time before they were written, which a runner behind the wall clock (it
 * waited, or the machine is loaded) would otherwise give them. */
static void pd_start_rx(pd_sim_t *sim)
{
    if (sim->rx.len && !sim->rx_timer && !sim->crashed) {
        sim->rx_timer = 1;
        uint64_t wall = pd_wall_cycles(sim);
        uint64_t now = pd_cycles(sim);
        sim->rx_read_at = wall;
        sim->rx_first = 1;
        avr_cycle_timer_register(sim->avr, wall > now ? wall - now : 1, pd_rx_timer, sim);
    }
}

/* Does nothing: it is there so that a sleeping MCU, which simavr skips ahead to
 * its next cycle timer, stops at the pass's target (PD_AHEAD_NS). Once due it
 * stays armed a cycle ahead until the next pass moves it: simavr asks the timers
 * for the next sleep right after the instruction that crossed the target, and a
 * SLEEP there, with this timer gone, slept to the next tick (up to a millisecond
 * ahead of the wall clock, and a host byte entered the UART that much late). */
static avr_cycle_count_t pd_pace_timer(struct avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)when;
    ((pd_sim_t *)param)->pace_at = 0;
    return avr->cycle + 1U;
}

static void pd_set_pace(pd_sim_t *sim, uint64_t target)
{
    if (sim->pace_at == target) {
        return;
    }
    avr_cycle_timer_cancel(sim->avr, pd_pace_timer, sim);
    uint64_t now = pd_cycles(sim);
    sim->pace_at = target;
    avr_cycle_timer_register(sim->avr, target > now ? target - now : 1, pd_pace_timer, sim);
}

/* The cycle (pd_cycles terms) of the soonest cycle timer other than the pace
 * timer: the next thing that can wake a sleeping MCU, short of host bytes and
 * the control socket, which end the runner's wait. UINT64_MAX when none. The
 * whole pool (sim_cycle_timers.h, at most 64) is looked at: its order is
 * simavr's business. */
static uint64_t pd_next_event(const pd_sim_t *sim)
{
    uint64_t next = UINT64_MAX;
    for (avr_cycle_timer_slot_p t = sim->avr->cycle_timers.timer; t; t = t->next) {
        if (t->timer != pd_pace_timer && sim->cycle_base + t->when < next) {
            next = sim->cycle_base + t->when;
        }
    }
    return next;
}

/*
 * What UART0 sent goes to the host no earlier than a line would have delivered
 * it: emulation runs up to PD_AHEAD_NS ahead of the wall clock, and a byte sent
 * early would make a round trip look shorter than the line allows. A burst goes
 * whole once its last byte is due and the UART has been quiet for a byte time
 * (one write, as a USB-serial bridge passes a short frame on); a stream that
 * never pauses goes on in chunks once its oldest byte waited PD_STREAM_NS.
 */
static void pd_flush_tx(pd_sim_t *sim)
{
    if (!sim->tx.len) {
        return;
    }
    uint64_t wall = pd_wall_cycles(sim);
    /* Only the bytes not yet known due are looked at: with nobody reading, a full
     * tx would otherwise be scanned whole on every pass. */
    while (sim->tx_ready < sim->tx.len &&
           sim->tx_due[(sim->tx.head + sim->tx_ready) % PD_BUF_SIZE] <= wall) {
        sim->tx_ready++;
    }
    size_t due = sim->tx_ready;
    uint64_t stream = (uint64_t)((double)PD_STREAM_NS * (double)sim->avr->frequency / 1e9);
    int burst_done = due == sim->tx.len && pd_cycles(sim) - sim->tx_last > sim->byte_cycles;
    int stream_late = due > 0 && wall - sim->tx_due[sim->tx.head] >= stream;
    if (!burst_done && !stream_late) {
        return;
    }
    while (due) {
        size_t chunk = PD_BUF_SIZE - sim->tx.head;
        if (chunk > due) {
            chunk = due;
        }
        ssize_t n = write(sim->master, sim->tx.data + sim->tx.head, chunk);
        if (n <= 0) {
            sim->tx_blocked = 1;
            break; /* nobody reads: the bytes wait in tx (bounded) */
        }
        sim->tx_blocked = 0;
        sim->tx.head = (sim->tx.head + (size_t)n) % PD_BUF_SIZE;
        sim->tx.len -= (size_t)n;
        sim->tx_ready -= (size_t)n;
        due -= (size_t)n;
    }
}

static void pd_pump_pty(pd_sim_t *sim)
{
    while (sim->rx.len < PD_BUF_SIZE) {
        uint8_t buf[256];
        size_t room = PD_BUF_SIZE - sim->rx.len;
        ssize_t n = read(sim->master, buf, room < sizeof buf ? room : sizeof buf);
        if (n <= 0) {
            break;
        }
        if (sim->crashed) {
            continue; /* a stopped MCU drops what arrives, as a real one would */
        }
        if (!pd_line_carries(&sim->line, sim->master, pd_uart_baud(sim), false)) {
            sim->line.lost_in += (uint64_t)n; /* sent at a rate UART0 is not at */
            continue;
        }
        for (ssize_t i = 0; i < n; i++) {
            pd_fifo_push(&sim->rx, buf[i]);
        }
    }
    pd_flush_tx(sim);
}

/* A client opened the port while no other held it: the board's DTR auto-reset.
 * A real USB serial port asserts DTR at the first open and drops it at the last
 * close (HUPCL), so a second client opening a port already held open resets
 * nothing; the emulated one counts the clients' opens and closes the same way
 * (the runner's own descriptor predates the watch). inotify merges two identical
 * events left unread, so two closes within one pass may count as one: a client
 * count above 0 then outlasts them until the next close, and the count never goes
 * below 0. */
static void pd_check_opens(pd_sim_t *sim)
{
    if (sim->inotify < 0) {
        return;
    }
    char buf[sizeof(struct inotify_event) * 16] __attribute__((aligned(8)));
    int opened = 0;
    for (;;) {
        ssize_t n = read(sim->inotify, buf, sizeof buf);
        if (n <= 0) {
            break;
        }
        for (char *p = buf; p < buf + n;) {
            struct inotify_event *ev = (struct inotify_event *)p;
            if (ev->mask & IN_OPEN) {
                if (sim->clients == 0) {
                    opened = 1;
                }
                sim->clients++;
            }
            if ((ev->mask & IN_CLOSE) && sim->clients > 0) {
                sim->clients--;
            }
            p += sizeof *ev + ev->len;
        }
    }
    if (opened) {
        pd_reset_mcu(sim);
    }
}

/* --glitch PIN, a test hook: every 50 us of emulated time, raise the pin's
 * IRQ with the opposite level and then its own level again. That is the shape
 * of simavr 1.6's re-raise artefact as a naive IRQ listener sees it (a short
 * pulse that never happened at the pin); the trace must not change. */
static void pd_glitch(pd_sim_t *sim)
{
    int pin = sim->glitch_pin;
    pd_port_t *port = pd_port_of(sim, pin);
    if (!port->io) {
        return;
    }
    int bit = pd_bit_of(sim, pin);
    avr_irq_t *irq = avr_io_getirq(sim->avr, AVR_IOCTL_IOPORT_GETIRQ(port->name), bit);
    if (irq) {
        uint32_t level = (sim->avr->data[port->io->r_port] >> bit) & 1U;
        avr_raise_irq(irq, level ^ 1U);
        avr_raise_irq(irq, level);
    }
    sim->next_glitch = pd_cycles(sim) + sim->avr->frequency / 20000U;
}

static int pd_load_hex(pd_sim_t *sim, const char *path)
{
    ihex_chunk_p chunks = NULL;
    int count = read_ihex_chunks(path, &chunks);
    if (count <= 0) {
        fprintf(stderr, "avrsim: cannot read Intel hex %s\n", path);
        return -1;
    }
    for (int i = 0; i < count; i++) {
        if (chunks[i].baseaddr + chunks[i].size > sim->avr->flashend + 1U) {
            fprintf(stderr, "avrsim: %s: data at 0x%x is outside the flash\n", path,
                    chunks[i].baseaddr);
            free_ihex_chunks(chunks);
            return -1;
        }
        avr_loadcode(sim->avr, chunks[i].data, chunks[i].size, chunks[i].baseaddr);
    }
    free_ihex_chunks(chunks);
    return 0;
}

static void pd_usage(FILE *f)
{
    fprintf(f,
            "usage: avrsim [--trace FILE] [--link PATH] [--control PATH] [--hex FILE]...\n"
            "              [--boot ADDR] [--auto-reset] [--glitch PIN] [--stats FILE]\n"
            "              [--profile FILE] [--stack FILE] [--mcu NAME] [--freq HZ]\n"
            "              [--owner-fd FD] [--line-check] [--line-max BAUD] [--line-max-out BAUD]\n"
            "              [--mark ADDR]... [--mark-from ADDR]\n"
            "              [FIRMWARE.elf]\n"
            "Runs an emulated Arduino Uno with UART0 on a pseudo-terminal; prints the\n"
            "port as the first stdout line. SIGUSR1 resets the MCU, SIGINT/SIGTERM exit;\n"
            "--owner-fd FD: exit when FD (the owner's pipe) reads end-of-file;\n"
            "with --stats, SIGUSR2 and the exit append cycle and UART counters to FILE;\n"
            "with --profile, SIGUSR2 writes awake cycles per flash address to FILE;\n"
            "with --stats and --stack, each stats line also writes the deepest stack's bytes to FILE;\n"
            "--control PATH: a Unix socket taking JSON input commands, one per line;\n"
            "--line-*: bytes cross only at the rate both ends set (and at most BAUD);\n"
            "--mark ADDR (with --stats): cycles from a host burst's last byte (or from\n"
            "--mark-from's address) to the next ADDR reached.\n");
}

static void pd_cleanup(pd_sim_t *sim)
{
    pd_control_close(&sim->control);
    if (sim->link) {
        unlink(sim->link);
    }
    if (sim->trace) {
        fclose(sim->trace);
        sim->trace = NULL;
    }
    if (sim->stats) {
        fclose(sim->stats);
        sim->stats = NULL;
    }
    free(sim->profile);
    sim->profile = NULL;
}

static void pd_run(pd_sim_t *sim)
{
    const uint64_t start_ns = g_start_ns;
    const double cycles_per_ns = (double)sim->avr->frequency / 1e9;
    sim->byte_cycles = sim->avr->frequency * 10ULL / PD_DEFAULT_BAUD;
    /* An owned runner ends with its owner (killed with no chance to stop us),
     * or runners pile up unseen; one started on purpose runs until stopped. */
    while (!g_stop && !pd_owner_gone(sim->owner_fd)) {
        sim->passes++;
        if (g_reset) {
            g_reset = 0;
            pd_reset_mcu(sim);
        }
        if (g_dump_stats) {
            g_dump_stats = 0;
            pd_write_profile(sim);
            pd_write_stats(sim);
        }
        pd_check_opens(sim);
        pd_pump_pty(sim);
        pd_start_rx(sim);

        uint64_t wall_ns = pd_now_ns() - start_ns;
        uint64_t target = (uint64_t)((double)(wall_ns + PD_AHEAD_NS) * cycles_per_ns);
        uint64_t batch_end = pd_cycles(sim) + (uint64_t)((double)PD_BATCH_NS * cycles_per_ns);
        if (target > batch_end) {
            target = batch_end;
        }
        if (!sim->crashed) {
            pd_set_pace(sim, target);
            while (pd_cycles(sim) < target && !g_stop && !g_reset) {
                sim->last_cycle = sim->avr->cycle;
                avr_flashaddr_t pc = sim->avr->pc;
                if (sim->mark_at) {
                    pd_check_mark(sim, pc);
                } else if (sim->mark_from && pc == sim->mark_from) {
                    sim->mark_at = pd_cycles(sim);
                }
                pd_extint_check(sim, pc);
                int state = pd_run_one(sim);
                pd_track_sp(sim, pc);
                pd_timer_regs_check(sim);
                if (sim->reset_seen) {
                    pd_after_reset(sim);
                }
                if (state == cpu_Done || state == cpu_Crashed) {
                    fprintf(stderr, "avrsim: the MCU stopped (state %d); SIGUSR1 resets it\n",
                            state);
                    sim->crashed = 1;
                    break;
                }
                if (sim->glitch_pin >= 0 && pd_cycles(sim) >= sim->next_glitch) {
                    pd_glitch(sim);
                }
            }
        } else {
            /* A stopped MCU still lets time pass, so that deadlines resolve. */
            sim->cycle_base = target > sim->avr->cycle ? target - sim->avr->cycle : 0;
        }
        /* Whatever changed with no IRQ and was not seen yet (pd_timer_regs_check). */
        pd_ports_sample(sim);
        pd_pins_poll(&sim->pins, pd_cycles(sim));
        pd_control_service(&sim->control);
        pd_pump_pty(sim);
        pd_start_rx(sim);
        if (sim->port_out && !sim->tx.len &&
            pd_cycles(sim) >= (uint64_t)sim->avr->frequency / 1000U * PD_ANNOUNCE_MS) {
            fprintf(sim->port_out, "%s\n", sim->port_name);
            fflush(sim->port_out);
            sim->port_out = NULL; /* stdout carries nothing else */
        }

        /* Wait for host bytes or until the wall clock reaches emulated time. */
        uint64_t emulated_ns = (uint64_t)((double)pd_cycles(sim) / cycles_per_ns);
        uint64_t now_ns = pd_now_ns() - start_ns;
        if (!sim->crashed && sim->avr->state == cpu_Sleeping) {
            /* Nothing happens before the next timer event: the next pass is due
             * when its target reaches that, not every PD_AHEAD_NS (an idle
             * board would wake 20,000 times a second). */
            uint64_t next = pd_next_event(sim);
            uint64_t next_ns = next == UINT64_MAX ? emulated_ns + PD_BATCH_NS
                                                  : (uint64_t)((double)next / cycles_per_ns);
            if (next_ns > emulated_ns + PD_AHEAD_NS) {
                emulated_ns = next_ns - PD_AHEAD_NS;
            }
        }
        if (sim->tx.len) {
            /* Wake when the last byte sent is due, to hand the host its burst. */
            uint64_t due_ns =
                (uint64_t)((double)sim->tx_due[(sim->tx.head + sim->tx.len - 1) % PD_BUF_SIZE] /
                           cycles_per_ns);
            if (due_ns < emulated_ns) {
                emulated_ns = due_ns > now_ns ? due_ns : now_ns;
            }
        }
        if (emulated_ns > now_ns + PD_MIN_WAIT_NS) {
            uint64_t wait_ns = emulated_ns - now_ns;
            struct timespec timeout = {.tv_sec = (time_t)(wait_ns / 1000000000ULL),
                                       .tv_nsec = (long)(wait_ns % 1000000000ULL)};
            struct pollfd fds[2 + PD_CONTROL_MAX_CLIENTS + 1] = {
                {.fd = sim->master, .events = 0}, {.fd = sim->inotify, .events = POLLIN}};
            /* With the input buffer full the pty stays readable: asking for POLLIN
             * then would return at once, every pass, and spin a core until the
             * firmware has taken some bytes (it takes one per byte time). */
            if (sim->rx.len < PD_BUF_SIZE) {
                fds[0].events |= POLLIN;
            }
            /* POLLOUT only once the pty refused bytes: it is writable otherwise,
             * and bytes not yet due must not end the wait. */
            if (sim->tx_blocked) {
                fds[0].events |= POLLOUT;
            }
            int nfds = sim->inotify >= 0 ? 2 : 1;
            nfds += pd_control_pollfds(&sim->control, fds + nfds);
            ppoll(fds, (nfds_t)nfds, &timeout, NULL);
            pd_control_service(&sim->control);
        }
    }
}

int main(int argc, char **argv)
{
    g_start_ns = pd_now_ns();
    /* Wake-ups on time: the default 50 us of timer slack would hand the host
     * its bytes up to that late, and host bytes would enter the UART late. */
    prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
    pd_sim_t *sim = &g_sim;
    const char *trace_path = NULL;
    const char *stats_path = NULL;
    const char *control_path = NULL;
    const char *hex[PD_MAX_HEX];
    int hex_count = 0;
    const char *mcu = PD_DEFAULT_MCU;
    uint32_t freq = PD_DEFAULT_FREQ;
    int auto_reset = 0;
    sim->inotify = -1;
    sim->master = -1;
    sim->slave = -1;
    sim->glitch_pin = -1;
    sim->owner_fd = -1;
    sim->sp_min = UINT16_MAX;
    pd_control_init(&sim->control);

    static const struct option options[] = {
        {"trace", required_argument, NULL, 't'}, {"link", required_argument, NULL, 'l'},
        {"hex", required_argument, NULL, 'x'},   {"boot", required_argument, NULL, 'b'},
        {"mcu", required_argument, NULL, 'm'},   {"freq", required_argument, NULL, 'f'},
        {"auto-reset", no_argument, NULL, 'r'},  {"glitch", required_argument, NULL, 'g'},
        {"stats", required_argument, NULL, 's'}, {"profile", required_argument, NULL, 'p'},
        {"stack", required_argument, NULL, 'k'},
        {"control", required_argument, NULL, 'c'}, {"owner-fd", required_argument, NULL, 'o'},
        {"help", no_argument, NULL, 'h'},
        {"line-check", no_argument, NULL, 'L'}, {"line-max", required_argument, NULL, 'M'},
        {"line-max-out", required_argument, NULL, 'O'},
        {"mark", required_argument, NULL, 'K'},
        {"mark-from", required_argument, NULL, 'F'},
        {NULL, 0, NULL, 0},
    };
    int opt;
    while ((opt = getopt_long(argc, argv, "h", options, NULL)) != -1) {
        switch (opt) {
        case 't':
            trace_path = optarg;
            break;
        case 'l':
            sim->link = optarg;
            break;
        case 'x':
            if (hex_count == PD_MAX_HEX) {
                fprintf(stderr, "avrsim: at most %d --hex files\n", PD_MAX_HEX);
                return 2;
            }
            hex[hex_count++] = optarg;
            break;
        case 'b':
            sim->boot = 1;
            sim->boot_addr = (uint32_t)strtoul(optarg, NULL, 0);
            break;
        case 'm':
            mcu = optarg;
            break;
        case 'f':
            freq = (uint32_t)strtoul(optarg, NULL, 0);
            break;
        case 'r':
            auto_reset = 1;
            break;
        case 'g':
            sim->glitch_pin = atoi(optarg);
            if (sim->glitch_pin < 2 || sim->glitch_pin >= PD_PINS_COUNT) {
                fprintf(stderr, "avrsim: --glitch takes an output pin 2..19 (2..69 on the Mega)\n");
                return 2;
            }
            break;
        case 's':
            stats_path = optarg;
            break;
        case 'p':
            sim->profile_path = optarg;
            break;
        case 'k':
            sim->stack_path = optarg;
            break;
        case 'c':
            control_path = optarg;
            break;
        case 'o':
            sim->owner_fd = pd_owner_parse(optarg, "avrsim");
            if (sim->owner_fd < 0) {
                return 2;
            }
            break;
        case 'L':
        case 'M':
        case 'O': {
            /* pd_linerate.h parses them as the native board does. */
            char *args[3] = {(char *)(opt == 'L' ? "--line-check"
                                      : opt == 'M' ? "--line-max"
                                                   : "--line-max-out"),
                             optarg, NULL};
            int at = 0;
            if (pd_line_option(&sim->line, opt == 'L' ? 1 : 2, args, &at) <= 0) {
                fprintf(stderr, "avrsim: --line-max and --line-max-out take a baud rate\n");
                return 2;
            }
            break;
        }
        case 'K':
            if (sim->mark_count == PD_MAX_MARKS) {
                fprintf(stderr, "avrsim: at most %d --mark addresses\n", PD_MAX_MARKS);
                return 2;
            }
            sim->mark_pc[sim->mark_count++] = (uint32_t)strtoul(optarg, NULL, 0);
            break;
        case 'F':
            sim->mark_from = (uint32_t)strtoul(optarg, NULL, 0);
            break;
        case 'h':
            pd_usage(stdout);
            return 0;
        default:
            pd_usage(stderr);
            return 2;
        }
    }
    const char *elf = optind < argc ? argv[optind] : NULL;
    if (optind + 1 < argc || (!elf && hex_count == 0) || freq == 0) {
        pd_usage(stderr);
        return 2;
    }

    /* stdout carries exactly one line, the port: keep the real stdout aside
     * and send anything else printed there (simavr prints) to stderr. */
    fflush(stdout);
    int port_fd = dup(STDOUT_FILENO);
    dup2(STDERR_FILENO, STDOUT_FILENO);
    FILE *port_out = port_fd >= 0 ? fdopen(port_fd, "w") : NULL;
    avr_global_logger_set(pd_logger);

    static elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf && elf_read_firmware(elf, &fw) != 0) {
        fprintf(stderr, "avrsim: cannot read ELF %s\n", elf);
        return 1;
    }
    /* The command line wins over a .mmcu section. */
    strncpy(fw.mmcu, mcu, sizeof fw.mmcu - 1);
    fw.frequency = freq;

    sim->avr = avr_make_mcu_by_name(fw.mmcu);
    if (!sim->avr) {
        fprintf(stderr, "avrsim: unknown MCU %s\n", fw.mmcu);
        return 1;
    }
    avr_init(sim->avr);
    sim->avr->log = LOG_ERROR; /* simavr warnings are about its own model, not the firmware */
    if (elf) {
        avr_load_firmware(sim->avr, &fw);
        pd_find_tables(sim, &fw);
    }
    sim->avr->frequency = freq;
    for (int i = 0; i < hex_count; i++) {
        if (pd_load_hex(sim, hex[i]) != 0) {
            return 1;
        }
    }
    sim->avr->sleep = pd_sleep_hook;
    pd_tame_extint(sim);
    sim->core_reset = sim->avr->reset;
    sim->avr->reset = pd_core_reset;
    if (sim->boot) {
        /* BOOTRST programmed; the boot section: the Uno's 1 KB (BOOTSZ = 10, hfuse
         * 0xDC) for Optiboot, the Mega 2560's 8 KB at 0x3E000 for its stk500v2
         * bootloader (BOOTSZ = 00, hfuse 0xD8 as boards.txt sets it). simavr
         * starts at reset_pc whatever the fuses say; they are set for the firmware. */
        sim->avr->fuse[AVR_FUSE_LOW] = 0xFF;
        sim->avr->fuse[AVR_FUSE_HIGH] = sim->avr->flashend > 0xFFFFU ? 0xD8 : 0xDC;
        sim->avr->fuse[AVR_FUSE_EXT] = 0xFD;
        sim->avr->reset_pc = sim->boot_addr;
        sim->avr->pc = sim->boot_addr;
        pd_set_extrf(sim);
    }

    pd_pins_init(&sim->pins, freq, pd_trace_emit, sim);
    if (trace_path) {
        sim->trace = fopen(trace_path, "w");
        if (!sim->trace) {
            perror("avrsim: trace file");
            return 1;
        }
    }
    if (sim->profile_path) {
        sim->profile_words = ((size_t)sim->avr->flashend + 1U) / 2U;
        sim->profile = calloc(sim->profile_words, sizeof *sim->profile);
        if (!sim->profile) {
            perror("avrsim: profile");
            pd_cleanup(sim);
            return 1;
        }
    }
    if (stats_path) {
        sim->stats = fopen(stats_path, "a");
        if (!sim->stats) {
            perror("avrsim: stats file");
            pd_cleanup(sim);
            return 1;
        }
    }
    pd_connect(sim);
    if (sim->glitch_pin >= sim->board->num_pins) {
        fprintf(stderr, "avrsim: --glitch: the %s has pins 2..%d\n", sim->board->name,
                sim->board->num_pins - 1);
        pd_cleanup(sim);
        return 2;
    }
    if (control_path && pd_control_open(&sim->control, control_path, pd_control_apply, sim) != 0) {
        pd_cleanup(sim);
        return 1;
    }
    if (pd_open_pty(sim) != 0) {
        pd_cleanup(sim);
        return 1;
    }
    if (auto_reset) {
        sim->inotify = inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
        if (sim->inotify < 0 || inotify_add_watch(sim->inotify, sim->slave_path, IN_OPEN | IN_CLOSE) < 0) {
            perror("avrsim: inotify (--auto-reset)");
            pd_cleanup(sim);
            return 1;
        }
    }
    const char *port = sim->slave_path;
    if (sim->link) {
        struct stat st;
        if (lstat(sim->link, &st) == 0 && S_ISLNK(st.st_mode)) {
            unlink(sim->link);
        }
        if (symlink(sim->slave_path, sim->link) != 0) {
            perror("avrsim: --link");
            sim->link = NULL;
            pd_cleanup(sim);
            return 1;
        }
        port = sim->link;
    }

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = pd_on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGUSR1, &sa, NULL);
    pd_owner_hangup(&sa);
    if (sim->stats || sim->profile) {
        sigaction(SIGUSR2, &sa, NULL); /* otherwise SIGUSR2 keeps its default */
    }
    signal(SIGPIPE, SIG_IGN);

    sim->port_out = port_out;
    sim->port_name = port;
    pd_run(sim);
    pd_write_stats(sim);
    pd_cleanup(sim);
    if (port_out) {
        fclose(port_out);
    }
    return g_stop == SIGINT ? 128 + SIGINT : 0;
}

/*
 * The simulated board: the portable core behind a POSIX HAL.
 *
 *   pd_sim [--trace FILE] [--link PATH] [--control PATH] [--owner-fd FD]
 *
 * Opens a pseudo-terminal in raw mode, prints the slave's path (or PATH when
 * --link makes a symlink to it) as the first line on stdout, then runs the
 * core until SIGINT/SIGTERM/SIGHUP, or with --owner-fd until its owner is
 * gone (pd_owner.h says the rule). The exit status is 0, or 130 (128 + SIGINT)
 * after a Ctrl-C, as a shell reports an interrupted command.
 * SIGUSR1 is a simulated reboot (the core and a user service's statics as at
 * power-up, see sim_user_reset). The pins are
 * virtual: every change is written to the trace as one JSON object per line,
 * flushed per line, with t = seconds since the process started (monotonic).
 * --control PATH opens the input-control socket (firmware/simcontrol): levels,
 * analog values and pulse trains on the virtual input pins, which the HAL's
 * input functions read back on the same clock. A pulse train is computed
 * from the clock when it is read, not stepped, so no edge depends on how
 * often this loop runs.
 *
 * We keep our own slave fd open for the whole run. Without it the master sees
 * EIO/POLLHUP whenever the host closes the port, and a host that reopens it
 * (reconnect tests, session restore) would find a dead board.
 */
#define _DEFAULT_SOURCE /* cfmakeraw, posix_openpt & co. */
#define _XOPEN_SOURCE 700

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "pd_control.h"
#include "pd_core.h"
#include "pd_linerate.h"
#include "pd_owner.h"

/*
 * The transmit queue, as on the Uno: frames wait here and the loop moves them
 * to the pty when it can take them, never waiting for it. Sized as the Uno's ring
 * is (the reserve and a free byte: pd_avr.h), so the core holds back received frames
 * on the same occasions; the reserve is this build's, whose pins are the Mega's 70.
 */
#define SIM_TX_SIZE (PD_TX_RESERVE + 1u)

enum { SIM_PIN_UNUSED = 0, SIM_PIN_SERVO, SIM_PIN_DIGITAL, SIM_PIN_PWM };

/* A virtual input pin, as the control socket drives it. */
typedef struct {
    uint8_t level;   /* the level outside pulse trains */
    uint16_t analog; /* counts, 0..1023 (pins 14..19) */
    uint32_t pulses; /* the current train: 0 = none */
    uint32_t hz;
    double start; /* board seconds of the train's first edge */
    int8_t edge;  /* counting (the Edge enum), -1: not */
    uint32_t counted; /* edges counted before the current train (and before start_edges) */
    uint32_t start_edges; /* the current train's edges of that kind when counting began */
} sim_input_t;

typedef struct sim_hal {
    int master;
    sim_input_t input[PD_MAX_PINS];
    FILE *trace;
    struct timespec start;
    double wall_read; /* the wall clock's seconds at the last reading of the board's */
    double board;     /* the board's seconds then (sim_elapsed) */
    uint8_t mode[PD_MAX_PINS];
    uint16_t value[PD_MAX_PINS];
    uint8_t tx[SIM_TX_SIZE];
    size_t tx_len; /* bytes queued, from tx[0] */
    uint32_t last_boot_id;
    uint16_t adc_value;             /* the conversion under way */
    bool driven[PD_MAX_PINS];       /* the control socket set the pin's level */
    uint32_t baud;                  /* the device's line rate (pd_hal_set_baud) */
    pd_line_t line;                 /* --line-*: what the line carries (pd_linerate.h) */
    const pd_board_info_t *info;    /* the pins it serves: sim_board, or the Mega's (--board mega) */
} sim_hal_t;

/* The Mega 2560's table (avr/pd_avr_mega.c, built into this program too): --board mega. */
extern const pd_board_info_t pd_avr_mega_info;

static const pd_board_info_t sim_board = {
    .board = "sim",
    .num_pins = 20,
    .max_servos = 8,
    .reserved_pins = PD_PINSET(PD_PIN(0) | PD_PIN(1), 0, 0), /* the Uno's UART, for the same semantics */
    .rx_buffer = 512,                         /* one read() of the pty; the pty holds more */
    /* The Uno's pin capabilities and timer rules, so that a program tested here
     * meets the same refusals on the board. */
    .pwm_pins = PD_PINSET(PD_PIN(3) | PD_PIN(5) | PD_PIN(6) | PD_PIN(9) | PD_PIN(10) | PD_PIN(11),
                         0, 0),
    .analog_pins = PD_PINSET(0x3FUL << 14, 0, 0),
    .counter_pins = PD_PINSET(0x3FFCUL, 0, 0),    /* 2..13, as the Uno */
    .pin_change_pins = PD_PINSET(0x3FF0UL, 0, 0), /* 4..13: the Uno's pin-change interrupts */
    .servo_timer_pins = PD_PINSET(PD_PIN(9) | PD_PIN(10), 0, 0),
    .servo_timer = 1,
    .clock_timer = 0,
};

static volatile sig_atomic_t sim_stop; /* the signal that stopped it, 0 while running */
static volatile sig_atomic_t sim_reboot;

/*
 * A user service's static variables (docs/services.md: a reboot empties the device). An
 * MCU's C runtime puts every static back at reset; here the core is initialised again, and
 * the user's own statics, which no init function of ours knows, are put back from a copy
 * taken before the core ran: firmware/Makefile links the user's sources into the two
 * sections below (posix/pd_user_sections.ld), whose bounds the linker provides. Weak: a
 * board without a service has neither section.
 */
extern char __start_pd_user_data[] __attribute__((weak));
extern char __stop_pd_user_data[] __attribute__((weak));
extern char __start_pd_user_bss[] __attribute__((weak));
extern char __stop_pd_user_bss[] __attribute__((weak));

typedef struct {
    char *start;
    size_t size;
    char *copy; /* as the program started */
} sim_user_section_t;

static sim_user_section_t sim_user_sections[2];

/* Byte by byte and not instrumented: the sections hold AddressSanitizer's red zones
 * between the user's variables, which are only bytes to a copy of the whole. */
__attribute__((no_sanitize_address)) static void sim_copy_bytes(char *to, const char *from,
                                                                size_t size)
{
    volatile char *out = to;
    const volatile char *in = from;
    for (size_t i = 0; i < size; i++) {
        out[i] = in[i];
    }
}

static void sim_user_keep(void)
{
    char *bounds[2][2] = {{__start_pd_user_data, __stop_pd_user_data},
                          {__start_pd_user_bss, __stop_pd_user_bss}};
    for (size_t i = 0; i < 2; i++) {
        sim_user_section_t *sec = &sim_user_sections[i];
        sec->start = bounds[i][0];
        sec->size = (bounds[i][0] != NULL) ? (size_t)(bounds[i][1] - bounds[i][0]) : 0u;
        if (sec->size != 0) {
            sec->copy = malloc(sec->size); /* the POSIX board's own, never the firmware's */
            if (sec->copy == NULL) {
                perror("pd_sim: the user service's statics");
                exit(1);
            }
            sim_copy_bytes(sec->copy, sec->start, sec->size);
        }
    }
}

static void sim_user_reset(void)
{
    for (size_t i = 0; i < 2; i++) {
        const sim_user_section_t *sec = &sim_user_sections[i];
        if (sec->size != 0) {
            sim_copy_bytes(sec->start, sec->copy, sec->size);
        }
    }
}

/*
 * The board's clock, in seconds since start: the host's monotonic clock, except
 * that a gap between two readings longer than SIM_MAX_STEP counts as that. An
 * MCU's time passes while it runs; this process does not run while a loaded
 * host keeps it waiting, and on the wall clock its failsafe (checked once a
 * loop pass) then looked late by however long that was: a test of the failsafe's
 * timing saw 0.15 ms over its 3 ms bound on a busy machine. With the cap, the
 * board fires within SIM_MAX_STEP of its deadline on its own clock, as the
 * emulated Uno does on its emulated one, whatever the load. The loop reads the
 * clock every pass (poll() waits 1 ms at most), so on a host that keeps up no
 * gap reaches the cap and the board's clock is the wall clock.
 */
#define SIM_MAX_STEP 0.0015

static double sim_elapsed(sim_hal_t *hal)
{
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    double wall =
        (double)(now.tv_sec - hal->start.tv_sec) + (double)(now.tv_nsec - hal->start.tv_nsec) / 1e9;
    double step = wall - hal->wall_read;
    hal->board += step < SIM_MAX_STEP ? step : SIM_MAX_STEP;
    hal->wall_read = wall;
    return hal->board;
}

static void sim_trace(sim_hal_t *hal, uint8_t pin, uint8_t mode, uint16_t value)
{
    if (pin >= PD_MAX_PINS || (hal->mode[pin] == mode && hal->value[pin] == value)) {
        return; /* only changes are traced */
    }
    hal->mode[pin] = mode;
    hal->value[pin] = value;
    if (hal->trace) {
        fprintf(hal->trace, "{\"t\": %.6f, \"pin\": %u, \"mode\": \"%s\", \"value\": %u}\n",
                sim_elapsed(hal), (unsigned)pin,
                mode == SIM_PIN_SERVO ? "servo" : mode == SIM_PIN_PWM ? "pwm" : "digital",
                (unsigned)value);
        fflush(hal->trace);
    }
}

/* Reboot: servo pulses stop and pins are released; each gets a line with 0. */
static void sim_release_all(sim_hal_t *hal)
{
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        if (hal->mode[pin] != SIM_PIN_UNUSED) {
            uint8_t mode = hal->mode[pin];
            hal->value[pin] = UINT16_MAX; /* force a line even if it was already 0 */
            sim_trace(hal, pin, mode, 0);
            hal->mode[pin] = SIM_PIN_UNUSED;
            hal->value[pin] = 0;
        }
    }
}

/* --- the control socket ------------------------------------------------ */

/* Why a pin takes no analog value: the board's analog inputs, from its table. */
static const char *sim_not_analog(const pd_board_info_t *info)
{
    static char why[80]; /* up to 65 B with three 11-character ints (gcc -O2 checks it) */
    int first = -1, last = -1;
    for (int pin = 0; pin < info->num_pins && pin < PD_MAX_PINS; pin++) {
        if (pd_pinset_has(&info->analog_pins, (uint8_t)pin)) {
            first = first < 0 ? pin : first;
            last = pin;
        }
    }
    snprintf(why, sizeof(why), "analog inputs are pins %d..%d (A0..A%d)", first, last,
             last - first);
    return why;
}

/* The pin's level at board time `now`: a pulse goes to the opposite of the
 * level before the train for the first half of each period. */
static uint8_t sim_input_level(const sim_input_t *in, double now)
{
    if (in->pulses && now >= in->start) {
        double halves = (now - in->start) * 2.0 * (double)in->hz;
        if (halves < 2.0 * (double)in->pulses) {
            return (uint8_t)(in->level ^ (((uint64_t)halves & 1u) ? 0u : 1u));
        }
    }
    return in->level;
}

/* Edges of the counter's kind the current train made by board time `now`. The
 * first edge of a train leaves the level before it; edges come every half period. */
static uint32_t sim_train_edges(const sim_input_t *in, double now)
{
    if (!in->pulses || now < in->start) {
        return 0;
    }
    double halves = (now - in->start) * 2.0 * (double)in->hz;
    uint64_t all = (uint64_t)halves + 1u;
    if (all > 2u * (uint64_t)in->pulses) {
        all = 2u * (uint64_t)in->pulses;
    }
    uint64_t first_kind = (in->level == 0) ? (all + 1u) / 2u : all / 2u; /* rising edges */
    switch (in->edge) {
    case protoduino_Edge_EDGE_RISING:
        return (uint32_t)first_kind;
    case protoduino_Edge_EDGE_FALLING:
        return (uint32_t)(all - first_kind);
    default:
        return (uint32_t)all;
    }
}

static uint32_t sim_count(const sim_input_t *in, double now)
{
    return in->counted + sim_train_edges(in, now) - in->start_edges;
}

static const char *sim_control_apply(void *ctx, const pd_control_cmd_t *cmd, double *t)
{
    sim_hal_t *hal = ctx;
    if (cmd->pin >= hal->info->num_pins) {
        return "no such pin on this board";
    }
    if (pd_pinset_has(&hal->info->reserved_pins, cmd->pin)) {
        return "pins 0 and 1 carry the serial link";
    }
    sim_input_t *in = &hal->input[cmd->pin];
    double now = sim_elapsed(hal);
    if (in->edge >= 0 && cmd->kind != PD_CONTROL_ANALOG) {
        /* What the train made so far stays counted. */
        in->counted = sim_count(in, now);
        in->start_edges = 0;
    }
    switch (cmd->kind) {
    case PD_CONTROL_LEVEL: {
        hal->driven[cmd->pin] = true;
        uint8_t before = sim_input_level(in, now);
        in->pulses = 0; /* a level ends any train */
        in->level = (uint8_t)cmd->value;
        if (in->edge >= 0 && before != in->level &&
            (in->edge == protoduino_Edge_EDGE_BOTH ||
             (in->edge == protoduino_Edge_EDGE_RISING) == (in->level != 0))) {
            in->counted++;
        }
        break;
    }
    case PD_CONTROL_ANALOG:
        if (!pd_pinset_has(&hal->info->analog_pins, cmd->pin)) {
            return sim_not_analog(hal->info);
        }
        in->analog = (uint16_t)cmd->value;
        break;
    case PD_CONTROL_PULSES:
        hal->driven[cmd->pin] = true;
        in->level = sim_input_level(in, now); /* a new train starts from where the pin is */
        in->pulses = 0;
        in->pulses = cmd->pulses;
        in->hz = cmd->hz;
        in->start = now;
        break;
    }
    *t = now;
    return NULL;
}

/* --- the HAL ------------------------------------------------------------- */

uint16_t pd_hal_tx_room(void *ctx)
{
    sim_hal_t *hal = ctx;
    return (uint16_t)(SIM_TX_SIZE - hal->tx_len);
}

bool pd_hal_write(void *ctx, const uint8_t *data, uint16_t len)
{
    sim_hal_t *hal = ctx;
    if (len > SIM_TX_SIZE - hal->tx_len) {
        return false;
    }
    memcpy(hal->tx + hal->tx_len, data, len);
    hal->tx_len += len;
    return true;
}

/* Move what the pty takes now from the queue to it. */
static void sim_tx_flush(sim_hal_t *hal)
{
    if (hal->tx_len > 0 && !pd_line_carries(&hal->line, hal->master, hal->baud, true)) {
        hal->line.lost_out += hal->tx_len; /* sent at a rate the host or the line does not take */
        hal->tx_len = 0;
    }
    while (hal->tx_len > 0) {
        ssize_t n = write(hal->master, hal->tx, hal->tx_len);
        if (n < 0 && errno == EINTR) {
            continue;
        }
        if (n <= 0) {
            if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) {
                hal->tx_len = 0; /* the port is gone: what was queued is lost, as on a wire */
            }
            return;
        }
        memmove(hal->tx, hal->tx + n, hal->tx_len - (size_t)n);
        hal->tx_len -= (size_t)n;
    }
}

/* Any rate: a pty has none of its own (pd_linerate.h judges the bytes when asked to). */
uint8_t pd_hal_baud_rates(void *ctx)
{
    (void)ctx;
    return PD_RESET_ACK_BAUD_250K | PD_RESET_ACK_BAUD_500K | PD_RESET_ACK_BAUD_1M;
}

/* The bytes queued before go out at the old rate first, as pd_hal.h asks (the
 * pty's reader is the host: waited for 100 ms at most). */
void pd_hal_set_baud(void *ctx, uint32_t baud)
{
    sim_hal_t *hal = ctx;
    for (int i = 0; i < 100 && hal->tx_len > 0; i++) {
        sim_tx_flush(hal);
        if (hal->tx_len > 0) {
            struct pollfd p = {.fd = hal->master, .events = POLLOUT};
            poll(&p, 1, 1);
        }
    }
    hal->baud = baud;
}

uint32_t pd_hal_millis(void *ctx)
{
    return (uint32_t)(sim_elapsed(ctx) * 1000.0);
}

void pd_hal_servo_write(void *ctx, uint8_t channel, uint8_t pin, uint16_t us)
{
    (void)channel;
    sim_trace(ctx, pin, SIM_PIN_SERVO, us);
}

void pd_hal_servo_hold(void *ctx, bool hold)
{
    /* Virtual pins take their value the moment they are written: a held batch
     * is written within microseconds, at one trace time. */
    (void)ctx;
    (void)hold;
}

bool pd_hal_servo_pending(void *ctx)
{
    (void)ctx; /* taken at once */
    return false;
}

void pd_hal_digital_write(void *ctx, uint8_t pin, bool level)
{
    sim_trace(ctx, pin, SIM_PIN_DIGITAL, level ? 1u : 0u);
}

void pd_hal_pwm_write(void *ctx, uint8_t pin, uint8_t duty)
{
    sim_trace(ctx, pin, SIM_PIN_PWM, duty);
}

void pd_hal_pwm_release(void *ctx, uint8_t pin)
{
    sim_trace(ctx, pin, SIM_PIN_PWM, 0); /* an input reads as 0, as on the emulated Uno */
}

/* --- inputs: the control socket's virtual pins, on the board's clock ------ */

void pd_hal_input_config(void *ctx, uint8_t pin, bool pull_up)
{
    sim_hal_t *hal = ctx;
    /* An input with a pull-up and nothing driving it reads high, as on the Uno;
     * a level from the control socket always wins (it drives the pin). */
    if (pin < PD_MAX_PINS && pull_up && !hal->driven[pin]) {
        hal->input[pin].level = 1;
    }
}

void pd_hal_input_release(void *ctx, uint8_t pin)
{
    (void)ctx;
    (void)pin;
}

pd_pinset_t pd_hal_digital_read_all(void *ctx)
{
    sim_hal_t *hal = ctx;
    double now = sim_elapsed(hal);
    pd_pinset_t levels = {{0}};
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        pd_pinset_put(&levels, pin, sim_input_level(&hal->input[pin], now));
    }
    return levels;
}

void pd_hal_analog_start(void *ctx, uint8_t pin)
{
    sim_hal_t *hal = ctx;
    hal->adc_value = pin < PD_MAX_PINS ? hal->input[pin].analog : 0;
}

bool pd_hal_analog_done(void *ctx, uint16_t *counts)
{
    sim_hal_t *hal = ctx;
    *counts = hal->adc_value; /* a virtual converter is done at once */
    return true;
}

void pd_hal_counter_start(void *ctx, uint8_t pin, uint8_t edge)
{
    sim_hal_t *hal = ctx;
    if (pin < PD_MAX_PINS) {
        sim_input_t *in = &hal->input[pin];
        in->edge = (int8_t)edge;
        in->counted = 0;
        in->start_edges = 0;
        in->start_edges = sim_train_edges(in, sim_elapsed(hal)); /* a train under way counts from now */
    }
}

uint32_t pd_hal_counter_read(void *ctx, uint8_t pin)
{
    sim_hal_t *hal = ctx;
    return pin < PD_MAX_PINS ? sim_count(&hal->input[pin], sim_elapsed(hal)) : 0;
}

void pd_hal_counter_stop(void *ctx, uint8_t pin)
{
    sim_hal_t *hal = ctx;
    if (pin < PD_MAX_PINS) {
        hal->input[pin].edge = -1;
    }
}

void pd_hal_servo_detach(void *ctx, uint8_t channel, uint8_t pin)
{
    (void)channel;
    sim_trace(ctx, pin, SIM_PIN_SERVO, 0); /* no pulses: the emulated Uno's trace says 0 too */
}

void pd_hal_digital_release(void *ctx, uint8_t pin)
{
    sim_trace(ctx, pin, SIM_PIN_DIGITAL, 0); /* an input reads as 0 in the trace, as on the Uno */
}

/* Random at every boot (a simulated power-up): a reboot never repeats the last id. */
uint32_t pd_hal_boot_id(void *ctx)
{
    sim_hal_t *hal = ctx;
    uint32_t id = 0;
    FILE *f = fopen("/dev/urandom", "rb");
    if (f == NULL || fread(&id, sizeof(id), 1, f) != 1) {
        id = (uint32_t)time(NULL) ^ (uint32_t)getpid();
    }
    if (f != NULL) {
        fclose(f);
    }
    if (id == hal->last_boot_id) {
        id++;
    }
    hal->last_boot_id = id;
    return id;
}

void pd_hal_outputs_safe(void *ctx)
{
    /* Virtual pins take their value the moment they are written. */
    (void)ctx;
}

const pd_board_info_t *pd_hal_board_info(void *ctx)
{
    const sim_hal_t *hal = ctx;
    return hal->info;
}

/* --- the process --------------------------------------------------------- */

static void on_signal(int sig)
{
    if (sig == SIGUSR1) {
        sim_reboot = 1;
    } else {
        sim_stop = sig;
    }
}

static int usage(void)
{
    fprintf(stderr,
            "usage: pd_sim [--board uno|mega] [--trace FILE] [--link PATH] [--control PATH]\n"
            "              [--owner-fd FD] [--line-check] [--line-max BAUD] [--line-max-out BAUD]\n");
    return 2;
}

/* A raw pty whose slave stays open; returns the master fd or -1. */
static int open_pty(char *slave_name, size_t cap, int *slave_fd)
{
    int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0) {
        perror("pd_sim: posix_openpt");
        return -1;
    }
    const char *name = ptsname(master);
    if (!name || strlen(name) >= cap) {
        perror("pd_sim: ptsname");
        return -1;
    }
    strcpy(slave_name, name);
    *slave_fd = open(slave_name, O_RDWR | O_NOCTTY);
    if (*slave_fd < 0) {
        perror("pd_sim: open slave");
        return -1;
    }
    /* docs/protocol.md section 1: every byte value passes unchanged. */
    struct termios tio;
    if (tcgetattr(*slave_fd, &tio) != 0) {
        perror("pd_sim: tcgetattr");
        return -1;
    }
    cfmakeraw(&tio);
    cfsetispeed(&tio, B115200);
    cfsetospeed(&tio, B115200);
    if (tcsetattr(*slave_fd, TCSANOW, &tio) != 0) {
        perror("pd_sim: tcsetattr");
        return -1;
    }
    int flags = fcntl(master, F_GETFL);
    if (flags < 0 || fcntl(master, F_SETFL, flags | O_NONBLOCK) != 0) {
        perror("pd_sim: fcntl");
        return -1;
    }
    return master;
}

int main(int argc, char **argv)
{
    const char *trace_path = NULL;
    const char *link_path = NULL;
    const char *control_path = NULL;
    int owner_fd = -1;
    static pd_control_t control;
    static sim_hal_t hal;
    static pd_core_t core;
    char slave_name[128];
    int slave_fd = -1;
    static uint8_t rx[512];
    size_t rx_len = 0, rx_off = 0;

    clock_gettime(CLOCK_MONOTONIC, &hal.start);
    for (int pin = 0; pin < PD_MAX_PINS; pin++) {
        hal.input[pin].edge = -1; /* no counter */
    }
    hal.baud = PD_BAUD;
    hal.info = &sim_board;
    /* --board mega: the Mega build's own table (avr/pd_avr_mega.c), the one declaration of
     * its pins, with this board's link buffer. */
    static pd_board_info_t mega;
    for (int i = 1; i < argc; i++) {
        int line = pd_line_option(&hal.line, argc, argv, &i);
        if (line < 0) {
            return usage();
        }
        if (line > 0) {
            continue;
        }
        if (strcmp(argv[i], "--board") == 0 && i + 1 < argc) {
            const char *name = argv[++i];
            if (strcmp(name, "mega") == 0) {
                mega = pd_avr_mega_info;
                mega.rx_buffer = sim_board.rx_buffer;
                hal.info = &mega;
            } else if (strcmp(name, "uno") != 0) {
                return usage();
            }
        } else if (strcmp(argv[i], "--trace") == 0 && i + 1 < argc) {
            trace_path = argv[++i];
        } else if (strcmp(argv[i], "--link") == 0 && i + 1 < argc) {
            link_path = argv[++i];
        } else if (strcmp(argv[i], "--control") == 0 && i + 1 < argc) {
            control_path = argv[++i];
        } else if (strcmp(argv[i], "--owner-fd") == 0 && i + 1 < argc) {
            owner_fd = pd_owner_parse(argv[++i], "pd_sim");
            if (owner_fd < 0) {
                return 2;
            }
        } else {
            return usage();
        }
    }

    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_signal; /* no SA_RESTART: poll() returns at once */
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGUSR1, &sa, NULL);
    pd_owner_hangup(&sa);
    signal(SIGPIPE, SIG_IGN);

    if (trace_path) {
        hal.trace = fopen(trace_path, "w");
        if (!hal.trace) {
            perror("pd_sim: trace file");
            return 1;
        }
    }
    hal.master = open_pty(slave_name, sizeof(slave_name), &slave_fd);
    if (hal.master < 0) {
        return 1;
    }
    pd_control_init(&control);
    if (control_path && pd_control_open(&control, control_path, sim_control_apply, &hal) != 0) {
        return 1;
    }
    if (link_path) {
        struct stat st;
        if (lstat(link_path, &st) == 0 && S_ISLNK(st.st_mode)) {
            unlink(link_path); /* a stale link from a board that was killed */
        }
        if (symlink(slave_name, link_path) != 0) {
            perror("pd_sim: --link");
            return 1;
        }
    }
    /*
     * Boot (EVENT BOOT goes into the pty) before the port is announced: a host
     * can only open the port afterwards, and opening flushes its input, so no
     * client ever sees a stale BOOT from power-up racing its handshake. A
     * reboot (SIGUSR1) sends BOOT to whoever is connected.
     */
    sim_user_keep();
    pd_core_init(&core, &hal);
    printf("%s\n", link_path ? link_path : slave_name);
    fflush(stdout);
    /* An owned board ends with its owner (killed with no chance to stop us),
     * or boards pile up unseen; one started on purpose runs until stopped. */
    while (!sim_stop && !pd_owner_gone(owner_fd)) {
        if (sim_reboot) {
            sim_reboot = 0;
            sim_release_all(&hal);
            hal.tx_len = 0; /* a reset MCU forgets its transmit queue */
            for (int pin = 0; pin < PD_MAX_PINS; pin++) {
                hal.input[pin].edge = -1; /* its counters stop; the outside world's levels stay */
            }
            rx_len = rx_off = 0;
            hal.baud = PD_BAUD; /* a reset UART is at the opening rate */
            sim_user_reset();   /* and the service's statics are as at power-up */
            pd_core_init(&core, &hal);
        }
        /* Bytes the core left last time (their replies need transmit room) go first. */
        if (rx_off < rx_len) {
            rx_off += pd_core_rx(&core, rx + rx_off, rx_len - rx_off);
        }
        short events = (short)((rx_off == rx_len ? POLLIN : 0) | (hal.tx_len > 0 ? POLLOUT : 0));
        struct pollfd fds[1 + PD_CONTROL_MAX_CLIENTS + 1];
        fds[0] = (struct pollfd){.fd = hal.master, .events = events};
        int nfds = 1 + pd_control_pollfds(&control, fds + 1);
        int ready = poll(fds, (nfds_t)nfds, 1);
        struct pollfd p = fds[0];
        if (ready > 0 && nfds > 1) {
            pd_control_service(&control);
        }
        if (ready > 0 && (p.revents & POLLOUT)) {
            sim_tx_flush(&hal);
        }
        if (ready > 0 && (p.revents & POLLIN)) {
            ssize_t n = read(hal.master, rx, sizeof(rx));
            if (n > 0 && !pd_line_carries(&hal.line, hal.master, hal.baud, false)) {
                hal.line.lost_in += (uint64_t)n; /* sent at a rate we are not at */
            } else if (n > 0) {
                rx_len = (size_t)n;
                rx_off = pd_core_rx(&core, rx, rx_len);
            }
        } else if (ready > 0 && (p.revents & (POLLHUP | POLLERR | POLLNVAL))) {
            /* POLLHUP/POLLERR should not happen with our slave open; never spin. */
            struct timespec ms = {0, 1000000};
            nanosleep(&ms, NULL);
        }
        /* The replies this pass queued go out before the core's poll, as the Uno's
         * ring drains while its loop runs: a report waits for an empty queue
         * (pd_link_send_spare), and with a command every pass it would wait for good. */
        sim_tx_flush(&hal);
        pd_core_poll(&core);
        sim_tx_flush(&hal); /* what this pass queued goes out now, not after the next poll() */
    }

    pd_control_close(&control);
    if (link_path) {
        unlink(link_path);
    }
    if (hal.trace) {
        fclose(hal.trace);
    }
    close(slave_fd);
    close(hal.master);
    return sim_stop == SIGINT ? 128 + SIGINT : 0;
}

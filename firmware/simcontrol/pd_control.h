/*
 * pd_control.h: the input-control socket shared by both simulated boards
 * (firmware/posix/pd_sim.c and tools/avrsim/avrsim.c), so that a test drives
 * a button, a potentiometer or an encoder the same way on either board.
 *
 * A Unix stream socket at PATH takes one JSON object per line:
 *   {"pin": 2, "level": 0}                  drive a digital input
 *   {"pin": 14, "analog": 512}              set an analog input (0..1023 counts)
 *   {"pin": 3, "pulses": 100, "hz": 2000}   that many pulses at that rate
 * and answers each line with one line:
 *   {"ok": true, "t": SECONDS}              applied at board time t (the trace's clock)
 *   {"ok": false, "error": "MESSAGE"}       refused; nothing changed
 * This module only owns the socket and the syntax (jansson parses the JSON);
 * what a command means is the board's callback, which applies it at once.
 * It never blocks: the board's loop polls the descriptors and calls
 * pd_control_service() when one is ready.
 */
#ifndef PD_CONTROL_H
#define PD_CONTROL_H

#include <poll.h>
#include <stddef.h>
#include <stdint.h>

#define PD_CONTROL_MAX_CLIENTS 4
#define PD_CONTROL_LINE_MAX 512
/* Bounds checked here, the same on both boards. */
#define PD_CONTROL_ANALOG_MAX 1023
#define PD_CONTROL_PULSES_MAX 1000000L
#define PD_CONTROL_HZ_MAX 100000L

typedef enum {
    PD_CONTROL_LEVEL = 0,
    PD_CONTROL_ANALOG,
    PD_CONTROL_PULSES,
} pd_control_kind_t;

typedef struct {
    int pin;
    pd_control_kind_t kind;
    int value;       /* the level (0/1) or the analog counts */
    uint32_t pulses; /* PD_CONTROL_PULSES */
    uint32_t hz;     /* PD_CONTROL_PULSES */
} pd_control_cmd_t;

/* Apply one command now. Returns NULL when applied (with *t = the board time,
 * in the trace's seconds) or a message saying why it was refused. */
typedef const char *(*pd_control_apply_fn)(void *ctx, const pd_control_cmd_t *cmd, double *t);

typedef struct {
    int fd; /* -1: not connected */
    size_t len;
    int overflow; /* the current line is too long: drop it up to its newline */
    char line[PD_CONTROL_LINE_MAX];
} pd_control_client_t;

typedef struct {
    int listen_fd; /* -1: control disabled */
    char path[108];
    pd_control_client_t client[PD_CONTROL_MAX_CLIENTS];
    pd_control_apply_fn apply;
    void *ctx;
} pd_control_t;

/* Disabled state (pd_control_pollfds adds nothing, close does nothing). */
void pd_control_init(pd_control_t *c);

/* Listen at `path` (a stale socket file there is replaced). 0, or -1 with a
 * message on stderr. */
int pd_control_open(pd_control_t *c, const char *path, pd_control_apply_fn apply, void *ctx);

/* Adds the descriptors to watch for POLLIN to fds (room for at least
 * PD_CONTROL_MAX_CLIENTS + 1); returns how many were added. */
int pd_control_pollfds(const pd_control_t *c, struct pollfd *fds);

/* Accepts, reads and answers whatever is ready, without blocking. */
void pd_control_service(pd_control_t *c);

/* Closes every socket and removes the socket file. */
void pd_control_close(pd_control_t *c);

/* Parses one line (exposed for the tests of the syntax). NULL when valid. */
const char *pd_control_parse(const char *line, size_t len, pd_control_cmd_t *cmd);

#endif

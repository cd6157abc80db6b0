/*
 * The line rate on a simulated board's pseudo-terminal (docs/protocol.md 5,
 * *Line rate*), for the native and the emulated board alike. A pty carries
 * bytes whatever rate either end set, so a board that is asked to (--line-check,
 * --line-max, --line-max-out) judges each byte as a wire would: it arrives only
 * if the host's rate (the termios the host set on the slave, read from the
 * master) is the device's within 3 % (a UART's tolerance; the Uno's 115200 is
 * 2.1 % fast) and the line carries that rate (at most --line-max in both
 * directions, --line-max-out from the device to the host: a device whose
 * answers are lost). What fails is lost, as a UART's framing errors are to the
 * packet layer above. Header only: both boards include it.
 */
#ifndef PD_LINERATE_H
#define PD_LINERATE_H

#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>

typedef struct pd_line {
    bool check;        /* judge bytes at all (any of the options given) */
    uint32_t max;      /* the highest rate the line carries both ways (0: any) */
    uint32_t max_out;  /* the highest it carries from the device to the host (0: any) */
    uint64_t lost_in;  /* bytes from the host lost */
    uint64_t lost_out; /* bytes to the host lost */
} pd_line_t;

/* Linux's struct termios2 (asm-generic), by another name: glibc's <termios.h> and
 * <asm/termbits.h> cannot both be included. Its size is part of the ioctl number. */
struct pd_termios2 {
    unsigned int c_iflag, c_oflag, c_cflag, c_lflag;
    unsigned char c_line;
    unsigned char c_cc[19];
    unsigned int c_ispeed, c_ospeed;
};

/* The rate the host set on the pty (TCGETS2 on the master reads the slave's), 0 if unknown. */
static inline uint32_t pd_line_host_baud(int master)
{
    struct pd_termios2 t;
    if (ioctl(master, _IOR('T', 0x2A, struct pd_termios2), &t) != 0) {
        return 0;
    }
    return t.c_ospeed;
}

/* Whether the device's rate is above a line's limit (0: none), with a UART's 3 %: a line
 * that carries 115200 carries the Uno's 115200 (117647, 2.1 % fast) too. */
static inline bool pd_line_above(uint32_t device, uint32_t max)
{
    return max != 0 && (uint64_t)device * 100u > (uint64_t)max * 103u;
}

/* Whether a byte crosses the line now; `out`: from the device to the host. */
static inline bool pd_line_carries(const pd_line_t *line, int master, uint32_t device, bool out)
{
    if (!line->check) {
        return true;
    }
    uint32_t host = pd_line_host_baud(master);
    uint32_t diff = host > device ? host - device : device - host;
    if ((uint64_t)diff * 100u > (uint64_t)device * 3u) {
        return false;
    }
    if (pd_line_above(device, line->max)) {
        return false;
    }
    return !(out && pd_line_above(device, line->max_out));
}

/* Parse the line options; returns 1 if argv[*i] was one (and consumed its value), 0 if not,
 * -1 for a bad value. */
static inline int pd_line_option(pd_line_t *line, int argc, char **argv, int *i)
{
    const char *opt = argv[*i];
    if (strcmp(opt, "--line-check") == 0) {
        line->check = true;
        return 1;
    }
    uint32_t *into = NULL;
    if (strcmp(opt, "--line-max") == 0) {
        into = &line->max;
    } else if (strcmp(opt, "--line-max-out") == 0) {
        into = &line->max_out;
    } else {
        return 0;
    }
    if (*i + 1 >= argc) {
        return -1;
    }
    char *end = NULL;
    unsigned long v = strtoul(argv[++*i], &end, 10);
    if (end == NULL || *end != '\0' || v == 0 || v > 10000000UL) {
        return -1;
    }
    *into = (uint32_t)v;
    line->check = true;
    return 1;
}

#endif /* PD_LINERATE_H */

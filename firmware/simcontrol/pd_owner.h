/*
 * pd_owner.h: how a simulated board knows that the process owning it is gone,
 * shared by both boards (firmware/posix/pd_sim.c, tools/avrsim/avrsim.c).
 *
 * One rule (docs/api.md, "Simulated boards"): a board started with
 * --owner-fd FD is OWNED: FD is the read end of a pipe whose write end only
 * the owner holds (protoduino.simboard passes its stdin). When the owner
 * exits, however it dies (SIGKILL included), the kernel closes the write end,
 * the board reads end-of-file and stops as on SIGTERM. A pipe rather than the
 * parent's pid: getppid() changes meaning when the parent is gone before the
 * board first asks (a board started from a subshell that exited at once kept
 * running for good), and a pid can be reused. A board started without
 * --owner-fd was started on purpose (protoduino sim) and runs until it is
 * stopped: SIGINT, SIGTERM, or SIGHUP unless that was ignored (nohup).
 */
#ifndef PD_OWNER_H
#define PD_OWNER_H

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

/* --owner-fd's value, or -1 (and a message) if it is no open descriptor. */
static inline int pd_owner_parse(const char *text, const char *program)
{
    char *end = NULL;
    long fd = strtol(text, &end, 10);
    if (!end || *end != '\0' || fd < 0 || fd > 1023 || fcntl((int)fd, F_GETFD) < 0) {
        fprintf(stderr, "%s: --owner-fd takes an open file descriptor, not '%s'\n", program,
                text);
        return -1;
    }
    return (int)fd;
}

/* Whether the owner is gone: its pipe reads end-of-file (or fails). Never blocks;
 * bytes the owner writes are read and ignored. fd -1 (no owner): never. */
static inline int pd_owner_gone(int fd)
{
    if (fd < 0) {
        return 0;
    }
    struct pollfd p = {.fd = fd, .events = POLLIN};
    if (poll(&p, 1, 0) <= 0) {
        return 0;
    }
    char buf[64];
    ssize_t n = read(fd, buf, sizeof buf);
    return n == 0 || (n < 0 && errno != EAGAIN && errno != EINTR);
}

/* SIGHUP (the terminal closed) stops the board like SIGTERM, unless it was
 * ignored when the board started (nohup): then it stays ignored. */
static inline void pd_owner_hangup(const struct sigaction *stop)
{
    struct sigaction old;
    if (sigaction(SIGHUP, NULL, &old) == 0 && old.sa_handler != SIG_IGN) {
        sigaction(SIGHUP, stop, NULL);
    }
}

#endif

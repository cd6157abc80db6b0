/*
 * pd_control.c: the input-control socket of the simulated boards (see
 * pd_control.h for the protocol). Single-threaded: the board's own loop calls
 * in, so a command is applied between two steps of the board and never races
 * the firmware.
 */
#define _DEFAULT_SOURCE /* lstat, S_ISSOCK, SOCK_CLOEXEC */

#include "pd_control.h"

#include <errno.h>
#include <fcntl.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

static char pd_control_msg[256]; /* the last parse error (single-threaded) */

void pd_control_init(pd_control_t *c)
{
    memset(c, 0, sizeof *c);
    c->listen_fd = -1;
    for (int i = 0; i < PD_CONTROL_MAX_CLIENTS; i++) {
        c->client[i].fd = -1;
    }
}

static int pd_control_nonblock(int fd)
{
    int flags = fcntl(fd, F_GETFL);
    return flags < 0 ? -1 : fcntl(fd, F_SETFL, flags | O_NONBLOCK);
}

int pd_control_open(pd_control_t *c, const char *path, pd_control_apply_fn apply, void *ctx)
{
    struct sockaddr_un addr;
    memset(&addr, 0, sizeof addr);
    addr.sun_family = AF_UNIX;
    if (strlen(path) >= sizeof addr.sun_path) {
        fprintf(stderr, "control socket path too long (at most %zu bytes): %s\n",
                sizeof addr.sun_path - 1, path);
        return -1;
    }
    strcpy(addr.sun_path, path);
    struct stat st;
    if (lstat(path, &st) == 0 && S_ISSOCK(st.st_mode)) {
        unlink(path); /* left behind by a board that was killed */
    }
    int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) {
        perror("control socket");
        return -1;
    }
    if (bind(fd, (struct sockaddr *)&addr, sizeof addr) != 0 || listen(fd, 4) != 0 ||
        pd_control_nonblock(fd) != 0) {
        fprintf(stderr, "control socket %s: %s\n", path, strerror(errno));
        close(fd);
        return -1;
    }
    c->listen_fd = fd;
    strcpy(c->path, path);
    c->apply = apply;
    c->ctx = ctx;
    return 0;
}

int pd_control_pollfds(const pd_control_t *c, struct pollfd *fds)
{
    int n = 0;
    if (c->listen_fd < 0) {
        return 0;
    }
    fds[n++] = (struct pollfd){.fd = c->listen_fd, .events = POLLIN};
    for (int i = 0; i < PD_CONTROL_MAX_CLIENTS; i++) {
        if (c->client[i].fd >= 0) {
            fds[n++] = (struct pollfd){.fd = c->client[i].fd, .events = POLLIN};
        }
    }
    return n;
}

/* "<prefix><arg><suffix>": no format string from a variable. */
static const char *pd_control_fail(const char *prefix, const char *arg, const char *suffix)
{
    snprintf(pd_control_msg, sizeof pd_control_msg, "%s%s%s", prefix, arg, suffix);
    return pd_control_msg;
}

/* An integer member in [lo, hi]; NULL when valid. */
static const char *pd_control_int(json_t *obj, const char *key, long lo, long hi, long *out)
{
    json_t *v = json_object_get(obj, key);
    if (!json_is_integer(v)) {
        return pd_control_fail("\"", key, "\" must be an integer");
    }
    json_int_t x = json_integer_value(v);
    if (x < lo || x > hi) {
        snprintf(pd_control_msg, sizeof pd_control_msg, "\"%s\" must be %ld..%ld, not %lld", key,
                 lo, hi, (long long)x);
        return pd_control_msg;
    }
    *out = (long)x;
    return NULL;
}

static const char *pd_control_parse_obj(json_t *root, pd_control_cmd_t *cmd)
{
    static const char *const known[] = {"pin", "level", "analog", "pulses", "hz"};
    const char *key;
    json_t *value;
    json_object_foreach(root, key, value) {
        (void)value;
        size_t k = 0;
        while (k < sizeof known / sizeof known[0] && strcmp(key, known[k]) != 0) {
            k++;
        }
        if (k == sizeof known / sizeof known[0]) {
            return pd_control_fail("unknown key \"", key,
                                   "\" (keys: pin, level, analog, pulses, hz)");
        }
    }
    long x = 0;
    const char *err = pd_control_int(root, "pin", 0, 255, &x);
    if (err) {
        return err;
    }
    memset(cmd, 0, sizeof *cmd);
    cmd->pin = (int)x;
    int kinds = (json_object_get(root, "level") != NULL) +
                (json_object_get(root, "analog") != NULL) +
                (json_object_get(root, "pulses") != NULL);
    if (kinds != 1) {
        return "give exactly one of \"level\", \"analog\", \"pulses\"";
    }
    if (json_object_get(root, "hz") && !json_object_get(root, "pulses")) {
        return "\"hz\" goes with \"pulses\"";
    }
    if (json_object_get(root, "level")) {
        cmd->kind = PD_CONTROL_LEVEL;
        err = pd_control_int(root, "level", 0, 1, &x);
        cmd->value = (int)x;
    } else if (json_object_get(root, "analog")) {
        cmd->kind = PD_CONTROL_ANALOG;
        err = pd_control_int(root, "analog", 0, PD_CONTROL_ANALOG_MAX, &x);
        cmd->value = (int)x;
    } else {
        cmd->kind = PD_CONTROL_PULSES;
        err = pd_control_int(root, "pulses", 1, PD_CONTROL_PULSES_MAX, &x);
        cmd->pulses = (uint32_t)x;
        if (!err) {
            if (!json_object_get(root, "hz")) {
                return "\"pulses\" needs \"hz\" (pulses per second)";
            }
            err = pd_control_int(root, "hz", 1, PD_CONTROL_HZ_MAX, &x);
            cmd->hz = (uint32_t)x;
        }
    }
    return err;
}

const char *pd_control_parse(const char *line, size_t len, pd_control_cmd_t *cmd)
{
    json_error_t jerr;
    json_t *root = json_loadb(line, len, JSON_REJECT_DUPLICATES, &jerr);
    if (!root) {
        return pd_control_fail("not JSON: ", jerr.text, "");
    }
    const char *err = json_is_object(root) ? pd_control_parse_obj(root, cmd)
                                           : "expected one JSON object per line";
    json_decref(root);
    return err;
}

static void pd_control_drop(pd_control_client_t *cl)
{
    close(cl->fd);
    cl->fd = -1;
    cl->len = 0;
    cl->overflow = 0;
}

/* Replies are short; a client that does not read them is dropped rather
 * than allowed to stall the board. */
static void pd_control_reply(pd_control_client_t *cl, const char *err, double t)
{
    char out[PD_CONTROL_LINE_MAX];
    int n;
    if (err) {
        json_t *msg = json_string(err);
        char *quoted = msg ? json_dumps(msg, JSON_ENCODE_ANY) : NULL;
        n = snprintf(out, sizeof out, "{\"ok\": false, \"error\": %s}\n",
                     quoted ? quoted : "\"error\"");
        free(quoted);
        json_decref(msg);
    } else {
        n = snprintf(out, sizeof out, "{\"ok\": true, \"t\": %.6f}\n", t);
    }
    if (n < 0 || (size_t)n >= sizeof out) {
        n = snprintf(out, sizeof out, "{\"ok\": false, \"error\": \"reply too long\"}\n");
    }
    if (send(cl->fd, out, (size_t)n, MSG_NOSIGNAL) != n) {
        pd_control_drop(cl);
    }
}

static void pd_control_line(pd_control_t *c, pd_control_client_t *cl, const char *line,
                            size_t len)
{
    while (len && (line[len - 1] == '\r' || line[len - 1] == ' ')) {
        len--;
    }
    if (!len) {
        return; /* blank lines are allowed */
    }
    pd_control_cmd_t cmd;
    double t = 0.0;
    const char *err = pd_control_parse(line, len, &cmd);
    if (!err) {
        err = c->apply(c->ctx, &cmd, &t);
    }
    pd_control_reply(cl, err, t);
}

static void pd_control_read(pd_control_t *c, pd_control_client_t *cl)
{
    char buf[256];
    ssize_t n = recv(cl->fd, buf, sizeof buf, 0);
    if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
        pd_control_drop(cl);
        return;
    }
    for (ssize_t i = 0; i < n && cl->fd >= 0; i++) {
        if (buf[i] == '\n') {
            if (cl->overflow) {
                cl->overflow = 0;
                pd_control_reply(cl, "line too long", 0.0);
            } else {
                pd_control_line(c, cl, cl->line, cl->len);
            }
            cl->len = 0;
        } else if (cl->len < sizeof cl->line) {
            cl->line[cl->len++] = buf[i];
        } else {
            cl->overflow = 1;
        }
    }
}

void pd_control_service(pd_control_t *c)
{
    if (c->listen_fd < 0) {
        return;
    }
    for (;;) {
        int fd = accept(c->listen_fd, NULL, NULL);
        if (fd < 0) {
            break;
        }
        int slot = 0;
        while (slot < PD_CONTROL_MAX_CLIENTS && c->client[slot].fd >= 0) {
            slot++;
        }
        if (slot == PD_CONTROL_MAX_CLIENTS || pd_control_nonblock(fd) != 0) {
            static const char busy[] = "{\"ok\": false, \"error\": \"too many clients\"}\n";
            (void)!send(fd, busy, sizeof busy - 1, MSG_NOSIGNAL);
            close(fd);
            continue;
        }
        c->client[slot].fd = fd;
        c->client[slot].len = 0;
        c->client[slot].overflow = 0;
    }
    for (int i = 0; i < PD_CONTROL_MAX_CLIENTS; i++) {
        if (c->client[i].fd >= 0) {
            struct pollfd p = {.fd = c->client[i].fd, .events = POLLIN};
            if (poll(&p, 1, 0) > 0) {
                pd_control_read(c, &c->client[i]);
            }
        }
    }
}

void pd_control_close(pd_control_t *c)
{
    for (int i = 0; i < PD_CONTROL_MAX_CLIENTS; i++) {
        if (c->client[i].fd >= 0) {
            pd_control_drop(&c->client[i]);
        }
    }
    if (c->listen_fd >= 0) {
        close(c->listen_fd);
        c->listen_fd = -1;
        unlink(c->path);
    }
}

#include "pd_dedupe.h"

#include <string.h>

#include "protoduino.pb.h"

/* (to - from) mod PD_MAX_MESSAGE_ID, both 1..PD_MAX_MESSAGE_ID: how far `to` is ahead of `from`. */
static uint8_t ahead(uint8_t from, uint8_t to)
{
    uint8_t d = (uint8_t)(to - from); /* both below 128: no 8-bit wrap beyond one period */
    return (to >= from) ? d : (uint8_t)(d + PD_MAX_MESSAGE_ID);
}

/* Without GCC's induction-variable pass, which turned the count down back into a pointer
 * compare (2 more cycles a slot on the Uno); clang, the fuzzers' compiler, has no such
 * attribute. */
#if defined(__GNUC__) && !defined(__clang__)
#define PD_COUNT_DOWN __attribute__((optimize("no-ivopts")))
#else
#define PD_COUNT_DOWN
#endif

/*
 * Drop the entries that fell DEDUPE_WINDOW or more behind N. It runs on every command
 * that moves N, so on the Uno each of its 16 steps counts: ahead(Y, N) is (N - Y) mod
 * 256 when Y <= N and that plus 127 (mod 256) when Y > N, so an entry is out of reach
 * when both are DEDUPE_WINDOW or more, which needs no compare of Y with N; and a free
 * slot (0) may be "dropped" again, which needs no test for it. About 11 cycles a slot
 * where the index loop over ahead() took 17 (~110 a command).
 */
PD_COUNT_DOWN static void forget_old(pd_dedupe_t *dd)
{
    uint8_t newest = dd->newest;
    uint8_t *slot = dd->id;
    uint8_t n = PD_DEDUPE_WINDOW;
    do {
        uint8_t back = (uint8_t)(newest - *slot);
        if (back >= PD_DEDUPE_WINDOW && (uint8_t)(back + PD_MAX_MESSAGE_ID) >= PD_DEDUPE_WINDOW) {
            *slot = 0;
        }
        slot++;
    } while (--n != 0);
}

void pd_dedupe_init(pd_dedupe_t *dd)
{
    memset(dd, 0, sizeof(*dd));
    dd->newest = PD_MAX_MESSAGE_ID; /* the id before 1 */
}

void pd_dedupe_sync(pd_dedupe_t *dd, uint8_t next_id, bool clear)
{
    if (clear) {
        memset(dd->id, 0, sizeof(dd->id));
    }
    dd->newest = (next_id > 1u) ? (uint8_t)(next_id - 1u) : (uint8_t)PD_MAX_MESSAGE_ID;
    forget_old(dd);
}

int pd_dedupe_lookup(const pd_dedupe_t *dd, uint8_t id)
{
    if (ahead(id, dd->newest) < PD_DEDUPE_WINDOW) {
        for (uint8_t i = 0; i < PD_DEDUPE_WINDOW; i++) {
            if (dd->id[i] == id) {
                uint8_t pair = dd->status[i >> 1];
                return (i & 1u) ? pair >> 4 : pair & 0x0Fu;
            }
        }
    }
    return -1;
}

typedef char pd_assert_window_pow2[(PD_DEDUPE_WINDOW & (PD_DEDUPE_WINDOW - 1u)) == 0 ? 1 : -1];

/*
 * Record an executed command, in the slot of a stale entry of the same id (a
 * repeat never gets here), else the first free one from `next` on, else `next`
 * (the oldest entry). At most 16 ids are within reach of N, and the one
 * recorded is one of them, so while the window is full none of them is ever
 * overwritten: one of the 16 has fallen out of reach and was dropped.
 *
 * `moved`: N just moved to `id`. Then no entry holds `id`, and the search for
 * one is skipped (the scan of all 16 slots was ~330 cycles of every command on
 * the Uno; the first free slot is nearly always `next` itself). Why: every
 * entry is `id` Y with ahead(N, Y) 0 or 64..126 (within reach, 112..126 or 0,
 * after each move and sync, which drop the rest; an entry added while N stays
 * is not newer: 0 or 64..126), and an id that moves N is 1..63 ahead of it.
 * tests/c/test_dedupe_mirror.py holds this to the full search (the host's
 * mirror, protoduino.testing.DedupeWindow) over random ids at every edge of the rule.
 */
static void add(pd_dedupe_t *dd, uint8_t id, uint8_t status, bool moved)
{
    typedef char fits[(_protoduino_Status_MAX < 16) ? 1 : -1];
    (void)sizeof(fits);
    uint8_t slot = PD_DEDUPE_WINDOW;
    if (!moved) {
        for (uint8_t i = 0; i < PD_DEDUPE_WINDOW; i++) {
            if (dd->id[i] == id) {
                slot = i;
                break;
            }
        }
    }
    if (slot == PD_DEDUPE_WINDOW) {
        slot = dd->next;
        for (uint8_t k = 0; k < PD_DEDUPE_WINDOW; k++) {
            uint8_t i = (uint8_t)((dd->next + k) & (PD_DEDUPE_WINDOW - 1u));
            if (dd->id[i] == 0) {
                slot = i;
                break;
            }
        }
    }
    dd->id[slot] = id;
    uint8_t *pair = &dd->status[slot >> 1];
    *pair = (slot & 1u) ? (uint8_t)((*pair & 0x0Fu) | (status << 4))
                        : (uint8_t)((*pair & 0xF0u) | (status & 0x0Fu));
    dd->next = (uint8_t)((slot + 1u) & (PD_DEDUPE_WINDOW - 1u));
}

void pd_dedupe_done(pd_dedupe_t *dd, uint8_t id, int status)
{
    uint8_t d = ahead(dd->newest, id);
    bool moved = d >= 1u && d <= PD_ID_AHEAD_MAX;
    if (moved) {
        dd->newest = id;
        forget_old(dd);
    }
    if (status >= 0) {
        add(dd, id, (uint8_t)status, moved);
    }
}

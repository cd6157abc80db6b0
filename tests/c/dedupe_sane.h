/*
 * The dedupe window's invariants, for the fuzz targets (fuzz_rx.c, fuzz_dispatch.c): checked
 * after every input, whatever bytes came.
 */
#ifndef PD_TEST_DEDUPE_SANE_H
#define PD_TEST_DEDUPE_SANE_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_dedupe.h"

/* The window's bounds: a slot to write next, N an id, every entry an id, none twice. */
static inline bool dedupe_sane(const pd_dedupe_t *dd)
{
    if (dd->next >= PD_DEDUPE_WINDOW || dd->newest == 0 || dd->newest > PD_MAX_MESSAGE_ID) {
        return false;
    }
    for (uint8_t i = 0; i < PD_DEDUPE_WINDOW; i++) {
        if (dd->id[i] > PD_MAX_MESSAGE_ID) {
            return false;
        }
        for (uint8_t j = (uint8_t)(i + 1u); j < PD_DEDUPE_WINDOW; j++) {
            if (dd->id[i] != 0 && dd->id[i] == dd->id[j]) {
                return false;
            }
        }
    }
    return true;
}

#endif /* PD_TEST_DEDUPE_SANE_H */

/* What the probe service's handlers record, for tests/c/test_user.c. */
#ifndef PROBE_H
#define PROBE_H

#include "probe_service.h"

typedef struct probe_record {
    uint32_t echoes;        /* Echo handler runs */
    uint32_t peeks;         /* Peek handler runs */
    uint32_t safe_pins;     /* bit N: the safe hook ran for pin N */
    uint32_t released_pins; /* bit N: the release hook ran for pin N */
    uint32_t level;         /* the Level report's value; 0: nothing to send */
    uint32_t polled_at;     /* now_ms of the last poll hook */
    uint32_t overfills;     /* Overfill handler runs */
    pb_size_t report_blob;  /* the Level report's blob.size, however large (0: none) */
} probe_record_t;

extern probe_record_t probe_record;

#endif /* PROBE_H */

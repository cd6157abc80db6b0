#include "pd_dedupe.h"

#include <string.h>

#include "protoduino.pb.h"

void pd_dedupe_init(pd_dedupe_t *dd)
{
    memset(dd, 0, sizeof(*dd));
}

int pd_dedupe_find(const pd_dedupe_t *dd, uint32_t id)
{
    /* Every new command scans the whole window and finds nothing: one byte
     * of each id first (ids count up, so their first bytes in memory, the low
     * ones on the Uno, tell them apart; on any byte order it is only a filter,
     * the whole compare decides), the rest only on a match. A 32-bit compare
     * per entry was 380 of the Uno's cycles between a command's delimiter and
     * its Ack. */
    const uint8_t first = *(const uint8_t *)&id;
    for (uint8_t i = 0; i < dd->count; i++) {
        if (*(const uint8_t *)&dd->id[i] == first && dd->id[i] == id) {
            uint8_t pair = dd->status[i >> 1];
            return (i & 1u) ? pair >> 4 : pair & 0x0Fu;
        }
    }
    return -1;
}

void pd_dedupe_add(pd_dedupe_t *dd, uint32_t id, uint8_t status)
{
    typedef char fits[(_protoduino_Status_MAX < 16) ? 1 : -1];
    (void)sizeof(fits);
    dd->id[dd->next] = id;
    uint8_t *pair = &dd->status[dd->next >> 1];
    *pair = (dd->next & 1u) ? (uint8_t)((*pair & 0x0Fu) | (status << 4))
                            : (uint8_t)((*pair & 0xF0u) | (status & 0x0Fu));
    dd->next = (uint8_t)((dd->next + 1u) % PD_DEDUPE_WINDOW);
    if (dd->count < PD_DEDUPE_WINDOW) {
        dd->count++;
    }
}

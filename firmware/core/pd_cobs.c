#include "pd_cobs.h"

#include <stdbool.h>

size_t pd_cobs_encode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap)
{
    size_t out = 1;         /* next free byte of dst */
    size_t code_at = 0;     /* where the current block's code byte goes */
    uint8_t code = 1;       /* 1 + bytes in the current block */
    bool after_full = false; /* nothing since the last full (0xFF) block */

    if (cap == 0) {
        return 0;
    }
    for (size_t i = 0; i < len; i++) {
        after_full = false;
        if (src[i] != 0) {
            if (out >= cap) {
                return 0;
            }
            dst[out++] = src[i];
            code++;
        }
        if (src[i] == 0 || code == 0xFF) {
            /* Close the block; a full one (254 bytes) implies no zero. */
            after_full = (src[i] != 0);
            if (code_at >= cap) {
                return 0;
            }
            dst[code_at] = code;
            code_at = out++;
            code = 1;
        }
    }
    /*
     * Like the reference encoder (and the host's `cobs` package), a frame
     * ending on a full block gets no empty trailing block: both decode alike,
     * and the shared vectors pin this shorter form.
     */
    if (after_full) {
        return code_at;
    }
    if (code_at >= cap) {
        return 0;
    }
    dst[code_at] = code;
    return out;
}

int pd_cobs_decode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap)
{
    size_t in = 0;
    size_t out = 0;

    while (in < len) {
        uint8_t code = src[in++];
        if (code == 0) {
            return -1;
        }
        for (uint8_t k = 1; k < code; k++) {
            if (in >= len || src[in] == 0 || out >= cap) {
                return -1;
            }
            dst[out++] = src[in++];
        }
        /* Every block but a full one (0xFF) and the last implies a zero. */
        if (code != 0xFF && in < len) {
            if (out >= cap) {
                return -1;
            }
            dst[out++] = 0;
        }
    }
    return (int)out;
}

#include "pd_cobs.h"

#include <stdbool.h>

size_t pd_cobs_encode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap)
{
    /* Pointers, not indexes: on the Uno every Ack goes through here between a
     * command's delimiter and the Ack's first byte, and 16-bit index arithmetic
     * per byte was twice the work. */
    if (cap == 0) {
        return 0;
    }
    const uint8_t *const src_end = src + len;
    uint8_t *const end = dst + cap;
    uint8_t *out = dst + 1;  /* next free byte of dst; never past end */
    uint8_t *code_at = dst;  /* where the current block's code byte goes; may reach end */
    uint8_t code = 1;        /* 1 + bytes in the current block */
    bool after_full = false; /* nothing since the last full (0xFF) block */

    while (src != src_end) {
        uint8_t b = *src++;
        after_full = false;
        if (b != 0) {
            if (out >= end) {
                return 0;
            }
            *out++ = b;
            code++;
        }
        if (b == 0 || code == 0xFF) {
            /* Close the block; a full one (254 bytes) implies no zero. */
            after_full = (b != 0);
            if (code_at >= end) {
                return 0;
            }
            *code_at = code;
            code_at = out;
            if (out != end) {
                out++; /* at end, out and code_at both say full: the next write fails */
            }
            code = 1;
        }
    }
    /*
     * Like the reference encoder (and the host's `cobs` package), a frame
     * ending on a full block gets no empty trailing block: both decode alike,
     * and the shared vectors pin this shorter form.
     */
    if (after_full) {
        return (size_t)(code_at - dst);
    }
    if (code_at >= end) {
        return 0;
    }
    *code_at = code;
    return (size_t)(out - dst);
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

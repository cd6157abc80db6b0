#include "pd_cobs.h"

size_t pd_cobs_encode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap)
{
    /* A block at a time, pointers rather than indexes: on the Uno every Ack goes
     * through here between a command's delimiter and the Ack's first byte, so a
     * byte costs a copy and its tests, no per-byte state beyond the block's code
     * (about 30 cycles a byte when each byte also kept "after a full block"). In
     * place one byte to the left works (pd_link_send): no block is full there, so
     * a block's code byte lands on the 0x00 it stands for, already read. */
    const uint8_t *const src_end = src + len;
    uint8_t *const end = dst + cap;
    uint8_t *out = dst;
    for (;;) {
        uint8_t *code_at = out++;
        if (code_at >= end) {
            return 0;
        }
        uint8_t code = 1; /* 1 + bytes in the block */
        for (; src != src_end; src++) {
            uint8_t b = *src;
            if (b == 0) {
                break;
            }
            if (out >= end) {
                return 0;
            }
            *out++ = b;
            if (++code == 0xFF) {
                src++; /* a full block (254 bytes): it implies no 0x00 */
                break;
            }
        }
        *code_at = code;
        /*
         * Like the reference encoder (and the host's `cobs` package), a frame
         * ending on a full block gets no empty trailing block: both decode alike,
         * and the shared vectors pin this shorter form.
         */
        if (src == src_end) {
            return (size_t)(out - dst);
        }
        if (code != 0xFF) {
            src++; /* the 0x00 this block stands for */
        }
    }
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

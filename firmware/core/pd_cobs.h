/*
 * Consistent Overhead Byte Stuffing (Cheshire and Baker, 1999), docs/protocol.md
 * section 2. Pure functions on bounded buffers, and the incremental decoder the
 * link's receiver runs on every byte as it arrives (pd_cobs_rx_*). The link
 * collects the frame up to its 0x00 delimiter; this module only decodes.
 */
#ifndef PD_COBS_H
#define PD_COBS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* Worst-case encoded size of `n` bytes (no delimiter): one code byte per 254. */
#define PD_COBS_MAX_ENCODED(n) ((n) + (n) / 254u + 1u)

/*
 * Encode `len` bytes of `src` into `dst` (capacity `cap`), without delimiter.
 * Returns the encoded length, or 0 if `dst` is too small (a valid encoding is
 * never empty). `src` and `dst` must not overlap.
 */
size_t pd_cobs_encode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap);

/*
 * Decode one frame (without its delimiter). Returns the decoded length, or -1
 * if the frame is not valid COBS (a 0x00 inside it, a code byte pointing past
 * its end) or `dst` is too small. Decoding in place (dst == src) is allowed:
 * the output never runs ahead of the input.
 */
int pd_cobs_decode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap);

/*
 * The same decoding one encoded byte at a time, for a receiver that works as
 * the bytes arrive (the Uno's link does: at 98 % of the line there is no time
 * to decode a whole frame at its delimiter). Two bytes of state; the caller
 * keeps the 0x00 delimiters to itself and starts a decoder per frame.
 * Inline: on the Uno this runs per received byte, in the main loop.
 */
typedef struct pd_cobs_rx {
    uint8_t left; /* bytes left in the current block; 0: the next byte is a code */
    bool zero;    /* the current block implies a 0x00 after it, if another follows */
} pd_cobs_rx_t;

static inline void pd_cobs_rx_start(pd_cobs_rx_t *rx)
{
    rx->left = 0;
    rx->zero = false;
}

/*
 * One encoded byte of a frame (never 0x00): returns whether it yields a decoded
 * byte, then in *byte. A code byte starts a block of code - 1 data bytes; every
 * block but a full one (0xFF) and the last implies a 0x00, yielded here once
 * the next code shows that its block was not the last.
 */
static inline bool pd_cobs_rx_byte(pd_cobs_rx_t *rx, uint8_t *byte)
{
    if (rx->left == 0) {
        bool put = rx->zero; /* the previous block's implied 0x00, if any */
        rx->left = (uint8_t)(*byte - 1u);
        rx->zero = *byte != 0xFFu;
        *byte = 0;
        return put;
    }
    rx->left--;
    return true;
}

/* Whether the frame may end here: its last code byte does not point past the end. */
static inline bool pd_cobs_rx_complete(const pd_cobs_rx_t *rx)
{
    return rx->left == 0;
}

#endif /* PD_COBS_H */

/*
 * Consistent Overhead Byte Stuffing (Cheshire and Baker, 1999), docs/protocol.md
 * section 2. Pure functions on bounded buffers; the streaming receiver that
 * collects bytes up to a 0x00 delimiter lives in pd_link.c.
 */
#ifndef PD_COBS_H
#define PD_COBS_H

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

#endif /* PD_COBS_H */

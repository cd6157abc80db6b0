#include "pd_packet.h"

#include <string.h>

#include "pd_crc.h"

pd_packet_result_t pd_packet_build(uint8_t type, uint8_t seq, const uint8_t *payload,
                                   size_t len, uint8_t *out, size_t cap, size_t *out_len)
{
    if (len > PD_MAX_PAYLOAD || cap < PD_MIN_PACKET + len) {
        return PD_PACKET_ERR_SPACE;
    }
    out[0] = type;
    out[1] = (uint8_t)len;
    out[2] = seq;
    if (len > 0 && payload != out + PD_HEADER_SIZE) {
        memmove(out + PD_HEADER_SIZE, payload, len);
    }
    uint16_t crc = pd_crc16(out, PD_HEADER_SIZE + len);
    out[PD_HEADER_SIZE + len] = (uint8_t)(crc >> 8);
    out[PD_HEADER_SIZE + len + 1] = (uint8_t)crc;
    *out_len = PD_MIN_PACKET + len;
    return PD_PACKET_OK;
}

pd_packet_result_t pd_packet_parse(const uint8_t *raw, size_t len, pd_packet_t *pkt)
{
    if (len < PD_MIN_PACKET || len != (size_t)PD_MIN_PACKET + raw[1]) {
        return PD_PACKET_ERR_LENGTH;
    }
    return pd_packet_check(raw, len, pd_crc16(raw, len), pkt);
}

pd_packet_result_t pd_packet_check(const uint8_t *raw, size_t len, uint16_t crc, pd_packet_t *pkt)
{
    if (len < PD_MIN_PACKET || len != (size_t)PD_MIN_PACKET + raw[1]) {
        return PD_PACKET_ERR_LENGTH;
    }
    /* The CRC over the data and its own big-endian bytes is zero. */
    if (crc != 0) {
        return PD_PACKET_ERR_CRC;
    }
    if (raw[0] > PD_PACKET_COMMAND) {
        return PD_PACKET_ERR_TYPE;
    }
    pkt->type = raw[0];
    pkt->len = raw[1];
    pkt->seq = raw[2];
    pkt->payload = raw + PD_HEADER_SIZE;
    return PD_PACKET_OK;
}

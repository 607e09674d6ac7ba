#include "frame.h"

/* Table-driven CRC (one table read per byte, ~12 cycles, against ~100 for the bitwise loop); the
 * table is computed at boot into RAM (512 bytes). */
static uint16_t crc_table[256];

void crc16_init(void) {
    for (uint16_t b = 0; b < 256; b++) {
        uint16_t c = b << 8;
        for (uint8_t i = 0; i < 8; i++) c = (c & 0x8000) ? (uint16_t)((c << 1) ^ 0x1021) : (uint16_t)(c << 1);
        crc_table[b] = c;
    }
}

uint16_t crc16(const uint8_t *data, uint8_t n) {
    uint16_t crc = 0xFFFF;
    while (n--) {
        crc = (crc << 8) ^ crc_table[(uint8_t)(crc >> 8) ^ *data++];
    }
    return crc;
}

uint8_t cobs_encode(const uint8_t *src, uint8_t n, uint8_t *dst) {
    /* Frames are at most 39 bytes: one code block, no 254-byte split needed. */
    uint8_t code_at = 0, out = 1, code = 1;
    while (n--) {
        uint8_t b = *src++;
        if (b == 0) {
            dst[code_at] = code;
            code_at = out++;
            code = 1;
        } else {
            dst[out++] = b;
            code++;
        }
    }
    dst[code_at] = code;
    dst[out++] = 0;
    return out;
}

int16_t cobs_decode(uint8_t *buf, uint8_t n) {
    uint8_t i = 0, out = 0;
    while (i < n) {
        uint8_t code = buf[i];
        if (code == 0 || (uint16_t)i + code > n) return -1;
        i++;
        for (uint8_t k = 1; k < code; k++) {
            uint8_t b = buf[i++];
            if (b == 0) return -1;
            buf[out++] = b;
        }
        if (code < 0xFF && i < n) buf[out++] = 0;
    }
    return out;
}

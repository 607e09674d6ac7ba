/* Protocol v1 framing (docs/protocol.md section 2): CRC-16/CCITT-FALSE and COBS. */
#ifndef FRAME_H
#define FRAME_H

#include <stdint.h>

void crc16_init(void);
uint16_t crc16(const uint8_t *data, uint8_t n);
/* COBS-encode n bytes of src into dst and append the 0x00 delimiter; returns the bytes written. */
uint8_t cobs_encode(const uint8_t *src, uint8_t n, uint8_t *dst);
/* Decode n COBS bytes in place; returns the decoded length, or -1 for bytes no encoder makes. */
int16_t cobs_decode(uint8_t *buf, uint8_t n);

#endif

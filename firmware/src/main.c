/* pendulab rig firmware: protocol v1 (docs/protocol.md) on an Arduino Mega 2560.
 *
 * Interrupts do the time-critical work: the four encoder channels (INT0..INT3, highest priority), the
 * tick (Timer1 compare A: latch the counters, apply the voltage due at this tick, enforce the watchdog
 * and the track limits), the UART's receive and transmit. The main loop parses the host's frames,
 * encodes the SAMPLE of every tick and feeds the MCU's hardware watchdog; it sleeps when idle. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/eeprom.h>
#include <avr/wdt.h>
#include <string.h>

#include "board.h"
#include "frame.h"

#define FW_MAJOR 1
#define FW_MINOR 0
#define FW_PATCH 0
#define PROTOCOL 1
#define MAX_DELAY 8
#define RING 16 /* >= MAX_DELAY + 1 answers kept, indexed by answers mod RING */
#define DEFAULT_PERIOD_US 1000
#define DEFAULT_LIMIT_COUNTS 19780 /* 0.45 m */
/* The shortest period: a SAMPLE (22 bytes) on the wire at 1 Mbaud takes 220 us; keep half the period free. */
#define MIN_PERIOD_US 500
#define MAX_PERIOD_US 32767

/* Frame types and fields (docs/protocol.md section 3). */
enum { T_IDENTIFY = 0x01, T_CONFIGURE, T_COMMAND, T_ZERO, T_STREAM, T_IDENTITY = 0x81, T_SAMPLE, T_ACK };
enum { F_ENABLE = 1, F_CLEAR = 2 };
enum { ST_ENABLED = 1, ST_WATCHDOG = 2, ST_LIMIT = 4, ST_FAULT = 8, ST_LATE = 16 };
enum { ACK_OK = 0, ACK_RANGE = 1, ACK_NOT_NOW = 2 };

/* ------------------------------------------------------------------ state shared with the interrupts */
static volatile uint16_t cart_count, pend_count; /* x4 counts, low 16 bits, written by the encoder ISRs */

typedef struct {
    uint16_t answers;
    int16_t mv;
    uint8_t flags;
    uint8_t valid;
} Answer;

typedef struct {
    uint32_t tick;
    uint16_t cart, pend;
    int16_t mv;
    uint8_t status;
    uint16_t late, applied;
} Snapshot;

static volatile Answer ring[RING];
static volatile uint16_t sample_seq[RING];  /* seq of the SAMPLE of tick k, at k mod RING (main loop) */
static volatile uint32_t sample_tick[RING]; /* ... and which tick it belongs to */
static volatile Snapshot snaps[4];          /* ticks latched, waiting for the main loop to send */
static volatile uint8_t snap_head, snap_tail;
static volatile uint8_t streaming, tick_alive;
static volatile uint8_t work; /* set by an ISR when the main loop has something to do */
static volatile uint16_t cmd_age; /* ticks since the last valid COMMAND */

/* Owned by the tick ISR once streaming (the main loop changes them only with interrupts off). */
static uint16_t cart_last, pend_last;
static int32_t cart_full, pend_full, cart_zero, pend_zero;
static uint32_t tick;
static uint16_t late_count, applied;
static int16_t voltage_mv;
static uint8_t enabled, wd_tripped, limit_hit, fault;

/* Configuration (CONFIGURE), read by the ISR. */
static uint16_t period_us = DEFAULT_PERIOD_US, watchdog_ms = 20, v_max_mv = DAC_FULL_SCALE_MV;
static uint16_t watchdog_ticks = 20;
static uint8_t delay = 1;
static int32_t x_min = -DEFAULT_LIMIT_COUNTS, x_max = DEFAULT_LIMIT_COUNTS;
static uint32_t boot_id;

/* ------------------------------------------------------------------ encoders: x4 quadrature */
/* Counting up when A leads B: on an A edge +1 if A != B, on a B edge +1 if A == B. Each ISR counts
 * one step, so an edge is missed only if its channel's ISR waits longer than the next edge (15 us at
 * 1.5 m/s of cart speed = 240 cycles); these are the four highest-priority vectors. */
/* Hand-written: 40 cycles with the entry, against 54 for the compiler's (which saves r0/r1 it never
 * uses); at full speed they are the CPU's largest load. ENC(vector, counter, shift, up-when-T): T gets
 * A xor B of this encoder (PIND bits shift, shift + 1), then the 16-bit counter goes one way or the other. */
#define ENC_ISR(vector, counter, shift, inc_if_t)                                                           \
    ISR(vector, ISR_NAKED) {                                                                                \
        __asm__ __volatile__("push r24\n\t"                                                                 \
                             "in r24, __SREG__\n\t"                                                         \
                             "push r24\n\t"                                                                 \
                             "push r25\n\t"                                                                 \
                             "in r24, %[pin]\n\t"                                                           \
                             "mov r25, r24\n\t"                                                             \
                             "lsr r25\n\t"                                                                  \
                             "eor r24, r25\n\t"                                                             \
                             "bst r24, %[bit]\n\t"                                                          \
                             "lds r24, %[cnt]\n\t"                                                          \
                             "lds r25, %[cnt]+1\n\t"                                                        \
                             inc_if_t " 1f\n\t"                                                             \
                             "sbiw r24, 1\n\t"                                                              \
                             "rjmp 2f\n"                                                                     \
                             "1: adiw r24, 1\n"                                                              \
                             "2: sts %[cnt]+1, r25\n\t"                                                     \
                             "sts %[cnt], r24\n\t"                                                          \
                             "pop r25\n\t"                                                                  \
                             "pop r24\n\t"                                                                  \
                             "out __SREG__, r24\n\t"                                                        \
                             "pop r24\n\t"                                                                  \
                             "reti\n\t" ::[pin] "I"(_SFR_IO_ADDR(ENC_PIN)),                               \
                             [bit] "I"(shift), [cnt] "i"(&counter));                                        \
    }

ENC_ISR(INT0_vect, cart_count, 0, "brts") /* cart A changed: up if A != B */
ENC_ISR(INT1_vect, cart_count, 0, "brtc") /* cart B changed: up if A == B */
ENC_ISR(INT2_vect, pend_count, 2, "brts")
ENC_ISR(INT3_vect, pend_count, 2, "brtc")

/* ------------------------------------------------------------------ amplifier */
static void amplifier(int16_t mv, uint8_t on) {
    /* The op-amp stage inverts: V_amp = -(V_dac - 2.048 V) * 10 / 2.048, so
     * code = 2048 - mv * 2048 / 10000 (13422 / 65536 = 0.20480), clamped to the DAC's 12 bits. */
    int16_t code = 2048 - (int16_t)(((int32_t)mv * 13422 + 32768) >> 16);
    if (!on) code = 2048;
    if (code < 0) code = 0;
    if (code > 4095) code = 4095;
    if (!on) PORTA &= ~_BV(AMP_ENABLE); /* off first, then 0 V */
    PORTB &= ~_BV(DAC_CS);
    SPDR = 0x30 | (uint8_t)(code >> 8); /* DAC A, unbuffered, gain 1x, active */
    while (!(SPSR & _BV(SPIF))) {}
    SPDR = (uint8_t)code;
    while (!(SPSR & _BV(SPIF))) {}
    PORTB |= _BV(DAC_CS); /* the MCP4921 latches on CS high (LDAC tied low) */
    if (on) PORTA |= _BV(AMP_ENABLE);
}

/* ------------------------------------------------------------------ the tick */
ISR(TIMER1_COMPA_vect) {
    /* Let an encoder edge that came during this ISR's entry be counted first (one instruction after
     * sei runs before any interrupt), then latch both counters at once. */
    sei();
    __asm__ __volatile__("nop");
    cli();
    uint16_t c = cart_count, p = pend_count;
    PINA = _BV(TICK_OUT);
    sei(); /* the encoders may interrupt the rest */
    cart_full += (int16_t)(c - cart_last);
    pend_full += (int16_t)(p - pend_last);
    cart_last = c;
    pend_last = p;
    tick_alive = 1;
    work = 1; /* at least once a tick: the main loop feeds the hardware watchdog */
    int32_t x = cart_full - cart_zero;
    uint8_t status = 0;
    if (streaming) {
        if (tick >= delay) {
            uint8_t slot = (uint8_t)(tick - delay) % RING;
            volatile Answer *a = 0;
            if (sample_tick[slot] == tick - delay) {
                uint16_t want = sample_seq[slot];
                a = &ring[want % RING];
                if (!(a->valid && a->answers == want)) a = 0;
            }
            if (a) {
                a->valid = 0;
                applied = a->answers;
                if (a->flags & F_CLEAR) {
                    wd_tripped = 0;
                    if (x >= x_min && x <= x_max) limit_hit = 0;
                }
                if ((a->flags & F_ENABLE) && !(wd_tripped | limit_hit | fault)) {
                    int16_t mv = a->mv;
                    if (mv > (int16_t)v_max_mv) mv = v_max_mv;
                    if (mv < -(int16_t)v_max_mv) mv = -(int16_t)v_max_mv;
                    voltage_mv = mv;
                    enabled = 1;
                } else {
                    enabled = 0;
                    voltage_mv = 0;
                }
            } else {
                late_count++;
                status |= ST_LATE;
            }
        }
        if (cmd_age < 0xFFFF) cmd_age++;
        if (cmd_age > watchdog_ticks) wd_tripped = 1;
    }
    if (x < x_min || x > x_max) limit_hit = 1;
    uint8_t pins = PINA;
    if (!(pins & _BV(LIMIT_FITTED)) && (pins & (_BV(LIMIT_LEFT) | _BV(LIMIT_RIGHT)))) limit_hit = 1;
    if (!(pins & _BV(AMP_FAULT))) fault = 1;
    if (wd_tripped | limit_hit | fault | !streaming) {
        enabled = 0;
        voltage_mv = 0;
    }
    amplifier(voltage_mv, enabled);
    if (streaming) {
        status |= (enabled ? ST_ENABLED : 0) | (wd_tripped ? ST_WATCHDOG : 0) | (limit_hit ? ST_LIMIT : 0) | (fault ? ST_FAULT : 0);
        uint8_t next = (snap_head + 1) & 3;
        if (next != snap_tail) {
            volatile Snapshot *s = &snaps[snap_head];
            s->tick = tick;
            s->cart = (uint16_t)x;
            s->pend = (uint16_t)(pend_full - pend_zero);
            s->mv = voltage_mv;
            s->status = status;
            s->late = late_count;
            s->applied = applied;
            snap_head = next;
            work = 1;
        }
        tick++;
    }
}

/* ------------------------------------------------------------------ UART0 at 1 Mbaud */
/* Both rings are 256 bytes on a 256-byte boundary: the index is the low byte of the address and wraps
 * by itself, so the hand-written ISRs below need no arithmetic (42 and 50 cycles, against 63 and 75). */
static volatile uint8_t rx_buf[256] __attribute__((aligned(256)));
static volatile uint8_t tx_buf[256] __attribute__((aligned(256)));
static volatile uint8_t rx_head, rx_tail, tx_head, tx_tail;

/* Store the byte; wake the main loop on a frame's delimiter (or when the ring is full). */
ISR(USART0_RX_vect, ISR_NAKED) {
    __asm__ __volatile__(
        "push r30\n\t"
        "in r30, __SREG__\n\t"
        "push r30\n\t"
        "push r31\n\t"
        "push r24\n\t"
        "push r25\n\t"
        "lds r24, %[udr]\n\t"
        "lds r30, %[head]\n\t"
        "mov r25, r30\n\t"
        "inc r25\n\t"
        "lds r31, %[tail]\n\t"
        "cp r25, r31\n\t"
        "breq 1f\n\t"            /* full: drop the byte, wake the main loop */
        "ldi r31, hi8(%[buf])\n\t"
        "st Z, r24\n\t"
        "sts %[head], r25\n\t"
        "tst r24\n\t"
        "brne 2f\n"
        "1: ldi r24, 1\n\t"
        "sts %[work], r24\n"
        "2: pop r25\n\t"
        "pop r24\n\t"
        "pop r31\n\t"
        "pop r30\n\t"
        "out __SREG__, r30\n\t"
        "pop r30\n\t"
        "reti\n\t" ::[udr] "i"(&UDR0),
        [head] "i"(&rx_head), [tail] "i"(&rx_tail), [buf] "i"(rx_buf), [work] "i"(&work));
}

/* Send the next byte, or stop the interrupt when the ring is empty. */
ISR(USART0_UDRE_vect, ISR_NAKED) {
    __asm__ __volatile__(
        "push r30\n\t"
        "in r30, __SREG__\n\t"
        "push r30\n\t"
        "push r31\n\t"
        "push r24\n\t"
        "lds r30, %[tail]\n\t"
        "lds r24, %[head]\n\t"
        "cp r30, r24\n\t"
        "breq 1f\n\t"
        "ldi r31, hi8(%[buf])\n\t"
        "ld r24, Z+\n\t"
        "sts %[udr], r24\n\t"
        "sts %[tail], r30\n\t"
        "rjmp 2f\n"
        "1: lds r24, %[ucsrb]\n\t"
        "andi r24, %[noudrie]\n\t"
        "sts %[ucsrb], r24\n"
        "2: pop r24\n\t"
        "pop r31\n\t"
        "pop r30\n\t"
        "out __SREG__, r30\n\t"
        "pop r30\n\t"
        "reti\n\t" ::[udr] "i"(&UDR0),
        [head] "i"(&tx_head), [tail] "i"(&tx_tail), [buf] "i"(tx_buf), [ucsrb] "i"(&UCSR0B),
        [noudrie] "n"(0xFF & ~(1 << UDRIE0)));
}

static uint16_t rig_seq;

/* Queue one frame: header, payload, CRC, COBS. Whole frames only, in seq order. */
static void send(uint8_t type, const void *payload, uint8_t n) {
    uint8_t body[3 + 34 + 2], wire[3 + 34 + 2 + 2];
    body[0] = type;
    memcpy(body + 1, &rig_seq, 2);
    memcpy(body + 3, payload, n);
    uint16_t crc = crc16(body, 3 + n);
    memcpy(body + 3 + n, &crc, 2);
    uint8_t len = cobs_encode(body, 3 + n + 2, wire);
    if ((uint8_t)(tx_tail - tx_head - 1) < len) return; /* no room: the host counts the gap in seq */
    rig_seq++;
    uint8_t h = tx_head;
    for (uint8_t i = 0; i < len; i++) tx_buf[h++] = wire[i];
    tx_head = h;
    UCSR0B |= _BV(UDRIE0);
}

static void ack(uint8_t type, uint8_t result) {
    uint8_t p[2] = {type, result};
    send(T_ACK, p, 2);
}

static void send_identity(void) {
    uint8_t p[34];
    float cpm = CART_COUNTS_PER_M, cpr = PEND_COUNTS_PER_RAD;
    /* The seesaw's jumper: its pivot encoder, behind the 3:1 gear, is on the pendulum's channel. Read at
     * every IDENTIFY (the pull-up has long settled), so the host always learns what is wired now. */
    if (!(PINA & _BV(SEESAW))) cpr *= SEESAW_GEAR;
    p[0] = PROTOCOL;
    p[1] = FW_MAJOR;
    p[2] = FW_MINOR;
    p[3] = FW_PATCH;
    memcpy(p + 4, &boot_id, 4);
    uint32_t per = period_us;
    memcpy(p + 8, &per, 4);
    memcpy(p + 12, &cpm, 4);
    memcpy(p + 16, &cpr, 4);
    memcpy(p + 20, &v_max_mv, 2);
    cli();
    memcpy(p + 22, &x_min, 4);
    memcpy(p + 26, &x_max, 4);
    sei();
    memcpy(p + 30, &watchdog_ms, 2);
    p[32] = MAX_DELAY;
    p[33] = 16;
    send(T_IDENTITY, p, 34);
}

static void send_sample(const volatile Snapshot *s) {
    uint8_t p[15];
    uint16_t seq = rig_seq;
    memcpy(p, (const void *)&s->tick, 4);
    memcpy(p + 4, (const void *)&s->cart, 2);
    memcpy(p + 6, (const void *)&s->pend, 2);
    memcpy(p + 8, (const void *)&s->mv, 2);
    p[10] = s->status;
    memcpy(p + 11, (const void *)&s->late, 2);
    memcpy(p + 13, (const void *)&s->applied, 2);
    /* Record the sample's seq before it can be answered: the ISR looks it up N ticks later. */
    uint8_t slot = (uint8_t)s->tick % RING;
    cli();
    sample_seq[slot] = seq;
    sample_tick[slot] = s->tick;
    sei();
    send(T_SAMPLE, p, 15);
}

static void set_timer(uint16_t us) {
    /* CTC on OCR1A with /8: 0.5 us resolution, exact for any whole number of microseconds. */
    cli();
    TCCR1B = 0;
    TCNT1 = 0;
    OCR1A = 2 * us - 1;
    TCCR1A = 0;
    TCCR1B = _BV(WGM12) | _BV(CS11);
    TIFR1 = _BV(OCF1A);
    TIMSK1 = _BV(OCIE1A);
    sei();
}

/* ------------------------------------------------------------------ host frames */
static void handle(uint8_t *f, uint8_t n) {
    static const uint8_t lengths[6] = {0, 1, 17, 5, 1, 1};
    if (n < 5) return;
    uint8_t type = f[0];
    if (type < T_IDENTIFY || type > T_STREAM || n != 3 + lengths[type] + 2) return;
    uint16_t crc;
    memcpy(&crc, f + n - 2, 2);
    if (crc16(f, n - 2) != crc) return;
    uint8_t *p = f + 3;
    switch (type) {
    case T_IDENTIFY:
        send_identity();
        break;
    case T_CONFIGURE: {
        uint32_t per;
        uint16_t wd, vmax;
        int32_t lo, hi;
        memcpy(&per, p, 4);
        memcpy(&wd, p + 4, 2);
        uint8_t d = p[6];
        memcpy(&lo, p + 7, 4);
        memcpy(&hi, p + 11, 4);
        memcpy(&vmax, p + 15, 2);
        if (streaming) {
            ack(T_CONFIGURE, ACK_NOT_NOW); /* the delay N is fixed for a session */
            break;
        }
        if (per < MIN_PERIOD_US || per > MAX_PERIOD_US || wd < 1 || wd > 60000 || d < 1 || d > MAX_DELAY || lo >= hi ||
            vmax < 1 || vmax > DAC_FULL_SCALE_MV) {
            ack(T_CONFIGURE, ACK_RANGE);
            break;
        }
        uint32_t ticks = ((uint32_t)wd * 1000 + per - 1) / per;
        cli();
        watchdog_ms = wd;
        watchdog_ticks = ticks > 0xFFFE ? 0xFFFE : (uint16_t)ticks;
        delay = d;
        x_min = lo;
        x_max = hi;
        v_max_mv = vmax;
        sei();
        if (per != period_us) {
            period_us = (uint16_t)per;
            set_timer(period_us);
        }
        ack(T_CONFIGURE, ACK_OK);
        break;
    }
    case T_COMMAND: {
        uint16_t answers;
        memcpy(&answers, p, 2);
        volatile Answer *a = &ring[answers % RING];
        cli();
        a->answers = answers;
        memcpy((void *)&a->mv, p + 2, 2);
        a->flags = p[4];
        a->valid = 1;
        cmd_age = 0; /* only a frame that passed the CRC feeds the watchdog */
        sei();
        break;
    }
    case T_ZERO:
        cli();
        if (p[0] & 1) cart_zero = cart_full + (int16_t)(cart_count - cart_last);
        if (p[0] & 2) pend_zero = pend_full + (int16_t)(pend_count - pend_last);
        sei();
        ack(T_ZERO, ACK_OK);
        break;
    case T_STREAM:
        if (p[0] && !streaming) {
            ack(T_STREAM, ACK_OK); /* before the first sample */
            cli();
            for (uint8_t i = 0; i < RING; i++) {
                ring[i].valid = 0;
                sample_tick[i] = 0xFFFFFFFFul;
            }
            tick = 0;
            late_count = 0;
            cmd_age = 0;
            snap_head = snap_tail = 0;
            TCNT1 = 0; /* tick 0 one period from now */
            TIFR1 = _BV(OCF1A);
            streaming = 1;
            sei();
        } else {
            if (!p[0] && streaming) {
                cli();
                streaming = 0;
                enabled = 0;
                voltage_mv = 0;
                snap_head = snap_tail = 0;
                amplifier(0, 0); /* now, with the tick held off: the SPI is not reentrant */
                sei();
            }
            ack(T_STREAM, ACK_OK);
        }
        break;
    }
}

/* ------------------------------------------------------------------ boot */
/* Disable the watchdog first thing: after a watchdog reset it stays on at its shortest timeout. */
uint8_t reset_cause __attribute__((section(".noinit")));
void early(void) __attribute__((naked, used, section(".init3")));
void early(void) {
    reset_cause = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

static uint32_t boot_state __attribute__((section(".noinit"))); /* SRAM powers up random */
static uint32_t EEMEM ee_boots;

static uint32_t mix32(uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352dUL;
    x ^= x >> 15;
    x *= 0x846ca68bUL;
    x ^= x >> 16;
    return x;
}

static void make_boot_id(void) {
    /* A counter in EEPROM makes every boot different; the power-up SRAM and the noise of a floating
     * ADC input make it random. */
    uint32_t boots = eeprom_read_dword(&ee_boots) + 1;
    eeprom_write_dword(&ee_boots, boots);
    uint32_t noise = 0;
    ADMUX = _BV(REFS0) | 0x07; /* ADC7, unconnected */
    ADCSRA = _BV(ADEN) | 7;
    for (uint8_t i = 0; i < 8; i++) {
        ADCSRA |= _BV(ADSC);
        while (ADCSRA & _BV(ADSC)) {}
        noise = (noise << 4) ^ ADC;
    }
    ADCSRA = 0;
    boot_state = mix32(boot_state ^ mix32(boots) ^ noise ^ ((uint32_t)reset_cause << 24));
    boot_id = boot_state;
}

int main(void) {
    /* Motor off before anything else. */
    DDRA = _BV(AMP_ENABLE) | _BV(TICK_OUT);
    PORTA = _BV(LIMIT_LEFT) | _BV(LIMIT_RIGHT) | _BV(LIMIT_FITTED) | _BV(AMP_FAULT) | _BV(SEESAW); /* pull-ups */
    DDRB = _BV(DAC_CS) | _BV(DAC_SCK) | _BV(DAC_SDI);
    PORTB = _BV(DAC_CS);
    SPCR = _BV(SPE) | _BV(MSTR);
    SPSR = _BV(SPI2X); /* fosc/2 = 8 MHz */
    amplifier(0, 0);
    if (reset_cause & _BV(BORF)) fault = 1; /* a brown-out: 0 V until the next reset */

    crc16_init();
    make_boot_id();

    /* Encoders: any edge on INT0..INT3. */
    DDRD &= ~(_BV(CART_A) | _BV(CART_B) | _BV(PEND_A) | _BV(PEND_B));
    EICRA = _BV(ISC00) | _BV(ISC10) | _BV(ISC20) | _BV(ISC30);
    EIFR = 0x0F;
    EIMSK = 0x0F;

    /* UART0: 1 Mbaud (U2X, UBRR 1), 8N1. 921600 is not reachable from 16 MHz (-7.8 %/+8.5 %); the
     * Mega's USB bridge runs its UART at 1 Mbaud when the host asks for 921600 (docs/protocol.md). */
    UCSR0A = _BV(U2X0);
    UBRR0 = 1;
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);

    set_timer(period_us);
    wdt_enable(WDTO_15MS);

    static uint8_t frame[66];
    uint8_t flen = 0, overflow = 0;
    for (;;) {
        /* Feed the hardware watchdog only while the tick runs too. */
        if (tick_alive) {
            tick_alive = 0;
            wdt_reset();
        }
        uint8_t did = 0;
        while (rx_tail != rx_head) {
            uint8_t b = rx_buf[rx_tail];
            rx_tail = rx_tail + 1;
            did = 1;
            if (b == 0) {
                if (!overflow && flen) {
                    int16_t n = cobs_decode(frame, flen);
                    if (n > 0) handle(frame, (uint8_t)n);
                }
                flen = 0;
                overflow = 0;
            } else if (flen < sizeof frame) {
                frame[flen++] = b;
            } else {
                overflow = 1; /* longer than any frame: rejected unread */
            }
        }
        while (snap_tail != snap_head) {
            send_sample(&snaps[snap_tail]);
            snap_tail = (snap_tail + 1) & 3;
            did = 1;
        }
        if (!did) {
            /* Sleep until an ISR says there is work: an encoder edge wakes the CPU for a few cycles only.
             * Written out so that its address range (idle_begin..idle_end) is known: the twin counts the
             * cycles spent here as idle when it measures the CPU load. */
            set_sleep_mode(SLEEP_MODE_IDLE);
            sleep_enable();
            __asm__ __volatile__(".global idle_begin\n\t"
                                 ".global idle_end\n"
                                 "idle_begin:\n\t"
                                 "cli\n\t"
                                 "lds __tmp_reg__, %[work]\n\t"
                                 "tst __tmp_reg__\n\t"
                                 "brne idle_end\n\t"
                                 "sei\n\t" /* the instruction after sei runs first: no wake-up is lost */
                                 "sleep\n\t"
                                 "rjmp idle_begin\n"
                                 "idle_end:\n\t"
                                 "sts %[work], __zero_reg__\n\t"
                                 "sei\n\t" ::[work] "i"(&work)
                                 : "memory");
            sleep_disable();
        }
    }
}

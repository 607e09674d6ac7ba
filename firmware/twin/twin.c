/* The rig's digital twin: the real firmware (.hex/.elf) in simavr, its pins wired to the plant.
 *
 * The plant is Plant.fmu's own CasADi-generated code (plant_rk4), or with --plant seesaw Seesaw.fmu's
 * (seesaw_rk4: its tilt on the pendulum encoder's channel behind the 3:1 gear, the firmware's seesaw jumper
 * PA6 grounded), integrated in the AVR's time in RK4
 * steps of at most 100 us; a voltage change (DAC write or enable pin) splits a step at its cycle. The
 * encoders are driven as real quadrature edges on PD0..PD3 at the cycles where the (linearly
 * interpolated) positions cross a count boundary. The DAC (MCP4921 on the SPI) and the amplifier
 * enable pin give the voltage; UART0 is a pseudo-terminal whose path is the first line on stdout.
 *
 * twin FIRMWARE [--plant pendulum|seesaw] --params P1,...,Pn [--raise-after S] [--poke MAG,DUR,START] [--seed N]
 *      [--restart-after S] [--fault-after S] [--close-after S] [--byte-error-rate P]
 *   test and measurement options: [--duration S] [--no-pace] [--trace FILE] [--profile FILE]
 *      [--kinematic V,W,T] [--hang-after S] [--idle BEGIN,END]
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_hex.h>
#include <avr_extint.h>
#include <avr_ioport.h>
#include <avr_spi.h>
#include <avr_uart.h>

#include "plant_casadi.h"
#include "plant_sizes.h"
#include "seesaw_casadi.h"

#define F_CPU 16000000.0
#define SUB_CYCLES 1600 /* 100 us: Plant.fmu's largest RK4 sub-step */
#define CART_CPM 43956.04  /* counts per metre (IP02) */
#define PEND_CPR 651.8986  /* counts per radian (4096 per turn) */
#define SEESAW_GEAR 3.0   /* SEESAW-E: the pivot encoder turns 3 times per turn of the seesaw */
#define HOLD_ANGLE (0.5 * M_PI / 180.0)
#define RAISE_TIME 1.0     /* s a person takes to raise the pendulum */
#define LIFT_TIME 0.6      /* s a person takes to lift the seesaw level (and centre the cart on it) */
#define NP_MAX (PLANT_NP > SEESAW_NP ? PLANT_NP : SEESAW_NP)
#define SPDR_ADDR 0x4E

static avr_t *avr;
static double params[NP_MAX];
/* The plant: the pendulum (state x, xdot, alpha, alphadot; its encoder reads 0 hanging) or the seesaw (x, xdot,
 * theta, thetadot; its encoder reads 0 level, 3 x 4096 counts per turn). */
static int seesaw;
static double angle_zero = M_PI, angle_cpr = PEND_CPR;
static double state[4] = {0, 0, M_PI, 0}; /* at cycle seg_start */
static double next_state[4];              /* predicted at cycle seg_end */
static avr_cycle_count_t seg_start, seg_end;
static double v_dac, v_applied;

/* options */
static double raise_after = -1, poke_mag, poke_dur, poke_start = -1, restart_after = -1, fault_after = -1,
              close_after = -1, byte_error_rate = 0, duration = -1, hang_after = -1;
static double kin_v = 0, kin_w = 0, kin_t = 0; /* kinematic test motion */
static int kinematic = 0, pace = 1;
static FILE *trace, *profile_out;
static unsigned seed = 1;
static int seed_given = 0;

/* the person */
static double connected_at = -1, zeroed_at = -1, raise_at = -1, released_at = -1;
static double lift_from[2];              /* the seesaw's x and tilt when the hand takes it */
static int raising = 0, held = 0, raised_done = 0, hung = 0, faulted = 0;

static double wall(void);
static double wall0;
static double now_s(void) { return avr->cycle / F_CPU; }

static void say(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "[twin %8.3f s] ", now_s());
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
}

/* ------------------------------------------------------------------ random (xorshift) */
static unsigned rnd(void) {
    seed ^= seed << 13;
    seed ^= seed >> 17;
    seed ^= seed << 5;
    return seed;
}
static double urand(void) { return (rnd() & 0xFFFFFF) / 16777216.0; }

/* ------------------------------------------------------------------ plant */
static void rk4(double *s, double V, double t, double h) {
    static double w[PLANT_WORK_DOUBLES];
    static long long int iw[PLANT_WORK_INTS];
    double out[4];
    const double *arg[5] = {s, &V, params, &t, &h};
    double *res[1] = {out};
    if (seesaw) seesaw_rk4(arg, res, iw, w, 0);
    else plant_rk4(arg, res, iw, w, 0);
    memcpy(s, out, sizeof out);
}

static void kinematic_state(double t, double *s) {
    /* Cart: a triangle wave of amplitude 0.4 m at kin_v; pendulum: spinning at kin_w; still for the
     * first 0.3 s (the firmware boots) and after kin_t. */
    int moving = t >= 0.3 && t < kin_t;
    double tt = t < 0.3 ? 0 : (t < kin_t ? t : kin_t) - 0.3, a = 0.4, T = 4 * a / kin_v;
    double ph = fmod(tt + T / 4, T) / T; /* starts at 0 going up */
    double tri = ph < 0.5 ? (4 * ph - 1) : (3 - 4 * ph);
    s[0] = a * tri;
    s[1] = moving ? (ph < 0.5 ? kin_v : -kin_v) : 0;
    s[2] = M_PI + kin_w * tt;
    s[3] = moving ? kin_w : 0;
}

static double x_hold;
static int amp_enabled;
static void seesaw_hand(double t, double *s) {
    /* The person lifts the seesaw off its tilt stop to level along a smooth path, bringing the cart (which slid
     * down the tilted track) back to the centre meanwhile, then holds both there until the controller has it. */
    if (raising) {
        double u = (t - raise_at) / LIFT_TIME;
        if (u > 1) u = 1;
        double g = 0.5 + 0.5 * cos(M_PI * u), dg = u < 1 ? -0.5 * M_PI * sin(M_PI * u) / LIFT_TIME : 0; /* 1 -> 0 */
        s[0] = lift_from[0] * g;
        s[1] = lift_from[0] * dg;
        s[2] = lift_from[1] * g;
        s[3] = lift_from[1] * dg;
    } else if (held) {
        s[0] = s[1] = s[2] = s[3] = 0;
    }
}

static void hand(double t, double *s) {
    /* The person's hands override the pendulum while raising or holding it, and keep the cart still. */
    if (seesaw) {
        seesaw_hand(t, s);
        return;
    }
    if (raising || held) { /* until the raise is done, whatever the motor does */
        s[0] = x_hold;
        s[1] = 0;
    }
    if (raising) {
        /* Up to 2.5 deg from upright (outside the controller's +-2 deg capture window) along a smooth path,
         * then placed at HOLD_ANGLE in the last 2 ms: the controller can only take a pendulum at rest. */
        const double outside = 2.5 * M_PI / 180.0, place = 0.002;
        double span = RAISE_TIME - place, u = t - raise_at;
        if (u < span) {
            double f = u / span, g = 0.5 - 0.5 * cos(M_PI * f);
            s[2] = M_PI + (outside - M_PI) * g;
            s[3] = (outside - M_PI) * 0.5 * M_PI * sin(M_PI * f) / span;
        } else {
            double f = (u - span) / place;
            if (f > 1) f = 1;
            s[2] = outside + (HOLD_ANGLE - outside) * f;
            s[3] = f < 1 ? (HOLD_ANGLE - outside) / place : 0;
        }
    } else if (held) {
        s[2] = HOLD_ANGLE;
        s[3] = 0;
    }
}

/* ------------------------------------------------------------------ encoders */
typedef struct {
    const char *name;
    int pin_a;          /* PD pin of channel A (B is pin_a + 1) */
    long count;         /* count shown on the pins */
    double u0, u1;      /* position in counts at seg_start / seg_end */
    avr_irq_t *a, *b;
    avr_cycle_count_t last_edge[2];
    int fault;          /* 0, or ENC_DEAD / ENC_FROZEN from fault_at on */
    double fault_at;    /* s after the host connects; < 0: never */
} Encoder;

enum { ENC_DEAD = 1, ENC_FROZEN = 2 };
static Encoder enc[2] = {{"cart", 0, 0, 0, 0, 0, 0, {0, 0}, 0, -1}, {"pendulum", 2, 0, 0, 0, 0, 0, {0, 0}, 0, -1}};
static int enc_fault_kind[2];   /* the fault given on the command line, applied at fault_at */
static long edges_total;

static void drive_pins(Encoder *e) {
    static const int A[4] = {0, 1, 1, 0}, B[4] = {0, 0, 1, 1};
    int ph = (int)(((e->count % 4) + 4) % 4);
    avr_raise_irq(e->a, A[ph]);
    avr_raise_irq(e->b, B[ph]);
}

static avr_cycle_count_t edge_due(Encoder *e) {
    /* The cycle at which the linearly interpolated position crosses the next count boundary. */
    double u0 = e->u0, u1 = e->u1, target;
    if (u1 >= e->count + 0.5) target = e->count + 0.5;
    else if (u1 < e->count - 0.5) target = e->count - 0.5;
    else return 0;
    double f = (u1 == u0) ? 1.0 : (target - u0) / (u1 - u0);
    if (f < 0) f = 0;
    avr_cycle_count_t at = seg_start + (avr_cycle_count_t)ceil(f * (double)(seg_end - seg_start));
    return at <= avr->cycle ? avr->cycle + 1 : at;
}

static avr_cycle_count_t edge_timer(avr_t *a, avr_cycle_count_t when, void *param) {
    (void)a;
    Encoder *e = param;
    if (e->u1 >= e->count + 0.5) e->count++;
    else if (e->u1 < e->count - 0.5) e->count--;
    else return 0;
    edges_total++;
    int old_a = (int)(((e->count - 1) % 4 + 4) % 4);
    (void)old_a;
    drive_pins(e);
    /* which channel moved: A on even->odd phase changes 0->1, 2->3 */
    e->last_edge[0] = when;
    avr_cycle_count_t next = edge_due(e);
    return next > when ? next : (next ? when + 1 : 0);
}

static void plan_encoders(void) {
    double u[2][2] = {{state[0] * CART_CPM, next_state[0] * CART_CPM},
                      {(state[2] - angle_zero) * angle_cpr, (next_state[2] - angle_zero) * angle_cpr}};
    for (int i = 0; i < 2; i++) {
        enc[i].u0 = u[i][0];
        enc[i].u1 = u[i][1];
        avr_cycle_timer_cancel(avr, edge_timer, &enc[i]);
        if (enc[i].fault) continue; /* a dead or frozen encoder makes no more edges */
        avr_cycle_count_t at = edge_due(&enc[i]);
        if (at) avr_cycle_timer_register(avr, at - avr->cycle, edge_timer, &enc[i]);
    }
}

/* ------------------------------------------------------------------ the plant's steps in AVR time */
static void predict(void) {
    /* next_state: the state at seg_end with the voltage now applied. */
    double t0 = seg_start / F_CPU, h = (seg_end - seg_start) / F_CPU;
    if (kinematic) {
        kinematic_state(seg_end / F_CPU, next_state);
    } else {
        memcpy(next_state, state, sizeof state);
        if (h > 0) rk4(next_state, v_applied, t0, h);
        hand(seg_end / F_CPU, next_state);
    }
    plan_encoders();
}

static void advance_to(avr_cycle_count_t c) {
    /* The state at cycle c (inside the current step) with the voltage that acted until now. */
    if (c <= seg_start) return;
    if (c >= seg_end) {
        memcpy(state, next_state, sizeof state);
    } else if (kinematic) {
        kinematic_state(c / F_CPU, state);
    } else {
        rk4(state, v_applied, seg_start / F_CPU, (c - seg_start) / F_CPU);
        hand(c / F_CPU, state);
    }
    seg_start = c;
}

static void person(double t);
static void link_io(void);
static void pacing(void);

static avr_uart_t *uart0;

static avr_cycle_count_t step_timer(avr_t *a, avr_cycle_count_t when, void *param) {
    (void)a;
    (void)param;
    /* simavr 1.6 counts a parity bit in every 8N1 byte (11 bits); the wire has 10. */
    if (uart0 && uart0->cycles_per_byte % 11 == 0) uart0->cycles_per_byte = uart0->cycles_per_byte / 11 * 10;
    advance_to(when);
    person(when / F_CPU);
    seg_end = when + SUB_CYCLES;
    predict();
    link_io();
    if (pace) pacing();
    return seg_end;
}

static void restart_steps(void) {
    avr_cycle_timer_cancel(avr, step_timer, NULL);
    seg_end = avr->cycle + SUB_CYCLES;
    predict();
    avr_cycle_timer_register(avr, SUB_CYCLES, step_timer, NULL);
}

static void release(void) {
    /* The controller has the pendulum (seesaw): the hand lets go (and the poke, the seesaw's tap, is scheduled from now). */
    const char *what = seesaw ? "seesaw" : "pendulum";
    held = 0;
    released_at = now_s();
    if (poke_start >= 0) {
        params[seesaw ? S_tap_magnitude : P_poke_magnitude] = poke_mag;
        params[seesaw ? S_tap_duration : P_poke_duration] = poke_dur;
        params[seesaw ? S_tap_start : P_poke_start] = released_at + poke_start;
        say("hand released, the controller has the %s; %s %g rad/s^2 for %g s at t = %.3f s", what, seesaw ? "tap" : "poke",
            poke_mag, poke_dur, released_at + poke_start);
    } else {
        say("hand released, the controller has the %s", what);
    }
}

static void set_voltage(void) {
    double v = amp_enabled ? v_dac : 0.0;
    if (v == v_applied) return;
    advance_to(avr->cycle);
    v_applied = v;
    if (trace) fprintf(trace, "volt,%llu,%.0f,%d\n", (unsigned long long)avr->cycle, v * 1000, amp_enabled);
    if (held && amp_enabled && v != 0.0) release();
    restart_steps();
}

/* ------------------------------------------------------------------ DAC, enable, tick pin */
static avr_spi_t *spi;
static uint16_t dac_shift;

static avr_cycle_count_t spi_done(avr_t *a, avr_cycle_count_t when, void *param) {
    (void)when;
    (void)param;
    avr_raise_interrupt(a, &spi->spi);
    return 0;
}

static void spdr_write(avr_t *a, avr_io_addr_t addr, uint8_t v, void *param) {
    /* simavr 1.6 takes 100 us per SPI byte; the real SPI at fosc/2 takes 16 cycles (8 bits x 2). */
    (void)param;
    avr_regbit_clear(a, spi->spi.raised);
    a->data[addr] = v;
    dac_shift = (uint16_t)((dac_shift << 8) | v);
    int div = 4 << (((a->data[spi->r_spcr] & 3)) * 2); /* SPR1:0 -> /4 /16 /64 /128 */
    if ((a->data[spi->r_spcr] & 3) == 3) div = 128;
    if (a->data[spi->r_spsr] & 1) div /= 2; /* SPI2X */
    avr_cycle_timer_register(a, 8 * div, spi_done, NULL);
}

static void dac_cs(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    if (value) { /* CS rising: the MCP4921 latches the last 16 bits */
        uint16_t code = dac_shift & 0x0FFF;
        if (!(dac_shift & 0x1000)) code = 2048; /* shut down: output pulled to 0 V by the stage */
        v_dac = (2048.0 - code) * 10.0 / 2048.0; /* the inverting op-amp stage of firmware/README.md */
        set_voltage();
    }
}

static void amp_enable(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    int on = value && (avr->data[0x21] & 1); /* DDRA bit 0: an input is held low by the pull-down */
    if (on != amp_enabled) {
        amp_enabled = on;
        say(on ? "motor enabled" : "motor off (amplifier disabled)");
        set_voltage();
        /* The pendulum's hand lets go when the motor pushes; the seesaw's when the motor is enabled (level,
         * with the cart centred, the controller may well command 0 V). */
        if (seesaw && held && on) {
            advance_to(avr->cycle);
            release();
            restart_steps();
        }
    }
}

static long ticks_seen;
static void tick_pin(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)value;
    (void)param;
    ticks_seen++;
    if (trace) fprintf(trace, "tick,%llu,%ld,%ld\n", (unsigned long long)avr->cycle, enc[0].count, enc[1].count);
}

/* ------------------------------------------------------------------ UART <-> pseudo-terminal */
static int master = -1, slave = -1;
static unsigned char in_buf[4096];
static size_t in_len, in_pos;
static int xoff = 1; /* until the firmware enables its receiver (simavr drops bytes before) */
static avr_irq_t *uart_in;
static unsigned char out_buf[256];
static size_t out_len;
static long bytes_in, bytes_out;

static void flush_out(void) {
    size_t off = 0;
    while (off < out_len) {
        ssize_t n = write(master, out_buf + off, out_len - off);
        if (n <= 0) break; /* nobody reads: drop, as a UART with no listener does */
        off += (size_t)n;
    }
    out_len = 0;
}

static unsigned char corrupt(unsigned char b) {
    if (byte_error_rate > 0 && urand() < byte_error_rate) b ^= (unsigned char)(1u << (rnd() % 8));
    return b;
}

static void uart_out(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    bytes_out++;
    out_buf[out_len++] = corrupt((unsigned char)value);
    if (value == 0 && trace) fprintf(trace, "tx,%llu,%.6f\n", (unsigned long long)avr->cycle, wall() - wall0);
    if (value == 0 || out_len == sizeof out_buf) flush_out();
}

/* The host's frames as the person sees them: only ZERO matters (the lab zeroes, then the person raises). */
static unsigned char host_frame[80];
static size_t host_len;
static void watch_host(unsigned char b) {
    if (b != 0) {
        if (host_len < sizeof host_frame) host_frame[host_len++] = b;
        return;
    }
    /* COBS-decode enough to read the type byte */
    if (host_len >= 2 && host_frame[0] > 1 && host_frame[1] == 0x04 && zeroed_at < 0) {
        zeroed_at = now_s();
    }
    host_len = 0;
}

static void feed_uart(void) {
    while (!xoff && in_pos < in_len) {
        unsigned char b = in_buf[in_pos++];
        if (trace && b == 0) fprintf(trace, "rx,%llu,%.6f\n", (unsigned long long)avr->cycle, wall() - wall0);
        avr_raise_irq(uart_in, b);
    }
    if (in_pos == in_len) in_pos = in_len = 0;
}

static void uart_xon(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)value;
    (void)param;
    xoff = 0;
    feed_uart();
}
static void uart_xoff(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    xoff = value ? 1 : 0;
}

static void read_host(void) {
    if (in_len >= sizeof in_buf) return;
    ssize_t n = read(master, in_buf + in_len, sizeof in_buf - in_len);
    if (n > 0) {
        if (connected_at < 0) {
            connected_at = now_s();
            say("host connected");
        }
        for (ssize_t i = 0; i < n; i++) {
            watch_host(in_buf[in_len + i]);
            in_buf[in_len + i] = corrupt(in_buf[in_len + i]);
        }
        in_len += (size_t)n;
        bytes_in += n;
    }
}

static void link_io(void) {
    flush_out();
    read_host();
    feed_uart();
}

/* ------------------------------------------------------------------ pacing: AVR time = wall time */
static long lags;
static double wall(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void pacing(void) {
    /* Wait for the wall clock, reading the host's bytes as they come; poll() sleeps, it does not spin. */
    double target = wall0 + now_s();
    for (;;) {
        double left = target - wall();
        if (left <= 0) break;
        struct pollfd pfd = {master, POLLIN, 0};
        struct timespec ts = {0, (long)(left * 1e9)};
        if (ppoll(&pfd, 1, &ts, NULL) > 0) {
            read_host();
            feed_uart();
        }
    }
    if (wall() - target > 3e-4) { /* fell behind (descheduled, overload): never race to catch up, which would squeeze the host's time */
        lags++;
        wall0 = wall() - now_s();
    }
}

/* ------------------------------------------------------------------ the person and the faults */
static avr_irq_t *fault_pin, *seesaw_pin;
static avr_flashaddr_t dead_loop;

static void porta_external(void) {
    /* Port A's pins driven from outside: the seesaw's jumper to GND (PA6), the amplifier's fault (PA5). In
     * simavr 1.6 an internal pull-up re-raises a plain input pin at every write to its port; an 'external'
     * value wins over it (one setting per port: both pins in it). */
    avr_ioport_external_t e = {.name = 'A', .mask = (uint8_t)((seesaw ? 1 << 6 : 0) | (faulted ? 1 << 5 : 0)), .value = 0};
    avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL('A'), &e);
    if (seesaw) avr_raise_irq(seesaw_pin, 0);
}

static void seesaw_person(double t, double since) {
    /* The seesaw's operator lifts it level (raise_after s after the host connects, whether or not the host has
     * zeroed: the tilt encoder must be zeroed level, "hold it level, then start"), holds it, lets go when the
     * motor is enabled. */
    if (raise_after >= 0 && !raised_done && !raising && since >= raise_after) {
        raising = 1;
        raise_at = t;
        lift_from[0] = state[0];
        lift_from[1] = state[2];
        say("a person lifts the seesaw level off its tilt stop (%.1f s) and centres the cart (from x = %+.3f m); held until the motor "
            "is enabled", LIFT_TIME, state[0]);
    }
    if (raising && t >= raise_at + LIFT_TIME) {
        raising = 0;
        raised_done = 1;
        held = 1;
        say("seesaw lifted level off its tilt stop by hand, cart centred; held until the motor is enabled");
        if (zeroed_at >= 0) say("the host zeroed the encoders before the seesaw was level: its tilt reads off by the difference");
        if (amp_enabled) release(); /* the controller engaged during the lift (the step after this predicts from here) */
    }
}

static void person(double t) {
    double since = connected_at < 0 ? -1 : t - connected_at;
    if (seesaw) {
        seesaw_person(t, since);
    } else if (raise_after >= 0 && !raised_done && !raising && since >= raise_after && zeroed_at >= 0 && t >= zeroed_at + 0.1) {
        raising = 1;
        raise_at = t;
        x_hold = state[0];
        say("a person raises the pendulum (%.1f s) to %.1f deg from upright; held until the motor is enabled", RAISE_TIME,
            HOLD_ANGLE * 180 / M_PI);
    }
    if (raising && t >= raise_at + RAISE_TIME) {
        raising = 0;
        raised_done = 1;
        held = 1;
        say("pendulum raised and held");
        if (amp_enabled && v_applied != 0.0) release(); /* the controller engaged during the last of the raise */
    }
    if (since >= 0 && restart_after >= 0 && since >= restart_after) {
        restart_after = -1;
        say("restart: reset of the MCU (external reset)");
        avr_reset(avr);
    }
    if (since >= 0 && fault_after >= 0 && since >= fault_after && !faulted) {
        faulted = 1;
        porta_external(); /* driven low from outside */
        avr_raise_irq(fault_pin, 0);
        say("amplifier fault input active");
    }
    for (int i = 0; i < 2; i++) {
        if (since >= 0 && enc[i].fault_at >= 0 && since >= enc[i].fault_at && !enc[i].fault) {
            enc[i].fault = enc_fault_kind[i];
            avr_cycle_timer_cancel(avr, edge_timer, &enc[i]);
            if (enc[i].fault == ENC_DEAD) {
                /* Power or cable lost: both channels fall low (the decoder sees at most one more edge). */
                avr_raise_irq(enc[i].a, 0);
                avr_raise_irq(enc[i].b, 0);
            }
            say("%s encoder %s: no more edges", enc[i].name, enc[i].fault == ENC_DEAD ? "dead (both channels low)" : "frozen");
        }
    }
    if (since >= 0 && close_after >= 0 && since >= close_after) {
        say("closing the port (--close-after)");
        exit(0);
    }
    if (hang_after >= 0 && t >= hang_after && !hung && dead_loop) {
        hang_after = -1;
        hung = 1; /* applied between instructions, in main(): the core rewrites pc after timer callbacks */
        say("firmware hung: main loop stuck in a dead loop (interrupts still on)");
        if (getenv("TWIN_LOG")) {
            for (avr_cycle_timer_slot_p t = avr->cycle_timers.timer; t; t = t->next)
                fprintf(stderr, "timer %p param %p when %llu (now %llu) WDTCSR %02x\n", (void *)t->timer, t->param, (unsigned long long)t->when, (unsigned long long)avr->cycle, avr->data[0x60]);
        }
    }
    if (getenv("TWIN_LOG") && hung && ((long)(t * 1e4)) % 20 == 0) {
        for (avr_cycle_timer_slot_p tm = avr->cycle_timers.timer; tm; tm = tm->next)
            fprintf(stderr, "t=%.4f timer %p when %llu (now %llu) pc %x\n", t, (void *)tm->timer, (unsigned long long)tm->when, (unsigned long long)avr->cycle, avr->pc);
    }
    if (duration >= 0 && t >= duration) {
        say("duration reached");
        exit(0);
    }
}

/* ------------------------------------------------------------------ profile: interrupts and sleep */
typedef struct {
    long count;
    avr_cycle_count_t total, max;
} IsrStat;
static IsrStat isr[64];
static struct {
    int vector;
    uint16_t sp;
    avr_cycle_count_t entry;
} stack_[16];
static int depth;
static avr_cycle_count_t idle_begin, idle_end, idle_cycles;
static avr_cycle_count_t run_cycles, sleep_cycles, max_latency[4];
static avr_cycle_count_t prof_from;
static int reset_seen;

static uint16_t sp_now(void) { return avr->data[R_SPL] | (avr->data[R_SPH] << 8); }

static double wall_start;
static double cpu_seconds(void) {
    struct rusage u;
    getrusage(RUSAGE_SELF, &u);
    return u.ru_utime.tv_sec + u.ru_stime.tv_sec + (u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

static void write_profile(void) {
    if (!profile_out) return;
    avr_cycle_count_t span = avr->cycle - prof_from;
    fprintf(profile_out, "{\"avr_s\": %.6f, \"wall_s\": %.6f, \"cpu_s\": %.6f, ", now_s(), wall() - wall_start, cpu_seconds());
    fprintf(profile_out, "\"idle_loop_cycles\": %llu, ", (unsigned long long)idle_cycles);
    fprintf(profile_out, "\"cycles\": %llu, \"run_cycles\": %llu, \"sleep_cycles\": %llu, \"edges\": %ld, \"ticks\": %ld, \"lags\": %ld, \"bytes_in\": %ld, "
            "\"bytes_out\": %ld, \"encoder_latency_max\": [%llu, %llu, %llu, %llu], \"isr\": {",
            (unsigned long long)span, (unsigned long long)run_cycles, (unsigned long long)sleep_cycles, edges_total, ticks_seen, lags, bytes_in, bytes_out,
            (unsigned long long)max_latency[0], (unsigned long long)max_latency[1], (unsigned long long)max_latency[2],
            (unsigned long long)max_latency[3]);
    int first = 1;
    for (int v = 0; v < 64; v++) {
        if (!isr[v].count) continue;
        fprintf(profile_out, "%s\"%d\": {\"count\": %ld, \"total\": %llu, \"max\": %llu}", first ? "" : ", ", v, isr[v].count,
                (unsigned long long)isr[v].total, (unsigned long long)isr[v].max);
        first = 0;
    }
    fprintf(profile_out, "}}\n");
    fclose(profile_out);
    profile_out = NULL;
}

static unsigned *pc_hist;
static void at_exit(void) {
    if (pc_hist) {
        FILE *f = fopen(getenv("TWIN_PC_HIST"), "w");
        for (unsigned i = 0; i < 131072; i++) if (pc_hist[i]) fprintf(f, "%x %u\n", i * 2, pc_hist[i]);
        fclose(f);
    }
    flush_out();
    write_profile();
    if (trace) fclose(trace);
    double w = wall() - wall_start;
    if (w > 0)
        say("twin ends: %.3f s of AVR time in %.3f s (%.2fx real time), %.3f s of CPU", now_s(), w, now_s() / w, cpu_seconds());
}

static void on_signal(int sig) {
    (void)sig;
    exit(0);
}

static void simavr_log(avr_t *a, const int level, const char *fmt, va_list ap) {
    /* simavr's messages go to stderr: stdout carries the port alone, and nobody reads it after that
     * (a full pipe would stop the simulation). */
    if (level > (a ? a->log : LOG_ERROR)) return;
    fprintf(stderr, "[simavr] ");
    vfprintf(stderr, fmt, ap);
}

static void no_sleep(avr_t *a, avr_cycle_count_t how_long) {
    (void)a;
    (void)how_long;
}

static void no_level_polling(void) {
    /* simavr polls a low pin every cycle while INTn is in its (reset) low-level mode; the firmware
     * uses any-edge mode only, so the poll is pure cost. */
    for (int i = 0; i < 8; i++) avr_extint_set_strict_lvl_trig(avr, (uint8_t)i, 0);
}

static void (*core_reset)(avr_t *);
static void on_reset(avr_t *a) {
    if (core_reset) core_reset(a);
    reset_seen = 1;
}

/* ------------------------------------------------------------------ main */
static void usage(const char *why) {
    fprintf(stderr, "twin: %s\n", why);
    exit(2);
}

static int parse_list(const char *s, double *out, int n) {
    int k = 0;
    char *end;
    while (k < n) {
        out[k++] = strtod(s, &end);
        if (end == s) return -1;
        if (*end != ',') break;
        s = end + 1;
    }
    return *end ? -1 : k;
}

int main(int argc, char **argv) {
    const char *firmware = NULL;
    int have_params = 0;
    double given[NP_MAX + 1];
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
#define NEEDV() do { if (!v) usage("missing value"); i++; } while (0)
        if (!strcmp(a, "--params")) { NEEDV(); have_params = parse_list(v, given, NP_MAX + 1); if (have_params < 0) usage("--params needs the plant's parameter vector"); }
        else if (!strcmp(a, "--plant")) {
            NEEDV();
            if (strcmp(v, "pendulum") && strcmp(v, "seesaw")) usage("--plant pendulum or --plant seesaw");
            seesaw = !strcmp(v, "seesaw");
        }
        else if (!strcmp(a, "--raise-after")) { NEEDV(); raise_after = atof(v); }
        else if (!strcmp(a, "--poke")) { NEEDV(); double p[3]; if (parse_list(v, p, 3) != 3) usage("--poke MAG,DUR,START"); poke_mag = p[0]; poke_dur = p[1]; poke_start = p[2]; }
        else if (!strcmp(a, "--seed")) { NEEDV(); seed = (unsigned)strtoul(v, NULL, 10) * 2654435761u + 1; seed_given = 1; }
        else if (!strcmp(a, "--restart-after")) { NEEDV(); restart_after = atof(v); }
        else if (!strcmp(a, "--fault-after")) { NEEDV(); fault_after = atof(v); }
        else if (!strcmp(a, "--close-after")) { NEEDV(); close_after = atof(v); }
        else if (!strcmp(a, "--dead-encoder") || !strcmp(a, "--frozen-encoder")) {
            NEEDV();
            int which = !strncmp(v, "cart,", 5) ? 0 : !strncmp(v, "pendulum,", 9) ? 1 : -1;
            if (which < 0) usage("--dead-encoder / --frozen-encoder WHICH,S (cart or pendulum)");
            enc[which].fault_at = atof(strchr(v, ',') + 1);
            enc_fault_kind[which] = !strcmp(a, "--dead-encoder") ? ENC_DEAD : ENC_FROZEN;
        }
        else if (!strcmp(a, "--byte-error-rate")) { NEEDV(); byte_error_rate = atof(v); }
        else if (!strcmp(a, "--duration")) { NEEDV(); duration = atof(v); }
        else if (!strcmp(a, "--hang-after")) { NEEDV(); hang_after = atof(v); }
        else if (!strcmp(a, "--no-pace")) { pace = 0; }
        else if (!strcmp(a, "--idle")) { NEEDV(); double r[2]; if (parse_list(v, r, 2) != 2) usage("--idle BEGIN,END (byte addresses)"); idle_begin = (avr_cycle_count_t)r[0]; idle_end = (avr_cycle_count_t)r[1]; }
        else if (!strcmp(a, "--trace")) { NEEDV(); trace = fopen(v, "w"); if (!trace) usage("cannot write the trace file"); }
        else if (!strcmp(a, "--profile")) { NEEDV(); profile_out = fopen(v, "w"); if (!profile_out) usage("cannot write the profile file"); }
        else if (!strcmp(a, "--kinematic")) { NEEDV(); double p[3]; if (parse_list(v, p, 3) != 3) usage("--kinematic V,W,T"); kin_v = p[0]; kin_w = p[1]; kin_t = p[2]; kinematic = 1; }
        else if (a[0] == '-') { fprintf(stderr, "twin: unknown option %s\n", a); return 2; }
        else firmware = a;
    }
    if (!firmware) usage("give the firmware (.hex or .elf)");
    if (!have_params) usage("--params is required");
    if (have_params != (seesaw ? SEESAW_NP : PLANT_NP))
        usage(seesaw ? "--params needs the seesaw's parameter vector (SeesawParameters.as_vector())"
                     : "--params needs the plant's parameter vector (PlantParameters.as_vector())");
    memcpy(params, given, sizeof(double) * have_params);
    if (!seed_given) {
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        seed = (unsigned)(ts.tv_nsec ^ (ts.tv_sec << 10) ^ ((unsigned)getpid() << 16));
    }
    if (!seed) seed = 1;
    if (seesaw) {
        params[S_tap_magnitude] = 0.0; /* the person taps, not the model's default tap */
        params[S_q_theta] = 0.0;       /* quantization happens in the encoders */
        params[S_q_x] = 0.0;
        angle_zero = 0.0;              /* the tilt encoder reads 0 level ... */
        angle_cpr = PEND_CPR * SEESAW_GEAR;
        state[2] = -params[S_theta_stop]; /* ... and the seesaw rests on a tilt stop, as the rig emulator's */
    } else {
        params[P_poke_magnitude] = 0.0; /* the person pokes, not the model's default poke */
        params[P_q_alpha] = 0.0;        /* quantization happens in the encoders */
        params[P_q_x] = 0.0;
    }

    avr_global_logger_set(simavr_log);
    avr = avr_make_mcu_by_name("atmega2560");
    if (!avr) usage("simavr has no atmega2560");
    avr_init(avr);
    avr->frequency = (uint32_t)F_CPU;
    avr->log = getenv("TWIN_LOG") ? LOG_TRACE : LOG_ERROR;
    size_t flen = strlen(firmware);
    if (flen > 4 && !strcmp(firmware + flen - 4, ".elf")) {
        elf_firmware_t f;
        memset(&f, 0, sizeof f);
        if (elf_read_firmware(firmware, &f)) usage("cannot read the firmware ELF");
        f.frequency = (uint32_t)F_CPU;
        avr_load_firmware(avr, &f);
    } else {
        ihex_chunk_p chunks = NULL;
        int n = read_ihex_chunks(firmware, &chunks);
        if (n <= 0) usage("cannot read the firmware .hex");
        for (int i = 0; i < n; i++) {
            if (chunks[i].baseaddr < (1 * 1024 * 1024)) avr_loadcode(avr, chunks[i].data, chunks[i].size, chunks[i].baseaddr);
        }
    }
    avr->frequency = (uint32_t)F_CPU;
    /* Power-up SRAM is random on a real chip (the firmware mixes it into its boot id). */
    for (int i = 0x200; i <= avr->ramend; i++) avr->data[i] = (uint8_t)rnd();
    /* avr-libc's _exit ends in 'cli; rjmp .': its rjmp is the dead loop of --hang-after. */
    for (avr_flashaddr_t a = 0; a + 4 <= avr->flashend; a += 2) {
        if (avr->flash[a] == 0xF8 && avr->flash[a + 1] == 0x94 && avr->flash[a + 2] == 0xFF && avr->flash[a + 3] == 0xCF) {
            dead_loop = a + 2;
            break;
        }
    }
    avr->sleep = no_sleep; /* pacing() keeps AVR time = wall time; sleeping skips idle cycles */
    no_level_polling();
    core_reset = avr->reset;
    avr->reset = on_reset;

    /* SPI: the real clock; the DAC's chip select; the amplifier's enable; the tick pin. */
    spi = (avr_spi_t *)avr->io[AVR_DATA_TO_IO(SPDR_ADDR)].w.param;
    avr->io[AVR_DATA_TO_IO(SPDR_ADDR)].w.c = spdr_write;
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 0), dac_cs, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('A'), 0), amp_enable, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('A'), 1), tick_pin, NULL);
    fault_pin = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('A'), 5);
    avr_raise_irq(fault_pin, 1);
    seesaw_pin = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('A'), 6);
    porta_external();
    for (int i = 0; i < 2; i++) {
        enc[i].a = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), enc[i].pin_a);
        enc[i].b = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), enc[i].pin_a + 1);
    }
    /* UART0 */
    uint32_t flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    uart0 = (avr_uart_t *)avr->io[AVR_DATA_TO_IO(0xC6)].w.param; /* UDR0 */
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), uart_xon, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), uart_xoff, NULL);

    master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) || unlockpt(master)) usage("cannot create a pseudo-terminal");
    const char *path = ptsname(master);
    slave = open(path, O_RDWR | O_NOCTTY); /* kept open: the master never sees EIO when the host closes */
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    printf("%s\n", path);
    fflush(stdout);

    if (getenv("TWIN_PC_HIST")) pc_hist = calloc(131072, sizeof *pc_hist); /* debugging: instructions per address */
    prctl(PR_SET_PDEATHSIG, SIGTERM); /* never outlive the program that started us */
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    atexit(at_exit);
    if (kinematic) kinematic_state(0, state);
    for (int i = 0; i < 2; i++) {
        double u = i == 0 ? state[0] * CART_CPM : (state[2] - angle_zero) * angle_cpr;
        enc[i].count = lround(floor(u + 0.5));
        drive_pins(&enc[i]);
    }
    seg_start = avr->cycle;
    restart_steps();
    say("twin ready: firmware %s in simavr (ATmega2560, 16 MHz), %s, cart centred, motor off", firmware,
        seesaw ? "seesaw on its tilt stop (seesaw jumper PA6 to GND)" : "pendulum hanging");
    wall_start = wall0 = wall();

    for (;;) {
        avr_flashaddr_t pc_before = avr->pc;
        avr_cycle_count_t c_before = avr->cycle;
        int sleeping = avr->state == cpu_Sleeping;
        int st = avr_run(avr);
        if (pc_hist && !(sleeping || avr->state == cpu_Sleeping)) pc_hist[pc_before / 2] += (unsigned)(avr->cycle - c_before);
        /* SLEEP jumps the clock to the next event in the same call that executes it. */
        if (sleeping || avr->state == cpu_Sleeping) sleep_cycles += avr->cycle - c_before;
        else if (pc_before >= idle_begin && pc_before < idle_end) idle_cycles += avr->cycle - c_before;
        else run_cycles += avr->cycle - c_before;
        if (st == cpu_Done || st == cpu_Crashed) {
            say("the AVR stopped (state %d)", st);
            return 1;
        }
        if (hung == 1 && depth == 0) {
            hung = 2;
            avr->pc = dead_loop; /* the main loop hangs, interrupts stay on */
            avr->state = cpu_Running;
            if (trace) fprintf(trace, "hang,%llu\n", (unsigned long long)avr->cycle);
        }
        if (reset_seen) {
            reset_seen = 0;
            depth = 0;
            no_level_polling();
            /* MCUSR (0x54) tells the firmware, and us, what reset it: WDRF is bit 3. */
            say("firmware reset (%s); motor off", (avr->data[0x54] & 0x08) ? "hardware watchdog" : "external reset");
            if (trace) fprintf(trace, "reset,%llu\n", (unsigned long long)avr->cycle);
            hung = 0;
            amp_enabled = 0;
            xoff = 1;
            for (int i = 0; i < 2; i++) drive_pins(&enc[i]);
            avr_raise_irq(fault_pin, faulted ? 0 : 1);
            porta_external();
            set_voltage();
            restart_steps();
            continue;
        }
        /* Interrupt entry: the PC lands on a vector. Exit: the stack is back above the return address. */
        if (avr->pc < 57 * 4 && avr->pc != pc_before && avr->pc != 0 && depth < 16) {
            int v = (int)(avr->pc / 4);
            stack_[depth].vector = v;
            stack_[depth].sp = sp_now();
            stack_[depth].entry = c_before;
            depth++;
            if (v >= 1 && v <= 4) {
                Encoder *e = &enc[(v - 1) / 2];
                avr_cycle_count_t lat = c_before - e->last_edge[0];
                if (e->last_edge[0] && lat > max_latency[v - 1] && lat < 100000) max_latency[v - 1] = lat;
            }
        }
        while (depth > 0 && sp_now() >= stack_[depth - 1].sp + 3) {
            depth--;
            IsrStat *s = &isr[stack_[depth].vector];
            avr_cycle_count_t d = avr->cycle - stack_[depth].entry;
            s->count++;
            s->total += d;
            if (d > s->max) s->max = d;
        }
    }
}

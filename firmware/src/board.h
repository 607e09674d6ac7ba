/* The rig's board: an Arduino Mega 2560 (ATmega2560, 16 MHz). Pin map (Arduino pin in brackets);
 * firmware/README.md has the wiring and the schematic. */
#ifndef BOARD_H
#define BOARD_H

#include <avr/io.h>

/* Encoders, x4 quadrature on the external interrupts INT0..INT3 (any edge). */
#define ENC_PIN      PIND
#define CART_A       PD0 /* INT0 [21] */
#define CART_B       PD1 /* INT1 [20] */
#define PEND_A       PD2 /* INT2 [19] */
#define PEND_B       PD3 /* INT3 [18] */

/* MCP4921 12-bit DAC on the hardware SPI (mode 0, 8 MHz), 4.096 V reference; an inverting op-amp stage
 * makes V_amp = -(V_dac - 2.048 V) * 10 / 2.048, so code 2048 is 0 V and one code is 4.88 mV. */
#define DAC_CS       PB0 /* SS   [53] */
#define DAC_SCK      PB1 /* SCK  [52] */
#define DAC_SDI      PB2 /* MOSI [51] */

/* Port A: the amplifier's enable (a 10 kOhm pull-down holds it off while the MCU is in reset), the tick
 * output (toggles at every sample: scope it), limit switches (normally closed to GND, internal pull-ups),
 * the jumper that says they are fitted, and the amplifier's fault output (open collector, active low). */
#define AMP_ENABLE   PA0 /* [22] out */
#define TICK_OUT     PA1 /* [23] out */
#define LIMIT_LEFT   PA2 /* [24] in, high = open = hit */
#define LIMIT_RIGHT  PA3 /* [25] in, high = open = hit */
#define LIMIT_FITTED PA4 /* [26] in, jumper to GND when the switches are fitted */
#define AMP_FAULT    PA5 /* [27] in, low = amplifier fault */
#define SEESAW       PA6 /* [28] in, jumper to GND on the seesaw (SEESAW-E): its pivot encoder is on the pendulum's
                          * channel behind a 3:1 gear, 3 x 4096 counts per turn of the seesaw */

#define DAC_FULL_SCALE_MV 10000
#define CART_COUNTS_PER_M 43956.04f   /* IP02: 1 count = 22.75 um */
#define PEND_COUNTS_PER_RAD 651.8986f /* 4096 counts per turn */
#define SEESAW_GEAR 3.0f              /* SEESAW-E: the pivot encoder turns 3 times per turn of the seesaw */

#endif

"""`kilolib_api.h`: the Kilobot library's documented declarations, written for this
project from kilolib's published API (the library itself is not shipped here). The
exported C compiles for the ATmega328P against it; a real robot's build links kilolib's
own `kilolib.a`, whose declarations these repeat."""

HEADER = """\
/* kilolib_api.h: the declarations of the Kilobot library (kilolib) that exported
 * swarmdsl programs use, as kilolib documents them. Link the real robot's build with
 * kilolib.a (make hex KILOLIB=path/to/kilolib.a). */
#ifndef KILOLIB_API_H
#define KILOLIB_API_H

#include <stdint.h>

/* Message types; user programs send NORMAL messages. */
typedef enum {
    NORMAL = 0, GPS, BOOT = 0x80, BOOTPGM_PAGE, BOOTPGM_SIZE, RESET, SLEEP, WAKEUP,
    CHARGE, VOLTAGE, RUN, READUID, CALIB
} message_type_t;

/* A message: 9 bytes of payload, its type and a CRC (message_crc). */
typedef struct {
    uint8_t data[9];
    uint8_t type;
    uint16_t crc;
} message_t;

/* The two signal-strength readings of a received message (estimate_distance). */
typedef struct {
    int16_t low_gain;
    int16_t high_gain;
} distance_measurement_t;

typedef void (*message_rx_t)(message_t *, distance_measurement_t *d);
typedef message_t *(*message_tx_t)(void);
typedef void (*message_tx_success_t)(void);

#define RGB(r, g, b) ((r) & 3) | (((g) & 3) << 2) | (((b) & 3) << 4)
#define TICKS_PER_SEC 31

extern volatile uint32_t kilo_ticks;      /* about 31 per second */
extern volatile uint16_t kilo_tx_period;
extern uint16_t kilo_uid;                 /* set at calibration */
extern uint8_t kilo_turn_left;
extern uint8_t kilo_turn_right;
extern uint8_t kilo_straight_left;
extern uint8_t kilo_straight_right;
extern message_rx_t kilo_message_rx;
extern message_tx_t kilo_message_tx;
extern message_tx_success_t kilo_message_tx_success;

uint16_t message_crc(const message_t *msg);
uint8_t estimate_distance(const distance_measurement_t *d);   /* millimetres */
void delay(uint16_t ms);
uint8_t rand_hard(void);
uint8_t rand_soft(void);
void rand_seed(uint8_t seed);
int16_t get_ambientlight(void);
int16_t get_voltage(void);
int16_t get_temperature(void);
void set_motors(uint8_t left, uint8_t right);
void spinup_motors(void);
void set_color(uint8_t color);
void kilo_init(void);
void kilo_start(void (*setup)(void), void (*loop)(void));

#endif
"""

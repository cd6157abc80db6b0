/*
 * A fake board for the core: a settable clock, virtual pins that count every
 * write, and a transmit side that checks every frame the core sends is well
 * formed (optional lone 0x00, valid COBS, delimiter, valid packet) and keeps
 * the last FAKE_MAX_FRAMES of them, decoded, for the tests to inspect. Any
 * malformed frame aborts: the fuzzer relies on that to catch encoder bugs.
 */
#ifndef FAKE_HAL_H
#define FAKE_HAL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "pd_core.h"
#include "protoduino.pb.h"

#define FAKE_MAX_FRAMES 64

typedef struct fake_frame {
    uint8_t type;
    uint8_t seq;
    uint8_t len;
    bool flushed; /* a lone 0x00 went out before it */
    uint8_t payload[PD_MAX_PAYLOAD];
} fake_frame_t;

typedef struct fake_hal {
    uint32_t now_ms;
    bool fail_writes;       /* pd_hal_write refuses every frame */
    uint16_t tx_room;       /* what pd_hal_tx_room reports (fake_init: plenty) */
    size_t n_frames;        /* frames sent since the last fake_clear() (may exceed the ring) */
    fake_frame_t frames[FAKE_MAX_FRAMES];
    int servo_us[PD_MAX_PINS];  /* -1: not a servo */
    int digital[PD_MAX_PINS];   /* -1: not a digital output, else 0/1 */
    int pwm[PD_MAX_PINS];       /* -1: not a PWM output, else its duty */
    unsigned pwm_writes[PD_MAX_PINS];
    /* Inputs: what the tests put at the pins, and how the core configured them. */
    int input[PD_MAX_PINS];      /* -1: not configured as an input, else 0 / 1 = pull-up */
    bool level[PD_MAX_PINS];     /* the level at the pin (the tests set it) */
    unsigned digital_reads;      /* pd_hal_digital_read_all() calls */
    uint16_t analog[PD_MAX_PINS]; /* the counts a conversion of the pin gives */
    int adc_pin;                 /* the conversion under way, -1: none */
    unsigned adc_polls;          /* pd_hal_analog_done() calls before it is done (fake_init: 1) */
    unsigned adc_left;
    unsigned conversions;        /* conversions started */
    int counter_edge[PD_MAX_PINS]; /* -1: not counting, else the Edge */
    uint32_t count[PD_MAX_PINS];
    unsigned servo_writes[PD_MAX_PINS];
    unsigned digital_writes[PD_MAX_PINS];
    unsigned writes;             /* servo, digital and PWM writes since fake_init */
    unsigned written_at[PD_MAX_PINS]; /* `writes` after the pin's last write (0: none): the order */
    unsigned outputs_safe_calls; /* pd_hal_outputs_safe() since fake_init */
    uint8_t baud_rates;          /* what pd_hal_baud_rates() answers (0 after fake_init: none) */
    uint32_t baud;               /* the last pd_hal_set_baud() rate (0: none since fake_init) */
    unsigned baud_sets;          /* pd_hal_set_baud() calls since fake_init */
    bool servo_held;             /* inside pd_hal_servo_hold(true) .. (false) */
    bool servo_pending;          /* pd_hal_servo_pending's answer (a width not yet at its pins) */
    unsigned servo_holds;        /* pd_hal_servo_hold(true) calls since fake_init */
    uint32_t boots;              /* pd_hal_boot_id() calls: the boot id */
    pd_board_info_t info;
} fake_hal_t;

void fake_init(fake_hal_t *hal);
/* Forget the frames sent so far. */
void fake_clear(fake_hal_t *hal);
/* Frame i (0 = oldest kept) of those sent since the last clear, or NULL. */
const fake_frame_t *fake_frame(const fake_hal_t *hal, size_t i);
size_t fake_count(const fake_hal_t *hal);

/* pb_encode's callbacks for DeviceInfo's pin table (pins, timers), written from
 * `hal`'s board as the device's encoder writes them (pd_encode_pin) for a
 * DeviceInfo of num_pins > 0: for comparing the two encoders on a DeviceInfo. */
void fake_info_callbacks(protoduino_DeviceInfo *info, fake_hal_t *hal);

/* OutputStates.servos (a callback field: the device writes it from its outputs' table,
 * pd_outputs_servos) as the tests read and write it: its bytes in a buffer of their own. */
typedef struct fake_servos {
    uint8_t bytes[5u * 24u]; /* the schema's bound: PD_INFO_SERVOS_MAX servos */
    size_t size;
} fake_servos_t;
/* pb_decode's and pb_encode's callbacks for `st`'s servos, reading into and writing from
 * `servos`. */
void fake_servos_callbacks(protoduino_OutputStates *st, fake_servos_t *servos);
/* Decode a DATA payload as pb_decode does, an Ack's OutputStates.servos into `servos`
 * (its size 0 when the message has none): the callback field survives the decoding only
 * when the oneofs around it are already that member, so a ReadOutputs answer is decoded
 * twice. */
/* pb_encode's callback for `st`'s servos, written by the writer the device's OutputStates
 * `device` holds (pd_outputs_read: pd_encode_servos_set), as the device's encoder calls it:
 * for comparing the two encoders. */
void fake_outputs_callbacks(protoduino_OutputStates *st, const protoduino_OutputStates *device);
bool fake_decode_out(const uint8_t *payload, size_t len, protoduino_ArduinoOut *out,
                     fake_servos_t *servos);

#endif /* FAKE_HAL_H */

/*
 * The output registry: which pin is a servo or a digital output, its limits
 * and its safe value (PROTOCOL.md section 7, docs/architecture.md "device
 * semantics"). Every check the device makes on an Init or a Control lives
 * here and returns the Ack status; on any status but OK nothing changed.
 */
#ifndef PD_OUTPUTS_H
#define PD_OUTPUTS_H

#include <stdbool.h>
#include <stdint.h>

#include "pd_hal.h"
#include "protoduino.pb.h"

/* Compile-time capacity; a board reports its real figures in pd_board_info_t. */
#ifndef PD_MAX_PINS
#define PD_MAX_PINS 20
#endif
#ifndef PD_MAX_SERVOS
#define PD_MAX_SERVOS 8
#endif

/* pin_mode values: free, digital, or PD_PIN_SERVO + channel. */
#define PD_PIN_FREE 0u
#define PD_PIN_DIGITAL 1u
#define PD_PIN_SERVO 2u

typedef struct pd_servo {
    uint8_t pin;
    uint16_t min_us;
    uint16_t max_us;
    uint16_t safe_us;
} pd_servo_t;

typedef struct pd_outputs {
    uint8_t pin_mode[PD_MAX_PINS];
    uint8_t servo_count; /* channels 0 .. servo_count - 1 are in use */
    pd_servo_t servo[PD_MAX_SERVOS];
    uint32_t digital_safe;  /* bit N: safe level of pin N */
    uint32_t digital_level; /* bit N: current level of pin N */
} pd_outputs_t;

void pd_outputs_init(pd_outputs_t *out);

protoduino_Status pd_outputs_servo_init(pd_outputs_t *out, void *hal,
                                        const protoduino_ServoInit *msg);
protoduino_Status pd_outputs_servo_control(pd_outputs_t *out, void *hal,
                                           const protoduino_ServoControl *msg);
protoduino_Status pd_outputs_digital_init(pd_outputs_t *out, void *hal,
                                          const protoduino_DigitalInit *msg);
protoduino_Status pd_outputs_digital_control(pd_outputs_t *out, void *hal,
                                             const protoduino_DigitalControl *msg);

/* Drive every configured output to its safe value (failsafe, Stop). */
void pd_outputs_all_safe(pd_outputs_t *out, void *hal);

#endif /* PD_OUTPUTS_H */

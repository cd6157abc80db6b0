/*
 * Build-time features: each pin mode is one, and a build may leave any out
 * (docs/protocol.md section 7, "Features"; firmware/README.md). A feature left
 * out costs no flash and no RAM: its commands are answered
 * STATUS_NOT_SUPPORTED, and DeviceInfo.features lacks its bit, so the host
 * refuses the mode before sending.
 *
 *   make -C firmware avr FEATURES="servo digital_output pwm"   (default: all six)
 *   Arduino library: edit src/pd_config.h of the installed library (the IDE
 *   compiles a library's files without the sketch's #defines).
 */
#ifndef PD_FEATURES_H
#define PD_FEATURES_H

#if defined(ARDUINO) || defined(PD_CONFIG_H_WANTED)
#include "pd_config.h"
#endif

#ifndef PD_FEATURE_SERVO
#define PD_FEATURE_SERVO 1
#endif
#ifndef PD_FEATURE_DIGITAL_OUTPUT
#define PD_FEATURE_DIGITAL_OUTPUT 1
#endif
#ifndef PD_FEATURE_DIGITAL_INPUT
#define PD_FEATURE_DIGITAL_INPUT 1
#endif
#ifndef PD_FEATURE_ANALOG_INPUT
#define PD_FEATURE_ANALOG_INPUT 1
#endif
#ifndef PD_FEATURE_PWM
#define PD_FEATURE_PWM 1
#endif
#ifndef PD_FEATURE_COUNTER
#define PD_FEATURE_COUNTER 1
#endif

/* User services (docs/services.md): UserCall and UserReport, with the service
 * table the generator writes (pd_user.h). Off by default: a firmware carries it
 * only when built with a user's .proto (make USER_PROTO=..., or the Arduino
 * library's pd_config.h), so the default firmware pays nothing for it. */
#ifndef PD_FEATURE_USER
#define PD_FEATURE_USER 0
#endif

/* DeviceInfo.features: bit N set for each Feature N built in (protoduino.proto, enum Feature). */
#define PD_FEATURES                                                          \
    ((PD_FEATURE_SERVO ? 1u << 1 : 0u) | (PD_FEATURE_DIGITAL_OUTPUT ? 1u << 2 : 0u) |   \
     (PD_FEATURE_DIGITAL_INPUT ? 1u << 3 : 0u) | (PD_FEATURE_ANALOG_INPUT ? 1u << 4 : 0u) | \
     (PD_FEATURE_PWM ? 1u << 5 : 0u) | (PD_FEATURE_COUNTER ? 1u << 6 : 0u) |   \
     (PD_FEATURE_USER ? 1u << 7 : 0u))

#endif /* PD_FEATURES_H */

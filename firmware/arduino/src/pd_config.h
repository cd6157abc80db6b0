/*
 * The Arduino library's build-time features (firmware/core/pd_features.h) and
 * its opening line rate.
 * The IDE compiles a library's files without the sketch's #defines, so a
 * feature is left out here, in the installed library's src/pd_config.h:
 * set its line to 0 (it then costs no flash and no RAM, and the device
 * answers its commands STATUS_NOT_SUPPORTED).
 */
#ifndef PD_CONFIG_H
#define PD_CONFIG_H

#define PD_FEATURE_SERVO 1
#define PD_FEATURE_DIGITAL_OUTPUT 1
#define PD_FEATURE_DIGITAL_INPUT 1
#define PD_FEATURE_ANALOG_INPUT 1
#define PD_FEATURE_PWM 1
#define PD_FEATURE_COUNTER 1
/* A user service (docs/services.md): 1 when the sketch carries one (its generated
 * files and handlers in the sketch's folder, as the ProtoduinoService example). */
#define PD_FEATURE_USER 0

/* The opening line rate (docs/protocol.md section 1): the host opens the port at
 * it (Board.open(baudrate=...) for another than 115200) and may then agree on a
 * faster one. */
#define PD_BAUD 115200UL

#endif /* PD_CONFIG_H */

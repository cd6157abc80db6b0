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

/* The board: the IDE passes no per-library flags, so the library tells it from what the IDE
 * compiles for, as `make avr BOARD=...` does from its BOARD_FLAGS (firmware/Makefile):
 * -mmcu=atmega2560 (__AVR_ATmega2560__) is the Mega 2560; the Nano (boards.txt's
 * build.board, ARDUINO_AVR_NANO) is the Uno's chip with A6 and A7 (pins 20 and 21). */
#if !defined(PD_BOARD_MEGA) && !defined(PD_BOARD_NANO)
#if defined(__AVR_ATmega2560__)
#define PD_BOARD_MEGA 1 /* its capacities: core/pd_caps.h */
#elif defined(ARDUINO_AVR_NANO)
#define PD_BOARD_NANO 1
#endif
#endif

#endif /* PD_CONFIG_H */

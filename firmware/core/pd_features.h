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

/* Each Feature of proto/protoduino.proto's enum is a PD_FEATURE_<NAME> switch,
 * 1 (0 for one declared off by default) unless the build defined it (make's
 * FEATURES, or the Arduino library's pd_config.h, which pd_tables.h includes
 * first), and PD_FEATURES is
 * DeviceInfo.features: bit N set for each Feature N built in. Both are
 * generated from the schema by `protoduino gen`. */
#include "pd_caps.h" /* first: a board's PD_MAX_SERVOS before the default below */
#include "pd_tables.h"

/* The servos' compile-time capacity (8; the Mega's build 24: firmware/Makefile); a board
 * reports its real figure in pd_board_info_t.max_servos (PD_MAX_PINS: pd_hal.h). Here, below
 * the encoder, whose bound of a ReadOutputs answer counts them (pd_encode.h). */
#ifndef PD_MAX_SERVOS
#define PD_MAX_SERVOS 8
#endif
/* A build without servos keeps one slot (the code stays simple), not eight. */
#if !PD_FEATURE_SERVO
#undef PD_MAX_SERVOS
#define PD_MAX_SERVOS 1
#endif

#endif /* PD_FEATURES_H */

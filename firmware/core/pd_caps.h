/*
 * pd_caps.h: a board's capacities in the portable core, stated once.
 *
 * Each capacity's default is the Uno's, in the header that uses it (PD_MAX_PINS in
 * pd_pinset.h, PD_MAX_SERVOS in pd_features.h, PD_MAX_PWM in pd_pwm.h, PD_SLOT_BITS in
 * pd_pintable.h, PD_MAX_TIMERS in pd_encode.h), and each of those headers includes this one
 * first, so that every file of a build sees the same sizes. The Mega's (PD_CAPS_MEGA: the
 * Mega build, `make avr BOARD=mega`; the simulated board, which serves the Uno's pins and
 * the Mega's; the C tests' unit-mega) and the Nano's (PD_BOARD_NANO) are set here. The
 * Arduino library tells the board from what the IDE compiles for (its pd_config.h).
 */
#ifndef PD_CAPS_H
#define PD_CAPS_H

#if defined(ARDUINO) || defined(PD_CONFIG_H_WANTED)
#include "pd_config.h"
#endif

#if defined(PD_BOARD_MEGA) && PD_BOARD_MEGA && !defined(PD_CAPS_MEGA)
#define PD_CAPS_MEGA 1
#endif

#if defined(PD_CAPS_MEGA) && PD_CAPS_MEGA
/* 70 pins, 24 servos on Timers 1 and 5 (5 bits of slot in the pin table's owner byte), 6
 * timers in DeviceInfo, 6 PWM outputs at once (firmware/README.md, The Mega 2560). */
#define PD_MAX_PINS 70
#define PD_MAX_SERVOS 24
#define PD_SLOT_BITS 5
#define PD_MAX_TIMERS 6
#define PD_MAX_PWM 6
#elif defined(PD_BOARD_NANO) && PD_BOARD_NANO
#define PD_MAX_PINS 22 /* the Uno's 20 and A6, A7 (analog inputs only) */
#endif

#endif /* PD_CAPS_H */

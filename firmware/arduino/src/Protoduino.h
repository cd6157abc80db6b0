/*
 * protoduino as an Arduino library: the same firmware as `make -C firmware
 * avr`, assembled by `make -C firmware arduino-lib` (which adds the core, the
 * generated messages and the nanopb runtime next to this header).
 *
 * It owns the UART (pins 0 and 1: do not use Serial) and Timer1 (servo pulses:
 * do not use the Servo library); millis() and the rest of the core stay yours.
 *
 * Your own commands (docs/services.md): put what `protoduino gen robot.proto`
 * writes and your handlers in the sketch's folder and set PD_FEATURE_USER to 1
 * in this library's src/pd_config.h; the example ProtoduinoService does so.
 */
#ifndef PROTODUINO_H
#define PROTODUINO_H

#ifdef __cplusplus
extern "C" {
#endif

void pd_avr_setup(void);
void pd_avr_loop(void);

#ifdef __cplusplus
}
#endif

/* Call once from setup(): starts the UART at PD_BAUD (pd_config.h: 115200 unless changed there;
 * the host may agree on a faster rate) and the servo timer. */
static inline void protoduino_begin(void)
{
    pd_avr_setup();
}

/* Call from loop() as often as possible (it sleeps until the next interrupt). */
static inline void protoduino_poll(void)
{
    pd_avr_loop();
}

#endif /* PROTODUINO_H */

/*
 * nanopb's decoder for the Uno: its pb_decode.c, unchanged, compiled here (the Uno
 * build leaves the file itself out: firmware/Makefile) with two of its static
 * functions kept out of line by the declarations below (GCC adds their attribute to
 * nanopb's own declarations).
 *
 * decode_extension and decode_callback_field run only for a message with extensions or
 * callback fields: protoduino's have none, and a user service's messages are bounded
 * (static) ones. Inlined, as the compiler did, their locals sat in the frames of every
 * level of every nested decode: decode_extension's pb_field_iter_t (27 B) and more in
 * each pb_decode_inner (78 B of locals, now 48), decode_callback_field's 10-byte buffer
 * and substream in each decode_field (33 B, now 27). A Pose decoded in full (ArduinoIn,
 * Pose, PoseItem, ServoControl: four levels) is the Uno's deepest stack
 * (tests/e2e/test_stack_margin.py): a level 125 B where it was 163, 152 B less in all,
 * for 38 B of flash.
 *
 * The Arduino IDE build compiles nanopb's pb_decode.c itself (it compiles every file of
 * the library, and this one is empty there): its decode takes the 38 B a level more.
 */
#ifndef ARDUINO

#include <pb_decode.h>

static bool decode_extension(pb_istream_t *stream, uint32_t tag, pb_wire_type_t wire_type,
                             pb_extension_t *extension) __attribute__((noinline));
static bool decode_callback_field(pb_istream_t *stream, pb_wire_type_t wire_type,
                                  pb_field_iter_t *field) __attribute__((noinline));

#include <pb_decode.c>

#endif

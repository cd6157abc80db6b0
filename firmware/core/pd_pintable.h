/*
 * The pin table: which pin belongs to which pin mode (docs/architecture.md,
 * "the pin table and the pin modes"). One byte per pin, the mode that owns it
 * and the slot of that mode's state it uses (a servo's channel). Every mode
 * claims and looks up its pins here, so "pin in use by another mode", "not
 * initialised" and a re-init keeping its slot are decided in one place for
 * all of them.
 *
 * The table knows no mode: a mode is a number, and what a mode does with its
 * pins (its state, its safe value, its release) is the mode's own file's; the
 * walks over every owned pin (Release, ReleaseAll, the safe-all) are
 * pd_outputs.c's, above the modes. So the table calls nothing but the HAL's
 * board facts, and every mode (the outputs, the inputs, a user service) calls
 * down into it.
 */
#ifndef PD_PINTABLE_H
#define PD_PINTABLE_H

#include <stdint.h>

#include "pd_caps.h" /* first: a board's PD_SLOT_BITS before the default below */
#include "pd_features.h"
#include "pd_hal.h"
#include "pd_tables.h"
#include "protoduino.pb.h"

/* Pin modes: the built-in ones, PD_MODE_<NAME> numbered from 1 up to
 * PD_MODE_BUILTIN_END - 1 (PD_MODE_FREE, 0, owns nothing), are generated into
 * pd_tables.h from the (pin_mode) options on proto/protoduino.proto's enum
 * Feature; a mode the firmware has of its own would follow them. PD_MODES in
 * pd_outputs.c has one entry for each mode. */
/* A user service's pins (pd_user.h), in a build with one: its hooks drive them safe and
 * release them. */
#define PD_MODE_USER PD_MODE_BUILTIN_END
#define PD_MODE_COUNT (PD_MODE_BUILTIN_END + (PD_FEATURE_USER ? 1 : 0))

/* An owner byte: mode in the high bits, slot in the low PD_SLOT_BITS (one byte per pin of
 * RAM): 4 and 4, or 3 and 5 in the Mega's build (firmware/Makefile), whose 24 servo
 * channels need them and whose modes (7 at most) still fit. */
#ifndef PD_SLOT_BITS
#define PD_SLOT_BITS 4u
#endif
#define PD_OWNER(mode, slot) ((uint8_t)(((mode) << PD_SLOT_BITS) | (slot)))
#define PD_OWNER_MODE(owner) ((uint8_t)((owner) >> PD_SLOT_BITS))
#define PD_OWNER_SLOT(owner) ((uint8_t)((owner) & ((1u << PD_SLOT_BITS) - 1u)))
#define PD_MAX_SLOTS (1u << PD_SLOT_BITS)
/* A set of a mode's slots, bit S for slot S: wide enough for PD_MAX_SLOTS. */
#if PD_SLOT_BITS > 4
typedef uint32_t pd_slots_t;
#else
typedef uint16_t pd_slots_t;
#endif

/* Pin checks shared by every Init and Control, in the contract's order: the
 * pin exists on this board (else STATUS_INVALID_PIN) and is not reserved
 * (STATUS_RESERVED_PIN). */
protoduino_Status pd_pins_check(void *hal, uint32_t pin);

/*
 * Claim `pin` of the table `owner` (PD_MAX_PINS bytes) for `mode`: checks the
 * pin exists and is not reserved, that it has digital I/O unless `mode` is
 * PD_MODE_ANALOG_INPUT, that no other mode owns it, and finds its slot (the one
 * it has on a re-init, else the lowest free one of the mode's `slots`; 0
 * slots: the mode keeps its state by pin, any number of its pins may be
 * claimed). Returns the Ack status; on OK *slot is set and the pin is owned by
 * `mode` (the caller must not fail after this).
 */
protoduino_Status pd_pins_claim(uint8_t *owner, void *hal, uint32_t pin, uint8_t mode,
                                uint8_t slots, uint8_t *slot);

/* For a Control: `pin` must exist, not be reserved and be owned by `mode`. */
protoduino_Status pd_pins_owned(const uint8_t *owner, void *hal, uint32_t pin, uint8_t mode,
                                uint8_t *slot);

/* How many pins `mode` owns. */
uint8_t pd_pins_count(const uint8_t *owner, uint8_t mode);

#endif /* PD_PINTABLE_H */

/*
 * User services (docs/services.md, docs/protocol.md section 7 "User services"):
 * the user's own commands and reports, declared in the user's .proto, carried
 * in UserCall / Ack.user_reply / UserReport as bytes of the user's schema and
 * decoded here with the user's nanopb descriptors.
 *
 * The generator (`protoduino gen robot.proto --out DIR`) writes the service
 * table, pd_user_service, and the handler prototypes; the user writes the
 * handlers. A user call runs through the same per-command path as the built-ins
 * (pd_dispatch.c: the dedupe window, one Ack, the failsafe and interlock
 * refusals), so it is acknowledged and executed exactly once.
 *
 * Handlers reach the board through pd_hal.h only (so the same handler runs on
 * the simulated board and on the Uno), claim the pins they drive in the pin
 * table (pd_user_claim: a built-in mode and a handler never drive one pin at
 * once), and the service's `safe` hook drives a claimed pin to its safe state
 * whenever the failsafe, a Stop or an interlock makes every output safe.
 *
 * Time: a handler runs between a command's delimiter and its Ack, and the
 * main loop (servo steps, inputs, the failsafe check) waits for it: keep it
 * under a millisecond; work that takes longer goes into the `poll` hook, one
 * slice per pass of the loop.
 *
 * Built only with PD_FEATURE_USER (pd_features.h); the default firmware has none of it.
 */
#ifndef PD_USER_H
#define PD_USER_H

#include <stdbool.h>
#include <stdint.h>

#include <pb.h>

#include "pd_features.h"
#include "pd_hal.h"
#include "protoduino.pb.h"

struct pd_core;

/* What a handler, a report or the poll hook gets: the device and its HAL. */
typedef struct pd_user_ctx {
    struct pd_core *core;
    void *hal; /* for the pd_hal_* calls */
} pd_user_ctx_t;

/* A method's handler: `request` is the decoded request message, `reply` the
 * zeroed reply message to fill. Returns 0 (done) or the user's error code,
 * 1..255 (the user's error enum: nothing was done; the host raises its named error). */
typedef uint8_t (*pd_user_handler_fn)(pd_user_ctx_t *ctx, const void *request, void *reply);

/* A report: fill the zeroed report message with the newest value; false: nothing to send. */
typedef bool (*pd_user_report_fn)(pd_user_ctx_t *ctx, void *report);

/* A claimed pin's safe state, or its release (back to an input without pull-up). `ctx`
 * as a handler's: the hook may publish a report (pd_user_publish) or read the time. */
typedef void (*pd_user_pin_fn)(pd_user_ctx_t *ctx, uint8_t pin);

/* Periodic work, every pass of the main loop (at least every few ms). */
typedef void (*pd_user_poll_fn)(pd_user_ctx_t *ctx, uint32_t now_ms);

/* Method flags (the generator takes them from the rpc's idempotency_level). */
#define PD_USER_IDEMPOTENT 0x01u /* no side effects: kept out of the dedupe window */
#define PD_USER_COMMANDS 0x02u   /* drives outputs: refused while the failsafe or an interlock holds */

/* One rpc of the user's service, in declaration order (method number = index + 1). */
typedef struct pd_user_method {
    const pb_msgdesc_t *request; /* NULL: a report (a server-streaming rpc) */
    const pb_msgdesc_t *reply;   /* the reply, or the report's message */
    pd_user_handler_fn handler;  /* a call's handler (NULL for a report) */
    pd_user_report_fn report;    /* a report's builder (NULL for a call) */
    uint8_t flags;
} pd_user_method_t;

/* Reports a service may have (one pending bit each, one coalesced counter each). */
#define PD_USER_MAX_REPORTS 8u

typedef struct pd_user_service {
    uint32_t fingerprint; /* CRC-32 of the user schema (DeviceInfo.user_fingerprint) */
    uint8_t method_count;
    const pd_user_method_t *methods;
    /* Scratch sized by the generator: the largest request, and the largest
     * reply or report message, of this service. */
    void *request_buf;
    uint16_t request_size;
    void *reply_buf;
    uint16_t reply_size;
    pd_user_pin_fn safe;    /* required if the service claims pins */
    pd_user_pin_fn release; /* NULL: pd_hal_digital_release */
    pd_user_poll_fn poll;   /* NULL: none */
} pd_user_service_t;

/* Written by the generator (DIR/<name>_service.c); the firmware links the one service. */
extern const pd_user_service_t pd_user_service;

/* The core's per-device state of the service's reports. */
typedef struct pd_user_state {
    uint8_t pending; /* bit N: report method N (counted among the reports) has a new value */
    uint16_t coalesced[PD_USER_MAX_REPORTS];
} pd_user_state_t;

/* --- for handlers and the poll hook --------------------------------------- */

/*
 * Claim `pin` for the service (as an Init does for a built-in mode): refused
 * with the status an Init would get (STATUS_INVALID_PIN, STATUS_RESERVED_PIN,
 * STATUS_PIN_IN_USE when a built-in mode has it). A claimed pin is the
 * service's until pd_user_release, Release, ReleaseAll or a new session, which
 * call its `release` hook; the failsafe, Stop and interlocks call its `safe` hook.
 */
protoduino_Status pd_user_claim(pd_user_ctx_t *ctx, uint8_t pin);

/*
 * Release `pin`, which the service claimed, as a Release command would: the service's
 * `release` hook runs (the pin no longer the service's there), and the pin is free for
 * any mode. STATUS_NOT_INITIALISED, changing nothing, for a pin the service does not hold
 * (never a built-in's).
 */
protoduino_Status pd_user_release(pd_user_ctx_t *ctx, uint8_t pin);

/* Whether the service holds `pin` (it may have been released since its claim). */
bool pd_user_owns(const pd_user_ctx_t *ctx, uint8_t pin);

/* Whether the outputs must stay safe now (the failsafe fired, or an interlock latched). */
bool pd_user_outputs_held(const pd_user_ctx_t *ctx);

/* Report method `method` (its number in the service) has a new value: sent when the
 * line allows, built then by its report function (newest wins). */
void pd_user_publish(pd_user_ctx_t *ctx, uint8_t method);

/* --- for the core ------------------------------------------------------ */

/* The flags of method `method` (0 for a method the service does not have). */
uint8_t pd_user_flags(uint8_t method);

/* Run a UserCall: its Ack's status; on OK the reply is in ack->result.user_reply. */
protoduino_Status pd_user_call(struct pd_core *core, const protoduino_UserCall *call,
                               protoduino_Ack *ack);

void pd_user_init(struct pd_core *core);
void pd_user_poll(struct pd_core *core, uint32_t now);

#if PD_FEATURE_USER
/* The user mode of the pin table (pd_pintable.h): a claimed pin to the service's safe
 * state, or released: no longer the service's in `owner` (the table) already as its hook
 * runs, then by default an input without pull-up, as at power-up. Called by the walks over
 * every owned pin (pd_outputs.c), and by pd_user_release. Inline here, with the service's
 * types: the walks sit below the modules that act on the whole device. */
static inline void pd_user_pin_safe(struct pd_core *core, void *hal, uint8_t pin)
{
    pd_user_ctx_t ctx = {core, hal};
    if (pd_user_service.safe != NULL) {
        pd_user_service.safe(&ctx, pin);
    }
}

static inline void pd_user_pin_release(struct pd_core *core, uint8_t *owner, void *hal,
                                       uint8_t pin)
{
    pd_user_ctx_t ctx = {core, hal};
    owner[pin] = 0;
    if (pd_user_service.release != NULL) {
        pd_user_service.release(&ctx, pin);
    } else {
        pd_hal_digital_release(hal, pin);
    }
}
#endif

/* The user reports' share of the core's report callbacks (pd_core.c gives the other slots
 * to the inputs): fill `out` with the next pending user report (false: none), and that
 * UserReport went out. */
bool pd_user_report(struct pd_core *core, protoduino_ArduinoOut *out);
void pd_user_sent(struct pd_core *core, const protoduino_ArduinoOut *out);

/* The user reports' slot of the core (pd_core.h; the inputs have slot 0). */
#define PD_USER_SLOT 1u

#endif /* PD_USER_H */

#include "pd_failsafe.h"

#include "pd_protocol.h"
#include "protoduino.pb.h"

/* Not inlined: LTO put a copy in pd_core_init and one in pd_core_open_session
 * (50 B of the Uno's flash); neither is on the command path. */
__attribute__((noinline)) void pd_failsafe_init(pd_failsafe_t *fs, uint32_t now_ms)
{
    fs->alive_ms = now_ms;
    fs->timeout_ms = PD_FAILSAFE_TIMEOUT_MS;
    fs->fired = false;
    fs->active = false;
    fs->heartbeat_only = false;
}

uint8_t pd_failsafe_alive(pd_failsafe_t *fs, uint32_t now_ms, uint8_t epoch)
{
    if (epoch != fs->epoch) {
        return PD_ALIVE_STALE; /* sent before the latest safe state: not a sign of life after it */
    }
    bool was_active = fs->active;
    fs->alive_ms = now_ms;
    fs->fired = false;
    fs->active = false;
    return was_active ? PD_ALIVE_CLEARED : PD_ALIVE_OK;
}

void pd_failsafe_restart(pd_failsafe_t *fs, uint32_t now_ms)
{
    if (!fs->fired) {
        fs->alive_ms = now_ms;
    }
}

bool pd_failsafe_expired(const pd_failsafe_t *fs, uint32_t now_ms)
{
    return (uint32_t)(now_ms - fs->alive_ms) >= fs->timeout_ms;
}

bool pd_failsafe_due(const pd_failsafe_t *fs, uint32_t now_ms)
{
    return !fs->fired && pd_failsafe_expired(fs, now_ms);
}

void pd_failsafe_fire(pd_failsafe_t *fs)
{
    fs->fired = true;
    fs->active = true;
    fs->epoch++;
    fs->cause = protoduino_FailsafeCause_FAILSAFE_CAUSE_PING_TIMEOUT;
}

void pd_failsafe_stop(pd_failsafe_t *fs)
{
    fs->active = true;
    fs->epoch++;
    fs->cause = protoduino_FailsafeCause_FAILSAFE_CAUSE_STOP;
}

void pd_failsafe_interlock(pd_failsafe_t *fs, uint8_t pin)
{
    fs->active = true;
    fs->epoch++;
    fs->cause = protoduino_FailsafeCause_FAILSAFE_CAUSE_INTERLOCK;
    fs->pin = pin;
}

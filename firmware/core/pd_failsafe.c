#include "pd_failsafe.h"

#include "pd_protocol.h"

void pd_failsafe_init(pd_failsafe_t *fs, uint32_t now_ms)
{
    fs->alive_ms = now_ms;
    fs->active = false;
}

void pd_failsafe_restart(pd_failsafe_t *fs, uint32_t now_ms)
{
    fs->alive_ms = now_ms;
}

bool pd_failsafe_ping(pd_failsafe_t *fs, uint32_t now_ms)
{
    bool was_active = fs->active;
    fs->alive_ms = now_ms;
    fs->active = false;
    return was_active;
}

bool pd_failsafe_due(const pd_failsafe_t *fs, uint32_t now_ms)
{
    return !fs->active && (uint32_t)(now_ms - fs->alive_ms) >= PD_FAILSAFE_TIMEOUT_MS;
}

void pd_failsafe_set(pd_failsafe_t *fs)
{
    fs->active = true;
}

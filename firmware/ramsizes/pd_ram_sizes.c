/*
 * pd_ram_sizes.c: not part of the firmware. Compiled for the Uno with the firmware's own
 * flags (`make -C firmware avr-ram-sizes`), it defines one array per part of the core's
 * state, each exactly as large as that part, so that `avr-nm -S` on the object reads the
 * sizes the Uno build has (the firmware's ELF names only the whole `core`).
 * protoduino_dev.rambudget.static_ram_parts() reads them: firmware/README.md's figures,
 * written by `python -m bench` and checked by tests/c/test_footprint.py.
 */
#include "pd_state.h"

#define PD_SIZE(name, part) extern const char pd_size_##name[]; \
    const char pd_size_##name[sizeof(part)] = {0}

PD_SIZE(core, pd_core_t);
PD_SIZE(packet, ((pd_core_t *)0)->link.rx_buf);
PD_SIZE(command, ((pd_core_t *)0)->in);
PD_SIZE(dedupe, ((pd_core_t *)0)->dedupe);
PD_SIZE(outputs, ((pd_core_t *)0)->outputs);
PD_SIZE(inputs, ((pd_core_t *)0)->outputs.inputs);

/*
 * clocks: an FMU that offers only FMI 3.0 Scheduled Execution (model partitions activated by clocks,
 * like the Reference FMU "Clocks"). cosim runs co-simulation FMUs, so it must refuse this one at
 * validate with a message that says what the FMU offers; the binary exists so that the refusal is
 * about the interface, not a missing file.
 */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

struct Model {
    double time;
    bool tick;
    int32_t ticks;
};

#include "../fmi3_runtime.c"

static bool model_variable(Instance *I, fmi3ValueReference vr, Var *v) {
    I->m.time = I->time;
    switch (vr) {
    case 0: *v = (Var){T_F64, &I->m.time, 1, K_READ_ONLY}; return true;
    case 1: *v = (Var){T_CLOCK, &I->m.tick, 1, K_INPUT}; return true;
    case 2: *v = (Var){T_I32, &I->m.ticks, 1, K_READ_ONLY}; return true;
    default: return false;
    }
}

static void model_start(Instance *I) { I->m.ticks = 0; }
static fmi3Status model_exit_init(Instance *I) { (void)I; return fmi3OK; }
static fmi3Status model_step(Instance *I, double t, double h, double *stop_at) {
    (void)I; (void)t; (void)h; (void)stop_at;
    return fmi3OK;
}

/*
 * stair: like the Reference FMU "Stair". `counter` starts at 1 and counts every whole second; when it
 * reaches 10 (t = 9 s) the FMU ends the simulation: FMI 2.0 returns fmi2Discard with fmi2Terminated,
 * FMI 3.0 sets terminateSimulation (and returns early at t = 9 when the importer allows it).
 * `phase` (String) is "climbing", then "top". Compiled for both versions (-DFMI_VERSION=2 or 3).
 */
#include <math.h>
#include <stdbool.h>
#include <stdint.h>

struct Model {
    double time;
    int32_t counter;
    double next_event;
    char phase[64];
};

#if FMI_VERSION == 2
#include "../fmi2_runtime.c"
#define STATUS fmi2Status
#define OK_STATUS fmi2OK
#else
#include "../fmi3_runtime.c"
#define STATUS fmi3Status
#define OK_STATUS fmi3OK
#endif

enum { VR_TIME = 0, VR_COUNTER = 1, VR_PHASE = 2 };

static bool model_variable(Instance *I, unsigned vr, Var *v) {
    I->m.time = I->time;
    switch (vr) {
    case VR_TIME: *v = (Var){T_F64, &I->m.time, 1, K_READ_ONLY}; return true;
    case VR_COUNTER: *v = (Var){T_I32, &I->m.counter, 1, K_READ_ONLY}; return true;
    case VR_PHASE: *v = (Var){T_STR, I->m.phase, 1, K_READ_ONLY}; return true;
    default: return false;
    }
}

static void model_start(Instance *I) {
    I->m.counter = 1;
    I->m.next_event = 1.0;
    strcpy(I->m.phase, "climbing");
}

static STATUS model_exit_init(Instance *I) {
    I->m.next_event = floor(I->time) + 1.0;
    return OK_STATUS;
}

static STATUS model_step(Instance *I, double t, double h, double *stop_at) {
    double end = t + h;
    /* every whole second up to the step's end (within rounding) is an event */
    while (I->m.next_event <= end + 1e-9 * fmax(1.0, fabs(end))) {
        I->m.counter++;
        if (I->m.counter >= 10) {
            strcpy(I->m.phase, "top");
            *stop_at = fabs(I->m.next_event - end) <= 1e-9 * fmax(1.0, fabs(end)) ? end : I->m.next_event;
            I->m.next_event += 1.0;
            return OK_STATUS;
        }
        I->m.next_event += 1.0;
    }
    return OK_STATUS;
}

/*
 * fault: a test FMU that misbehaves at the first doStep with t >= trigger_time.
 * mode 0: none; 1: segfault (write through a null pointer); 2: hang forever (asleep: a hung point is
 * stopped by its timeout either way, and a busy loop took a core from everything else for the whole timeout);
 * 3: doStep returns fmi*Error; 4: y becomes NaN from then on.
 * Otherwise y = the current time.
 */
#include <math.h>
#include <unistd.h>

#include "framework.h"

Status model_validate(ModelInstance *comp) {
    if (comp->d.mode < 0 || comp->d.mode > 4) {
        logError(comp, "parameter mode = %d is not one of 0..4", (int)comp->d.mode);
        return Error;
    }
    return check_finite(comp, "trigger_time", SCALAR, comp->d.trigger_time);
}

void model_initialize(ModelInstance *comp) { comp->d.y = comp->time; }

Status model_calculate(ModelInstance *comp) {
    (void)comp;
    return OK;
}

Status model_do_step(ModelInstance *comp, double t, double h) {
    ModelData *d = &comp->d;
    if (t >= d->trigger_time && !isnan(d->y)) {
        switch (d->mode) {
            case 1: {
                volatile int *volatile nowhere = 0;
                logError(comp, "fault mode 1: writing through a null pointer at t=%g", t);
                *nowhere = 1;
                break;
            }
            case 2:
                logError(comp, "fault mode 2: hanging forever at t=%g", t);
                for (;;) {
                    sleep(1000);
                }
            case 3:
                logError(comp, "fault mode 3: doStep fails at t=%g", t);
                return Error;
            case 4:
                d->y = NAN;
                return OK;
            default:
                break;
        }
    }
    if (!isnan(d->y)) d->y = t + h;
    return OK;
}

/* gain_array: y = k * u for arrays of 3 -- a test FMU for array connections. */
#include "framework.h"

Status model_validate(ModelInstance *comp) {
    return check_finite(comp, "k", SCALAR, comp->d.k);
}

void model_initialize(ModelInstance *comp) { (void)comp; }

Status model_calculate(ModelInstance *comp) {
    int i;
    for (i = 0; i < N_U; i++) {
        if (check_finite(comp, "u", i, comp->d.u[i]) > Warning) return Error;
        comp->d.y[i] = comp->d.k * comp->d.u[i];
    }
    return OK;
}

Status model_do_step(ModelInstance *comp, double t, double h) {
    (void)t;
    (void)h;
    return model_calculate(comp);  /* no states: outputs follow the inputs */
}

/*
 * decay: der(x) = -k*x, the Reference FMU Dahlquist's test equation, with the state's start value on the state
 * itself (initial="exact", start 1): the environment sets x before initialization and the model starts there
 * (model_initialize leaves x alone).  doStep is exact: x(t+h) = x e^{-kh}.  As Model Exchange the environment
 * integrates der_x itself; the model has no events.
 */
#include <math.h>

#include "model_exchange.h"

Status model_validate(ModelInstance *comp) {
    if (check_finite(comp, "k", SCALAR, comp->d.k) > Warning) return Error;
    return check_finite(comp, "x", SCALAR, comp->d.x);
}

void model_initialize(ModelInstance *comp) { (void)comp; /* x holds its start value, set or not */ }

Status model_calculate(ModelInstance *comp) {
    comp->d.der_x = -comp->d.k * comp->d.x;
    return OK;
}

Status model_event_update(ModelInstance *comp, EventInfo *info) {
    (void)comp;
    (void)info;  /* no events */
    return OK;
}

bool model_step_event(ModelInstance *comp) {
    (void)comp;
    return false;
}

Status model_do_step(ModelInstance *comp, double t, double h) {
    (void)t;
    comp->d.x *= exp(-comp->d.k * h);
    return OK;
}

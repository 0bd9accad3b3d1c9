/*
 * linear_ode: der(x) = a*x + b*u, y = x (no direct feed-through).
 * doStep is exact for u held over the step:
 *   x(t+h) = e^{ah} x + (e^{ah} - 1)/a * b * u   (= x + h b u when a == 0),
 * so any error a co-simulation shows comes from the coupling alone.
 * As Model Exchange the environment integrates der_y = a*y + b*u itself;
 * the model has no events.
 */
#include <math.h>

#include "model_exchange.h"

Status model_validate(ModelInstance *comp) {
    if (check_finite(comp, "a", SCALAR, comp->d.a) > Warning) return Error;
    if (check_finite(comp, "b", SCALAR, comp->d.b) > Warning) return Error;
    return check_finite(comp, "x0", SCALAR, comp->d.x0);
}

void model_initialize(ModelInstance *comp) { comp->d.y = comp->d.x0; }

Status model_calculate(ModelInstance *comp) {
    /* y is the state (doStep or the environment's solver changes it); its derivative: */
    comp->d.der_y = comp->d.a * comp->d.y + comp->d.b * comp->d.u;
    return OK;
}

Status model_event_update(ModelInstance *comp, EventInfo *info) {
    (void)comp;
    (void)info;  /* no events: nothing changes, no next event time */
    return OK;
}

bool model_step_event(ModelInstance *comp) {
    (void)comp;
    return false;
}

Status model_do_step(ModelInstance *comp, double t, double h) {
    ModelData *d = &comp->d;
    double growth;
    (void)t;
    if (check_finite(comp, "u", SCALAR, d->u) > Warning) return Error;
    /* expm1 keeps (e^{ah} - 1)/a accurate for small a*h. */
    growth = d->a != 0.0 ? expm1(d->a * h) / d->a : h;
    d->y = d->y + d->a * growth * d->y + growth * d->b * d->u;
    return OK;
}

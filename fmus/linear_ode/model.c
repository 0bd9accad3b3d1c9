/*
 * linear_ode: der(x) = a*x + b*u, y = x (no direct feed-through).
 * doStep is exact for u held over the step:
 *   x(t+h) = e^{ah} x + (e^{ah} - 1)/a * b * u   (= x + h b u when a == 0),
 * so any error a co-simulation shows comes from the coupling alone.
 */
#include <math.h>

#include "framework.h"

Status model_validate(ModelInstance *comp) {
    if (check_finite(comp, "a", SCALAR, comp->d.a) > Warning) return Error;
    if (check_finite(comp, "b", SCALAR, comp->d.b) > Warning) return Error;
    return check_finite(comp, "x0", SCALAR, comp->d.x0);
}

void model_initialize(ModelInstance *comp) { comp->d.y = comp->d.x0; }

Status model_calculate(ModelInstance *comp) {
    (void)comp;  /* y is the state: it changes in doStep only */
    return OK;
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

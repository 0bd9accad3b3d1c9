/*
 * algebraic: y = c0 + c1*u + c2*u^2 + c3*u^3 + a*cos(u) + w, no state -- a test FMU for algebraic loops.
 * The output follows the input at once (direct feed-through): it is recomputed whenever
 * it is read after an input was set (model_calculate), also between steps, which is what
 * a master solving a loop does (set the input, get the output, no step).
 * It gives directional derivatives (model_partial): dy/du = c1 + 2 c2 u + 3 c3 u^2 - a sin(u), dy/dw = 1,
 * which a master's loop Newton uses instead of finite differences.
 */
#include <math.h>

#include "framework.h"

Status model_validate(ModelInstance *comp) {
    if (check_finite(comp, "c0", SCALAR, comp->d.c0) > Warning) return Error;
    if (check_finite(comp, "c1", SCALAR, comp->d.c1) > Warning) return Error;
    if (check_finite(comp, "c2", SCALAR, comp->d.c2) > Warning) return Error;
    if (check_finite(comp, "c3", SCALAR, comp->d.c3) > Warning) return Error;
    return check_finite(comp, "a", SCALAR, comp->d.a);
}

void model_initialize(ModelInstance *comp) { (void)comp; }

Status model_calculate(ModelInstance *comp) {
    ModelData *d = &comp->d;
    if (check_finite(comp, "u", SCALAR, d->u) > Warning) return Error;
    if (check_finite(comp, "w", SCALAR, d->w) > Warning) return Error;
    d->y = d->c0 + d->c1 * d->u + d->c2 * d->u * d->u + d->c3 * d->u * d->u * d->u + d->a * cos(d->u) + d->w;
    return OK;
}

Status model_do_step(ModelInstance *comp, double t, double h) {
    (void)t;
    (void)h;
    return model_calculate(comp);  /* no state: the output follows the input */
}

Status model_partial(ModelInstance *comp, size_t unknown, size_t unknownElement, size_t known, size_t knownElement,
                     double *value) {
    const ModelData *d = &comp->d;
    (void)unknownElement;
    (void)knownElement;  /* scalars only */
    *value = 0.0;
    if (unknown != VR_Y) return OK;  /* y is the only variable that depends on anything */
    if (known == VR_U) *value = d->c1 + 2.0 * d->c2 * d->u + 3.0 * d->c3 * d->u * d->u - d->a * sin(d->u);
    else if (known == VR_W) *value = 1.0;
    return OK;
}

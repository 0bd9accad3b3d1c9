/*
 * counter: a discrete counter with Integer and Boolean ports (test FMU for the native kernel's Integer and
 * Boolean transfers and stop_when).  At each doStep, while enable: count += increment; then
 * odd = count is odd, done = count >= limit, y += h * count * u.
 */
#include "framework.h"

Status model_validate(ModelInstance *comp) {
    (void)comp;
    return OK;
}

void model_initialize(ModelInstance *comp) {
    ModelData *d = &comp->d;
    d->count = d->count0;
    d->odd = (d->count % 2) != 0;
    d->done = d->count >= d->limit;
    d->y = 0.0;
}

Status model_calculate(ModelInstance *comp) {
    (void)comp;
    return OK;
}

Status model_do_step(ModelInstance *comp, double t, double h) {
    ModelData *d = &comp->d;
    (void)t;
    if (d->enable) d->count += d->increment;
    d->odd = (d->count % 2) != 0;
    d->done = d->count >= d->limit;
    d->y += h * (double)d->count * d->u;
    return OK;
}

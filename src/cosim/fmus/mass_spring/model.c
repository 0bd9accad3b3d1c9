/*
 * mass_spring (Model Exchange only): a mass m on a spring k and damper d to
 * the wall, and on a coupling spring kc and damper dc to a neighbour whose
 * position x_in and velocity v_in are inputs; F is an external force:
 *   der(x) = v,  m der(v) = F - k x - d v - kc (x - x_in) - dc (v - v_in).
 * Output F_c = kc (x - x_in) + dc (v - v_in) is the force the coupling exerts
 * on the neighbour (direct feed-through from x_in, v_in), so two instances
 * make a two-mass oscillator split into two FMUs: the first (kc = 0) takes
 * the second's F_c as its F, the second takes the first's x and v.
 * State event: the indicator z_stop = x_stop - x crosses zero; in Event Mode
 * a mass moving towards the stop at x >= x_stop is reflected, v := -e_stop v
 * (x := x_stop), and the contact is counted and timed.
 */
#include <math.h>

#include "model_exchange.h"

Status model_validate(ModelInstance *comp) {
    ModelData *d = &comp->d;
    const char *names[] = {"m", "k", "d", "kc", "dc", "x0", "v0", "x_stop", "e_stop"};
    const double values[] = {d->m, d->k, d->d, d->kc, d->dc, d->x0, d->v0, d->x_stop, d->e_stop};
    for (size_t i = 0; i < sizeof values / sizeof values[0]; i++)
        if (check_finite(comp, names[i], SCALAR, values[i]) > Warning) return Error;
    if (!(d->m > 0) || d->e_stop < 0 || d->e_stop > 1 || d->x0 > d->x_stop) {
        logError(comp, "mass_spring needs m > 0, 0 <= e_stop <= 1 and x0 <= x_stop (m=%g e_stop=%g x0=%g x_stop=%g)",
                 d->m, d->e_stop, d->x0, d->x_stop);
        return Error;
    }
    return OK;
}

void model_initialize(ModelInstance *comp) {
    ModelData *d = &comp->d;
    d->x = d->x0;
    d->v = d->v0;
    d->hits = 0;
    d->t_hit = 0.0;
}

Status model_calculate(ModelInstance *comp) {
    ModelData *d = &comp->d;
    if (check_finite(comp, "F", SCALAR, d->F) > Warning || check_finite(comp, "x_in", SCALAR, d->x_in) > Warning ||
        check_finite(comp, "v_in", SCALAR, d->v_in) > Warning)
        return Error;
    d->F_c = d->kc * (d->x - d->x_in) + d->dc * (d->v - d->v_in);
    d->der_x = d->v;
    d->der_v = (d->F - d->k * d->x - d->d * d->v - d->F_c) / d->m;
    d->z_stop = d->x_stop - d->x;
    return OK;
}

Status model_event_update(ModelInstance *comp, EventInfo *info) {
    ModelData *d = &comp->d;
    if (!(d->x >= d->x_stop && d->v > 0.0)) return OK;  /* not at the stop moving into it: nothing to do */
    d->hits += 1;
    d->t_hit = comp->time;
    d->x = d->x_stop;  /* the solver stops a hair past the stop; restart exactly on it */
    d->v = -d->e_stop * d->v;
    info->valuesOfContinuousStatesChanged = true;
    return OK;
}

bool model_step_event(ModelInstance *comp) {
    (void)comp;
    return false;
}

/*
 * square_lag (Model Exchange only): der(x) = (s - x)/tau, x(t0) = 0.
 * s is 1 on [t0 + k*period, t0 + (k + 1/2)*period) and 0 on the other half
 * periods: each switch is a time event announced as the next event time.
 * Exactly, on a half period starting at t_k with x_k:
 *   x(t) = s + (x_k - s) * exp(-(t - t_k)/tau).
 * The trip is a step event: after every completed integrator step the model
 * asks for an event when x > x_trip; in that event s becomes 0 for good.
 */
#include <math.h>

#include "model_exchange.h"

/* Time of the n-th switch (n = 1, 2, ...). */
static double switch_time(const ModelInstance *comp, int32_t n) {
    return comp->startTime + 0.5 * comp->d.period * n;
}

Status model_validate(ModelInstance *comp) {
    ModelData *d = &comp->d;
    if (check_finite(comp, "tau", SCALAR, d->tau) > Warning || check_finite(comp, "period", SCALAR, d->period) > Warning ||
        check_finite(comp, "x_trip", SCALAR, d->x_trip) > Warning)
        return Error;
    if (!(d->tau > 0) || !(d->period > 0)) {
        logError(comp, "square_lag needs tau > 0 and period > 0 (tau=%g period=%g)", d->tau, d->period);
        return Error;
    }
    return OK;
}

void model_initialize(ModelInstance *comp) {
    ModelData *d = &comp->d;
    d->x = 0.0;
    d->s = 1.0;
    d->switches = 0;
    d->tripped = false;
    d->t_trip = 0.0;
}

Status model_calculate(ModelInstance *comp) {
    comp->d.der_x = (comp->d.s - comp->d.x) / comp->d.tau;
    return OK;
}

Status model_event_update(ModelInstance *comp, EventInfo *info) {
    ModelData *d = &comp->d;
    if (!d->tripped && d->x > d->x_trip) {
        d->tripped = true;
        d->t_trip = comp->time;
        d->s = 0.0;
    }
    if (d->tripped) return OK;  /* no more switching: no next event time */
    /* A time event reached (the environment may stop a rounding error short of it). */
    while (comp->time >= switch_time(comp, d->switches + 1) - 1e-9 * d->period) {
        d->switches += 1;
        d->s = d->switches % 2 == 0 ? 1.0 : 0.0;
    }
    info->nextEventTimeDefined = true;
    info->nextEventTime = switch_time(comp, d->switches + 1);
    return OK;
}

bool model_step_event(ModelInstance *comp) { return !comp->d.tripped && comp->d.x > comp->d.x_trip; }

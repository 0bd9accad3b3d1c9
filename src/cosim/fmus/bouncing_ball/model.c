/*
 * bouncing_ball (Model Exchange only): der(h) = v, der(v) = -g.
 * State event: the indicator z_floor = h crosses zero; in Event Mode a ball
 * moving down at h <= 0 bounces, v := -e*v (h := 0), and the bounce is counted
 * and timed.  A rebound slower than v_min leaves the ball resting (h = v = 0,
 * derivatives 0, indicator 1), which ends the otherwise infinite sequence of
 * ever shorter flights; with stop_at_rest the model then asks to end the
 * simulation (terminateSimulation).
 * Dropped from h0 at rest: bounce k (1-based) happens at
 *   t_1 = sqrt(2 h0 / g),  t_{k+1} = t_k + 2 e^k v_1 / g  with v_1 = g t_1.
 */
#include <math.h>

#include "model_exchange.h"

Status model_validate(ModelInstance *comp) {
    ModelData *d = &comp->d;
    if (check_finite(comp, "g", SCALAR, d->g) > Warning || check_finite(comp, "e", SCALAR, d->e) > Warning ||
        check_finite(comp, "h0", SCALAR, d->h0) > Warning || check_finite(comp, "v_min", SCALAR, d->v_min) > Warning)
        return Error;
    if (!(d->g > 0) || d->e < 0 || d->e > 1 || d->h0 < 0 || d->v_min < 0) {
        logError(comp, "bouncing_ball needs g > 0, 0 <= e <= 1, h0 >= 0 and v_min >= 0 (g=%g e=%g h0=%g v_min=%g)",
                 d->g, d->e, d->h0, d->v_min);
        return Error;
    }
    return OK;
}

void model_initialize(ModelInstance *comp) {
    ModelData *d = &comp->d;
    d->h = d->h0;
    d->v = 0.0;
    d->bounces = 0;
    d->t_bounce = 0.0;
    d->resting = d->h0 == 0.0;
}

Status model_calculate(ModelInstance *comp) {
    ModelData *d = &comp->d;
    d->der_h = d->resting ? 0.0 : d->v;
    d->der_v = d->resting ? 0.0 : -d->g;
    d->z_floor = d->resting ? 1.0 : d->h;
    return OK;
}

Status model_event_update(ModelInstance *comp, EventInfo *info) {
    ModelData *d = &comp->d;
    if (d->resting || !(d->h <= 0.0 && d->v < 0.0)) return OK;  /* no floor contact: nothing to do */
    d->bounces += 1;
    d->t_bounce = comp->time;
    d->h = 0.0;  /* the solver stops a hair below the floor; restart exactly on it */
    d->v = -d->e * d->v;
    if (d->v < d->v_min) {
        d->v = 0.0;
        d->resting = true;
        info->terminateSimulation = d->stop_at_rest;  /* nothing more will happen: may end the run */
    }
    info->valuesOfContinuousStatesChanged = true;
    return OK;
}

bool model_step_event(ModelInstance *comp) {
    (void)comp;
    return false;
}

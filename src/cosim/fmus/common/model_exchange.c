/* The Model Exchange core of the framework (see model_exchange.h). */
#include <math.h>
#include <string.h>

#include "model_exchange.h"

#define REAL_AT(comp, offset) (*(double *)((char *)&(comp)->d + (offset)))

static bool is_me(ModelInstance *comp, const char *function) {
    if (comp->modelExchange) return true;
    logError(comp, "%s: the instance was not instantiated for Model Exchange", function);
    return false;
}

static Status check_mode(ModelInstance *comp, const char *function, bool event, bool continuous) {
    if (!is_me(comp, function)) return Error;
    if ((event && comp->state == STATE_EVENT) || (continuous && comp->state == STATE_CONTINUOUS)) return OK;
    logError(comp, "%s is not allowed in this state (%s)", function,
             event && continuous ? "Event or Continuous-Time Mode required"
                                 : event ? "Event Mode required" : "Continuous-Time Mode required");
    return Error;
}

static Status check_size(ModelInstance *comp, const char *function, size_t n, size_t expected) {
    if (n == expected) return OK;
    logError(comp, "%s: %zu values given, the model has %zu", function, n, expected);
    return Error;
}

Status me_set_time(ModelInstance *comp, double time) {
    if (check_mode(comp, "setTime", true, true) > Warning) return Error;
    if (!isfinite(time)) {
        logError(comp, "setTime: time %g is not finite", time);
        return Error;
    }
    comp->time = time;
    comp->isDirty = true;
    return OK;
}

Status me_set_states(ModelInstance *comp, const double x[], size_t n) {
    size_t i;
    if (check_mode(comp, "setContinuousStates", true, true) > Warning) return Error;
    if (check_size(comp, "setContinuousStates", n, N_STATES) > Warning) return Error;
    for (i = 0; i < n; i++) REAL_AT(comp, STATE_OFFSETS[i]) = x[i];
    comp->isDirty = true;
    return OK;
}

Status me_get_states(ModelInstance *comp, double x[], size_t n) {
    size_t i;
    if (!is_me(comp, "getContinuousStates")) return Error;
    if (check_size(comp, "getContinuousStates", n, N_STATES) > Warning) return Error;
    for (i = 0; i < n; i++) x[i] = REAL_AT(comp, STATE_OFFSETS[i]);
    return OK;
}

Status me_get_nominals(ModelInstance *comp, double nominals[], size_t n) {
    size_t i;
    if (!is_me(comp, "getNominalsOfContinuousStates")) return Error;
    if (check_size(comp, "getNominalsOfContinuousStates", n, N_STATES) > Warning) return Error;
    for (i = 0; i < n; i++) nominals[i] = 1.0;  /* no nominal attributes: scale 1 */
    return OK;
}

Status me_get_derivatives(ModelInstance *comp, double dx[], size_t n) {
    size_t i;
    Status status;
    if (!is_me(comp, "getDerivatives")) return Error;
    if (check_size(comp, "getDerivatives", n, N_STATES) > Warning) return Error;
    status = framework_update(comp); /* model_calculate computes the derivatives */
    if (status > Warning) return status;
    for (i = 0; i < n; i++) dx[i] = REAL_AT(comp, DERIVATIVE_OFFSETS[i]);
    return status;
}

Status me_get_event_indicators(ModelInstance *comp, double z[], size_t n) {
    size_t i;
    Status status;
    if (!is_me(comp, "getEventIndicators")) return Error;
    if (check_size(comp, "getEventIndicators", n, N_EVENT_INDICATORS) > Warning) return Error;
    status = framework_update(comp);
    if (status > Warning) return status;
    for (i = 0; i < n; i++) z[i] = REAL_AT(comp, EVENT_INDICATOR_OFFSETS[i]);
    return status;
}

Status me_enter_event_mode(ModelInstance *comp) {
    if (check_mode(comp, "enterEventMode", true, true) > Warning) return Error;
    comp->state = STATE_EVENT;
    return OK;
}

Status me_update_discrete_states(ModelInstance *comp, EventInfo *info) {
    Status status;
    EventInfo result;
    if (check_mode(comp, "newDiscreteStates/updateDiscreteStates", true, false) > Warning) return Error;
    memset(&result, 0, sizeof result);
    /* Outputs and indicators must be current before the model looks at them. */
    status = framework_update(comp);
    if (status <= Warning) status = model_event_update(comp, &result);
    comp->isDirty = true;
    if (status > Warning) {
        comp->state = STATE_ERROR;
        return status;
    }
    comp->event = result;
    if (info) *info = result;
    return status;
}

Status me_enter_continuous_time_mode(ModelInstance *comp) {
    if (check_mode(comp, "enterContinuousTimeMode", true, false) > Warning) return Error;
    comp->state = STATE_CONTINUOUS;
    return OK;
}

Status me_completed_integrator_step(ModelInstance *comp, bool *enterEventMode, bool *terminateSimulation) {
    Status status;
    if (check_mode(comp, "completedIntegratorStep", false, true) > Warning) return Error;
    status = framework_update(comp);
    if (status > Warning) return status;
    if (enterEventMode) *enterEventMode = model_step_event(comp);
    if (terminateSimulation) *terminateSimulation = false;
    return status;
}

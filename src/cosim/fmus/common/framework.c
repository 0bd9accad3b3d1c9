/* The FMI-version independent part of the framework (see framework.h). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "framework.h"

static void vlog(ModelInstance *comp, Status status, const char *category, const char *fmt, va_list args) {
    char message[1024];
    if (!comp || !comp->log) return;
    vsnprintf(message, sizeof message, fmt, args);
    comp->log(comp, status, category, message);
}

void logError(ModelInstance *comp, const char *fmt, ...) {
    va_list args;
    va_start(args, fmt);
    vlog(comp, Error, "logStatusError", fmt, args);
    va_end(args);
}

void logInfo(ModelInstance *comp, const char *fmt, ...) {
    va_list args;
    if (!comp || !comp->loggingOn) return;
    va_start(args, fmt);
    vlog(comp, OK, "logEvents", fmt, args);
    va_end(args);
}

ModelInstance *framework_instantiate(const char *instanceName, const char *token, void *environment,
                                     AnyFunction logger, LogFunction log, bool loggingOn) {
    ModelInstance *comp = calloc(1, sizeof(ModelInstance));
    if (!comp) return NULL;
    comp->environment = environment;
    comp->logger = logger;
    comp->log = log;
    comp->loggingOn = loggingOn;
    comp->instanceName = strdup(instanceName ? instanceName : "instance");
    if (!comp->instanceName) {
        free(comp);
        return NULL;
    }
    /* A token from another build means another modelDescription: refuse. */
    if (!token || strcmp(token, INSTANTIATION_TOKEN) != 0) {
        logError(comp, "instantiation token/GUID '%s' does not match this binary's '%s'",
                 token ? token : "(null)", INSTANTIATION_TOKEN);
        framework_free(comp);
        return NULL;
    }
    framework_reset(comp);
    logInfo(comp, "instantiated %s", MODEL_IDENTIFIER);
    return comp;
}

void framework_free(ModelInstance *comp) {
    if (!comp) return;
    free(comp->instanceName);
    free(comp);
}

void framework_reset(ModelInstance *comp) {
    memset(&comp->d, 0, sizeof comp->d);
    setStartValues(&comp->d);
    comp->time = 0.0;
    comp->startTime = 0.0;
    comp->state = STATE_INSTANTIATED;
    comp->isDirty = true;
    memset(&comp->event, 0, sizeof comp->event);
}

Status framework_enter_initialization(ModelInstance *comp, double startTime) {
    if (comp->state != STATE_INSTANTIATED) {
        logError(comp, "enterInitializationMode is only allowed right after instantiation or reset");
        return Error;
    }
    comp->startTime = startTime;
    comp->time = startTime;
    comp->state = STATE_INITIALIZATION;
    comp->isDirty = true;
    return OK;
}

Status framework_exit_initialization(ModelInstance *comp) {
    Status status;
    if (comp->state != STATE_INITIALIZATION) {
        logError(comp, "exitInitializationMode called outside initialization mode");
        return Error;
    }
    status = model_validate(comp);
    if (status > Warning) {
        comp->state = STATE_ERROR;
        return status;
    }
    model_initialize(comp);
    /* Model Exchange continues in Event Mode (FMI 2.0 and 3.0), co-simulation in Step Mode. */
    comp->state = comp->modelExchange ? STATE_EVENT : STATE_STEP;
    comp->isDirty = true;
    return status;
}

Status framework_update(ModelInstance *comp) {
    Status status;
    if (!comp->isDirty || (comp->state != STATE_INITIALIZATION && comp->state != STATE_STEP &&
                           comp->state != STATE_EVENT && comp->state != STATE_CONTINUOUS))
        return OK;
    status = model_calculate(comp);
    if (status <= Warning) comp->isDirty = false;
    return status;
}

Status framework_do_step(ModelInstance *comp, double t, double h) {
    Status status;
    if (comp->state != STATE_STEP) {
        logError(comp, "doStep is only allowed after exitInitializationMode (and not after an error)");
        return Error;
    }
    if (!(h >= 0.0) || !isfinite(t) || !isfinite(h)) {
        logError(comp, "doStep: bad communication step t=%g h=%g", t, h);
        return Error;
    }
    status = model_do_step(comp, t, h);
    comp->isDirty = true;
    if (status > Warning) return status;
    comp->time = t + h;
    return status;
}

Status framework_terminate(ModelInstance *comp) {
    comp->state = STATE_TERMINATED;
    logInfo(comp, "terminated at t=%g", comp->time);
    return OK;
}

/* What an instance changes while it runs; a saved state is one of these. */
typedef struct {
    double time;
    double startTime;
    ModelState state;
    bool isDirty;
    EventInfo event;
    ModelData d;
} SavedState;

/* Serialized states start with the build's token, so bytes from another build are refused. */
#define TOKEN_BYTES 64

Status framework_get_state(ModelInstance *comp, void **state) {
    SavedState *saved;
    if (!state) {
        logError(comp, "getFMUState: the state argument is NULL");
        return Error;
    }
    saved = *state ? (SavedState *)*state : malloc(sizeof(SavedState));
    if (!saved) {
        logError(comp, "getFMUState: out of memory");
        return Error;
    }
    saved->time = comp->time;
    saved->startTime = comp->startTime;
    saved->state = comp->state;
    saved->isDirty = comp->isDirty;
    saved->event = comp->event;
    saved->d = comp->d;
    *state = saved;
    return OK;
}

Status framework_set_state(ModelInstance *comp, const void *state) {
    const SavedState *saved = (const SavedState *)state;
    if (!saved) {
        logError(comp, "setFMUState: the state is NULL");
        return Error;
    }
    comp->time = saved->time;
    comp->startTime = saved->startTime;
    comp->state = saved->state;
    comp->isDirty = saved->isDirty;
    comp->event = saved->event;
    comp->d = saved->d;
    return OK;
}

void framework_free_state(void **state) {
    if (!state) return;
    free(*state);
    *state = NULL;
}

size_t framework_serialized_size(void) { return TOKEN_BYTES + sizeof(SavedState); }

Status framework_serialize_state(ModelInstance *comp, const void *state, char *bytes, size_t size) {
    if (!state || !bytes || size < framework_serialized_size()) {
        logError(comp, "serializeFMUState: no state, or a buffer of %zu bytes (needs %zu)", size,
                 framework_serialized_size());
        return Error;
    }
    memset(bytes, 0, TOKEN_BYTES);
    strncpy(bytes, INSTANTIATION_TOKEN, TOKEN_BYTES - 1);
    memcpy(bytes + TOKEN_BYTES, state, sizeof(SavedState));
    return OK;
}

Status framework_deserialize_state(ModelInstance *comp, const char *bytes, size_t size, void **state) {
    char token[TOKEN_BYTES];
    if (!bytes || size != framework_serialized_size() || !state) {
        logError(comp, "deserializeFMUState: %zu bytes given, a state of this FMU has %zu", size,
                 framework_serialized_size());
        return Error;
    }
    memset(token, 0, sizeof token);
    strncpy(token, INSTANTIATION_TOKEN, TOKEN_BYTES - 1);
    if (memcmp(bytes, token, TOKEN_BYTES) != 0) {
        logError(comp, "deserializeFMUState: the bytes were saved by another build of this model");
        return Error;
    }
    if (!*state) *state = malloc(sizeof(SavedState));
    if (!*state) {
        logError(comp, "deserializeFMUState: out of memory");
        return Error;
    }
    memcpy(*state, bytes + TOKEN_BYTES, sizeof(SavedState));
    return OK;
}

void *framework_address(ModelInstance *comp, size_t index, size_t element) {
    const VariableInfo *v = &VARIABLES[index];
    size_t width = v->type == VT_REAL ? sizeof(double) : v->type == VT_INTEGER ? sizeof(int32_t) : sizeof(bool);
    if (v->causality == CAUS_INDEPENDENT) return NULL;
    return (char *)&comp->d + v->offset + element * width;
}

Status framework_check_type(ModelInstance *comp, size_t index, VariableType type, const char *function) {
    if (index >= N_VARIABLES || VARIABLES[index].type != type) {
        logError(comp, "%s: value reference does not name a variable of this type", function);
        return Error;
    }
    return OK;
}

Status framework_check_set(ModelInstance *comp, size_t index, VariableType type) {
    const VariableInfo *v;
    if (framework_check_type(comp, index, type, "set") > Warning) return Error;
    v = &VARIABLES[index];
    /* A fixed parameter only before exitInitializationMode; a tunable one also between steps (co-simulation
     * Step Mode) and in Model Exchange Event Mode, as FMI 2.0 and 3.0 allow. */
    if (v->causality == CAUS_PARAMETER && comp->state != STATE_INSTANTIATED && comp->state != STATE_INITIALIZATION &&
        !(v->tunable && (comp->state == STATE_STEP || comp->state == STATE_EVENT))) {
        logError(comp, v->tunable ? "tunable parameter '%s' can only be set in initialization, step or event mode"
                                  : "parameter '%s' can only be set before exitInitializationMode (it is not tunable)",
                 v->name);
        return Error;
    }
    /* A state's start value (initial="exact"): FMI lets the environment set it until exitInitializationMode. */
    if (v->exact_start && (comp->state == STATE_INSTANTIATED || comp->state == STATE_INITIALIZATION)) return OK;
    if (v->causality != CAUS_PARAMETER && v->causality != CAUS_INPUT) {
        logError(comp, "'%s' is not a parameter or input and cannot be set", v->name);
        return Error;
    }
    return OK;
}

Status check_finite(ModelInstance *comp, const char *name, size_t element, double value) {
    if (isfinite(value)) return OK;
    if (element == SCALAR)
        logError(comp, "%s = %g at t=%g is not a finite number", name, value, comp->time);
    else
        logError(comp, "%s[%zu] = %g at t=%g is not a finite number", name, element + 1, value, comp->time);
    return Error;
}

Status framework_directional_derivative(ModelInstance *comp, const size_t unknowns[], const size_t unknownElements[],
                                        size_t nUnknowns, const size_t knowns[], const size_t knownElements[],
                                        size_t nKnowns, const double seed[], double sensitivity[]) {
#if PROVIDES_DIRECTIONAL_DERIVATIVE
    size_t i, j;
    Status status;
    if (comp->state != STATE_INITIALIZATION && comp->state != STATE_STEP && comp->state != STATE_EVENT &&
        comp->state != STATE_CONTINUOUS) {
        logError(comp, "getDirectionalDerivative is only allowed after enterInitializationMode (and not after an error)");
        return Error;
    }
    for (i = 0; i < nUnknowns; i++)
        if (VARIABLES[unknowns[i]].type != VT_REAL) {
            logError(comp, "getDirectionalDerivative: '%s' is not a Real variable", VARIABLES[unknowns[i]].name);
            return Error;
        }
    for (j = 0; j < nKnowns; j++)
        if (VARIABLES[knowns[j]].type != VT_REAL) {
            logError(comp, "getDirectionalDerivative: '%s' is not a Real variable", VARIABLES[knowns[j]].name);
            return Error;
        }
    status = framework_update(comp);  /* partials at the current inputs, as the outputs a get would give */
    if (status > Warning) return status;
    for (i = 0; i < nUnknowns; i++) {
        double sum = 0.0;
        for (j = 0; j < nKnowns; j++) {
            double partial = 0.0;
            if (seed[j] == 0.0) continue;
            status = model_partial(comp, unknowns[i], unknownElements[i], knowns[j], knownElements[j], &partial);
            if (status > Warning) return status;
            sum += partial * seed[j];
        }
        sensitivity[i] = sum;
    }
    return OK;
#else
    (void)unknowns; (void)unknownElements; (void)nUnknowns; (void)knowns; (void)knownElements; (void)nKnowns;
    (void)seed; (void)sensitivity;
    logError(comp, "getDirectionalDerivative is not supported by this FMU");
    return Error;
#endif
}

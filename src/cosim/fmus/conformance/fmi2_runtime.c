/*
 * A small FMI 2.0 co-simulation runtime for the conformance FMUs, the FMI 2.0 twin of fmi3_runtime.c
 * (same model API; Float64 is fmi2Real, Int32 fmi2Integer, Boolean and String as in FMI 2.0).
 *
 * Ending early: when model_step sets *stop_at, fmi2DoStep returns fmi2Discard;
 * fmi2GetBooleanStatus(fmi2Terminated) is then true and fmi2GetRealStatus(fmi2LastSuccessfulTime)
 * is stop_at, as the FMI 2.0 standard prescribes for a slave that wants the simulation to end.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define STR_LEN 64

typedef char Str[STR_LEN];
typedef enum { T_F64, T_I32, T_BOOL, T_STR } VType;
typedef enum { K_READ_ONLY, K_PARAMETER, K_INPUT } VKind;
typedef enum { S_INSTANTIATED, S_INITIALIZATION, S_STEP, S_TERMINATED } RunState;
typedef struct { VType type; void *data; size_t count; VKind kind; } Var;

typedef struct Instance {
    char name[128];
    fmi2CallbackFunctions callbacks;
    RunState state;
    double time;
    bool terminated;      /* the model asked to end the simulation */
    double last_successful_time;
    struct Model m;
} Instance;

static bool model_variable(Instance *I, unsigned vr, Var *v);
static void model_start(Instance *I);
static fmi2Status model_exit_init(Instance *I);
static fmi2Status model_step(Instance *I, double t, double h, double *stop_at);

static void log_error(Instance *I, const char *fmt, ...) {
    char text[512];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    if (I && I->callbacks.logger) I->callbacks.logger(I->callbacks.componentEnvironment, I->name, fmi2Error,
                                                       "logStatusError", "%s", text);
}

static const char *TYPE_NAMES[] = {"Real", "Integer", "Boolean", "String"};

static bool find(Instance *I, fmi2ValueReference vr, VType type, const char *call, Var *v) {
    if (!model_variable(I, vr, v)) { log_error(I, "%s: no variable has value reference %u", call, vr); return false; }
    if (v->type != type) {
        log_error(I, "%s: variable %u is %s, not %s", call, vr, TYPE_NAMES[v->type], TYPE_NAMES[type]);
        return false;
    }
    return true;
}

static bool may_set(Instance *I, const Var *v, fmi2ValueReference vr, const char *call) {
    bool ok = (v->kind == K_INPUT && I->state != S_TERMINATED) ||
              (v->kind == K_PARAMETER && (I->state == S_INSTANTIATED || I->state == S_INITIALIZATION));
    if (!ok) log_error(I, "%s: variable %u cannot be set now", call, vr);
    return ok;
}

#define ACCESSORS(T, ctype, vtype)                                                                           \
    fmi2Status fmi2Get##T(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, ctype value[]) {       \
        Instance *I = (Instance *)c;                                                                         \
        for (size_t i = 0; i < nvr; i++) {                                                                   \
            Var v;                                                                                           \
            if (!find(I, vr[i], vtype, "fmi2Get" #T, &v)) return fmi2Error;                                  \
            value[i] = *(ctype *)v.data;                                                                     \
        }                                                                                                    \
        return fmi2OK;                                                                                       \
    }                                                                                                        \
    fmi2Status fmi2Set##T(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const ctype value[]) { \
        Instance *I = (Instance *)c;                                                                         \
        for (size_t i = 0; i < nvr; i++) {                                                                   \
            Var v;                                                                                           \
            if (!find(I, vr[i], vtype, "fmi2Set" #T, &v) || !may_set(I, &v, vr[i], "fmi2Set" #T)) return fmi2Error; \
            *(ctype *)v.data = value[i];                                                                     \
        }                                                                                                    \
        return fmi2OK;                                                                                       \
    }
ACCESSORS(Real, fmi2Real, T_F64)
ACCESSORS(Integer, fmi2Integer, T_I32)
ACCESSORS(Boolean, fmi2Boolean, T_BOOL)

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    Instance *I = (Instance *)c;
    for (size_t i = 0; i < nvr; i++) {
        Var v;
        if (!find(I, vr[i], T_STR, "fmi2GetString", &v)) return fmi2Error;
        value[i] = (const char *)v.data;
    }
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    Instance *I = (Instance *)c;
    for (size_t i = 0; i < nvr; i++) {
        Var v;
        if (!find(I, vr[i], T_STR, "fmi2SetString", &v) || !may_set(I, &v, vr[i], "fmi2SetString")) return fmi2Error;
        if (!value[i] || strlen(value[i]) >= STR_LEN) { log_error(I, "fmi2SetString: too long"); return fmi2Error; }
        strcpy((char *)v.data, value[i]);
    }
    return fmi2OK;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)guid; (void)location; (void)visible; (void)loggingOn;
    if (fmuType != fmi2CoSimulation) {
        if (functions && functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                              "only co-simulation is supported");
        return NULL;
    }
    Instance *I = calloc(1, sizeof(Instance));
    if (!I) return NULL;
    snprintf(I->name, sizeof I->name, "%s", instanceName ? instanceName : "");
    if (functions) I->callbacks = *functions;
    I->state = S_INSTANTIATED;
    model_start(I);
    return I;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real startTime,
                               fmi2Boolean stopDefined, fmi2Real stopTime) {
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stopTime;
    ((Instance *)c)->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { ((Instance *)c)->state = S_INITIALIZATION; return fmi2OK; }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *I = (Instance *)c;
    fmi2Status status = model_exit_init(I);
    if (status <= fmi2Warning) I->state = S_STEP;
    return status;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Instance *I = (Instance *)c;
    double stop_at = -1.0;
    (void)noSetPrior;
    if (I->state != S_STEP || I->terminated) { log_error(I, "fmi2DoStep: not in step mode"); return fmi2Error; }
    fmi2Status status = model_step(I, t, h, &stop_at);
    if (status > fmi2Warning) return status;
    I->time = t + h;
    I->last_successful_time = I->time;
    if (stop_at >= 0.0) {
        I->terminated = true;
        I->time = I->last_successful_time = stop_at;
        return fmi2Discard;
    }
    return status;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *I = (Instance *)c;
    if (s != fmi2Terminated) { log_error(I, "fmi2GetBooleanStatus: only fmi2Terminated is provided"); return fmi2Discard; }
    *value = I->terminated;
    return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *I = (Instance *)c;
    if (s != fmi2LastSuccessfulTime) { log_error(I, "fmi2GetRealStatus: only fmi2LastSuccessfulTime is provided"); return fmi2Discard; }
    *value = I->last_successful_time;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) { ((Instance *)c)->state = S_TERMINATED; return fmi2OK; }

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *I = (Instance *)c;
    memset(&I->m, 0, sizeof I->m);
    I->state = S_INSTANTIATED;
    I->terminated = false;
    I->time = I->last_successful_time = 0.0;
    model_start(I);
    return fmi2OK;
}

#define REFUSE(call) do { log_error((Instance *)c, call " is not supported by this FMU"); return fmi2Error; } while (0)

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { (void)s; (void)v; REFUSE("fmi2GetStatus"); }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { (void)s; (void)v; REFUSE("fmi2GetIntegerStatus"); }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { (void)s; (void)v; REFUSE("fmi2GetStringStatus"); }
fmi2Status fmi2CancelStep(fmi2Component c) { REFUSE("fmi2CancelStep"); }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; REFUSE("fmi2GetFMUstate"); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)s; REFUSE("fmi2SetFMUstate"); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; REFUSE("fmi2FreeFMUstate"); }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { (void)s; (void)n; REFUSE("fmi2SerializedFMUstateSize"); }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { (void)s; (void)b; (void)n; REFUSE("fmi2SerializeFMUstate"); }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { (void)s; (void)b; (void)n; REFUSE("fmi2DeSerializeFMUstate"); }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference a[], size_t b,
                                        const fmi2ValueReference d[], size_t e, const fmi2Real f[], fmi2Real g[]) {
    (void)a; (void)b; (void)d; (void)e; (void)f; (void)g; REFUSE("fmi2GetDirectionalDerivative");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference a[], size_t b, const fmi2Integer d[],
                                       const fmi2Real e[]) {
    (void)a; (void)b; (void)d; (void)e; REFUSE("fmi2SetRealInputDerivatives");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference a[], size_t b, const fmi2Integer d[],
                                        fmi2Real e[]) {
    (void)a; (void)b; (void)d; (void)e; REFUSE("fmi2GetRealOutputDerivatives");
}

/*
 * A small FMI 3.0 co-simulation runtime for the conformance FMUs (fmus/conformance/<name>/model.c).
 *
 * It exists beside fmus/common because the conformance FMUs need what the shared framework does not
 * offer: every FMI 3.0 type (Float32, Int8..UInt64, Enumeration, String, Binary, Clock), arrays whose
 * size is a structural parameter (set in Configuration Mode), and doStep ending the simulation early
 * (terminateSimulation, earlyReturn, lastSuccessfulTime).
 *
 * A model.c defines `struct Model`, then includes this file, then implements:
 *   static bool model_variable(Instance *I, fmi3ValueReference vr, Var *v)
 *       where variable `vr` lives: type, data pointer, element count now, kind (what may set it).
 *   static void model_start(Instance *I)            start values (instantiate and reset)
 *   static fmi3Status model_exit_init(Instance *I)   check parameters, initial outputs
 *   static fmi3Status model_step(Instance *I, double t, double h, double *stop_at)
 *       advance from t to t + h; set *stop_at to a time in (t, t + h] to end the simulation there.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define STR_LEN 64 /* longest String value + 1 */
#define BIN_LEN 64 /* longest Binary value */

typedef struct { size_t size; fmi3Byte bytes[BIN_LEN]; } Bin;
typedef char Str[STR_LEN];

typedef enum { T_F32, T_F64, T_I8, T_U8, T_I16, T_U16, T_I32, T_U32, T_I64, T_U64, T_BOOL, T_STR, T_BIN, T_CLOCK } VType;
/* Who may set a variable: nobody (outputs, locals, time), parameters before the step mode,
 * inputs at any time, structural parameters in Configuration Mode only. */
typedef enum { K_READ_ONLY, K_PARAMETER, K_INPUT, K_STRUCTURAL } VKind;
typedef enum { S_INSTANTIATED, S_CONFIGURATION, S_INITIALIZATION, S_STEP, S_TERMINATED } RunState;

typedef struct { VType type; void *data; size_t count; VKind kind; } Var;

typedef struct Instance {
    char name[128];
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback logger;
    bool early_return_allowed;
    RunState state;
    double time;
    struct Model m;
} Instance;

static bool model_variable(Instance *I, fmi3ValueReference vr, Var *v);
static void model_start(Instance *I);
static fmi3Status model_exit_init(Instance *I);
static fmi3Status model_step(Instance *I, double t, double h, double *stop_at);

static void log_error(Instance *I, const char *fmt, ...) {
    char text[512];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    if (I && I->logger) I->logger(I->environment, fmi3Error, "logStatusError", text);
}

static const char *TYPE_NAMES[] = {"Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32",
                                   "Int64", "UInt64", "Boolean", "String", "Binary", "Clock"};
static const size_t TYPE_SIZES[] = {sizeof(fmi3Float32), sizeof(fmi3Float64), 1, 1, 2, 2, 4, 4, 8, 8,
                                    sizeof(fmi3Boolean), sizeof(Str), sizeof(Bin), sizeof(fmi3Clock)};

/* The variable `vr` if it exists and has `type`; logs and returns false otherwise. */
static bool find(Instance *I, fmi3ValueReference vr, VType type, const char *call, Var *v) {
    if (!model_variable(I, vr, v)) {
        log_error(I, "%s: no variable has value reference %u", call, vr);
        return false;
    }
    if (v->type != type) {
        log_error(I, "%s: variable %u is %s, not %s", call, vr, TYPE_NAMES[v->type], TYPE_NAMES[type]);
        return false;
    }
    return true;
}

static bool may_set(Instance *I, const Var *v, fmi3ValueReference vr, const char *call) {
    bool ok = (v->kind == K_INPUT && I->state != S_TERMINATED) ||
              (v->kind == K_PARAMETER && (I->state == S_INSTANTIATED || I->state == S_INITIALIZATION)) ||
              (v->kind == K_STRUCTURAL && I->state == S_CONFIGURATION);
    if (!ok) log_error(I, "%s: variable %u cannot be set now%s", call, vr,
                       v->kind == K_STRUCTURAL ? " (a structural parameter: set it in Configuration Mode)" : "");
    return ok;
}

/* get/set for the plain-memory types: copy count elements per value reference. */
static fmi3Status get_plain(Instance *I, VType type, const char *call, const fmi3ValueReference vr[], size_t nvr,
                            void *values, size_t nValues) {
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        Var v;
        if (!find(I, vr[i], type, call, &v)) return fmi3Error;
        if (at + v.count > nValues) { log_error(I, "%s: nValues %zu is too small", call, nValues); return fmi3Error; }
        memcpy((char *)values + at * TYPE_SIZES[type], v.data, v.count * TYPE_SIZES[type]);
        at += v.count;
    }
    if (at != nValues) { log_error(I, "%s: nValues is %zu, the variables have %zu", call, nValues, at); return fmi3Error; }
    return fmi3OK;
}

static fmi3Status set_plain(Instance *I, VType type, const char *call, const fmi3ValueReference vr[], size_t nvr,
                            const void *values, size_t nValues) {
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        Var v;
        if (!find(I, vr[i], type, call, &v) || !may_set(I, &v, vr[i], call)) return fmi3Error;
        if (at + v.count > nValues) { log_error(I, "%s: nValues %zu is too small", call, nValues); return fmi3Error; }
        memcpy(v.data, (const char *)values + at * TYPE_SIZES[type], v.count * TYPE_SIZES[type]);
        at += v.count;
    }
    if (at != nValues) { log_error(I, "%s: nValues is %zu, the variables have %zu", call, nValues, at); return fmi3Error; }
    return fmi3OK;
}

#define PLAIN_ACCESSORS(T, ctype)                                                                              \
    fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, ctype values[],    \
                          size_t nValues) {                                                                    \
        return get_plain((Instance *)instance, T_##T, "fmi3Get" #T, vr, nvr, values, nValues);                 \
    }                                                                                                          \
    fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const ctype values[], \
                          size_t nValues) {                                                                    \
        return set_plain((Instance *)instance, T_##T, "fmi3Set" #T, vr, nvr, values, nValues);                 \
    }

#define T_Float32 T_F32
#define T_Float64 T_F64
#define T_Int8 T_I8
#define T_UInt8 T_U8
#define T_Int16 T_I16
#define T_UInt16 T_U16
#define T_Int32 T_I32
#define T_UInt32 T_U32
#define T_Int64 T_I64
#define T_UInt64 T_U64
#define T_Boolean T_BOOL
PLAIN_ACCESSORS(Float32, fmi3Float32)
PLAIN_ACCESSORS(Float64, fmi3Float64)
PLAIN_ACCESSORS(Int8, fmi3Int8)
PLAIN_ACCESSORS(UInt8, fmi3UInt8)
PLAIN_ACCESSORS(Int16, fmi3Int16)
PLAIN_ACCESSORS(UInt16, fmi3UInt16)
PLAIN_ACCESSORS(Int32, fmi3Int32)
PLAIN_ACCESSORS(UInt32, fmi3UInt32)
PLAIN_ACCESSORS(Int64, fmi3Int64)
PLAIN_ACCESSORS(UInt64, fmi3UInt64)
PLAIN_ACCESSORS(Boolean, fmi3Boolean)

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3String values[],
                         size_t nValues) {
    Instance *I = (Instance *)instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        Var v;
        if (!find(I, vr[i], T_STR, "fmi3GetString", &v)) return fmi3Error;
        for (size_t k = 0; k < v.count && at < nValues; k++) values[at++] = ((Str *)v.data)[k];
    }
    return at == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3String values[],
                         size_t nValues) {
    Instance *I = (Instance *)instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        Var v;
        if (!find(I, vr[i], T_STR, "fmi3SetString", &v) || !may_set(I, &v, vr[i], "fmi3SetString")) return fmi3Error;
        for (size_t k = 0; k < v.count && at < nValues; k++, at++) {
            if (!values[at] || strlen(values[at]) >= STR_LEN) {
                log_error(I, "fmi3SetString: variable %u takes a string of at most %d bytes", vr[i], STR_LEN - 1);
                return fmi3Error;
            }
            strcpy(((Str *)v.data)[k], values[at]);
        }
    }
    return at == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    Instance *I = (Instance *)instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        Var v;
        if (!find(I, vr[i], T_BIN, "fmi3GetBinary", &v)) return fmi3Error;
        for (size_t k = 0; k < v.count && at < nValues; k++, at++) {
            valueSizes[at] = ((Bin *)v.data)[k].size;
            values[at] = ((Bin *)v.data)[k].bytes;
        }
    }
    return at == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    Instance *I = (Instance *)instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        Var v;
        if (!find(I, vr[i], T_BIN, "fmi3SetBinary", &v) || !may_set(I, &v, vr[i], "fmi3SetBinary")) return fmi3Error;
        for (size_t k = 0; k < v.count && at < nValues; k++, at++) {
            if (valueSizes[at] > BIN_LEN) {
                log_error(I, "fmi3SetBinary: variable %u takes at most %d bytes, got %zu", vr[i], BIN_LEN, valueSizes[at]);
                return fmi3Error;
            }
            ((Bin *)v.data)[k].size = valueSizes[at];
            if (valueSizes[at]) memcpy(((Bin *)v.data)[k].bytes, values[at], valueSizes[at]);
        }
    }
    return at == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    return get_plain((Instance *)instance, T_CLOCK, "fmi3GetClock", vr, nvr, values, nvr);
}
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    return set_plain((Instance *)instance, T_CLOCK, "fmi3SetClock", vr, nvr, values, nvr);
}

/* Lifecycle ------------------------------------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t n, const fmi3String c[]) {
    (void)instance; (void)loggingOn; (void)n; (void)c;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String token, fmi3String resourcePath,
                                         fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed, const fmi3ValueReference required[],
                                         size_t nRequired, fmi3InstanceEnvironment environment,
                                         fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback update) {
    (void)token; (void)resourcePath; (void)visible; (void)loggingOn; (void)required; (void)nRequired; (void)update;
    if (eventModeUsed) {
        if (logMessage) logMessage(environment, fmi3Error, "logStatusError", "event mode is not supported");
        return NULL;
    }
    Instance *I = calloc(1, sizeof(Instance));
    if (!I) return NULL;
    snprintf(I->name, sizeof I->name, "%s", instanceName ? instanceName : "");
    I->environment = environment;
    I->logger = logMessage;
    I->early_return_allowed = earlyReturnAllowed;
    I->state = S_INSTANTIATED;
    model_start(I);
    return I;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String a, fmi3String b, fmi3String c, fmi3Boolean d, fmi3Boolean e,
                                          fmi3InstanceEnvironment environment, fmi3LogMessageCallback logMessage) {
    (void)a; (void)b; (void)c; (void)d; (void)e;
    if (logMessage) logMessage(environment, fmi3Error, "logStatusError", "only co-simulation is supported");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String a, fmi3String b, fmi3String c, fmi3Boolean d,
                                               fmi3Boolean e, fmi3InstanceEnvironment environment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback f,
                                               fmi3LockPreemptionCallback g, fmi3UnlockPreemptionCallback h) {
    (void)a; (void)b; (void)c; (void)d; (void)e; (void)f; (void)g; (void)h;
    if (logMessage) logMessage(environment, fmi3Error, "logStatusError", "scheduled execution is not implemented");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { free(instance); }

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    Instance *I = (Instance *)instance;
    if (I->state != S_INSTANTIATED) { log_error(I, "fmi3EnterConfigurationMode: only after instantiation"); return fmi3Error; }
    I->state = S_CONFIGURATION;
    return fmi3OK;
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    Instance *I = (Instance *)instance;
    if (I->state != S_CONFIGURATION) { log_error(I, "fmi3ExitConfigurationMode: not in Configuration Mode"); return fmi3Error; }
    I->state = S_INSTANTIATED;
    return fmi3OK;
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Instance *I = (Instance *)instance;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    I->time = startTime;
    I->state = S_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    Instance *I = (Instance *)instance;
    fmi3Status status = model_exit_init(I);
    if (status <= fmi3Warning) I->state = S_STEP;
    return status;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetPrior,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    Instance *I = (Instance *)instance;
    double stop_at = -1.0;
    fmi3Status status;
    (void)noSetPrior;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    if (I->state != S_STEP) { log_error(I, "fmi3DoStep: not in Step Mode"); return fmi3Error; }
    status = model_step(I, t, h, &stop_at);
    if (status > fmi3Warning) return status;
    I->time = t + h;
    if (stop_at >= 0.0) {
        /* The model ends the simulation at stop_at: within the step it returns there early when the
         * importer allows it, else it completes the step (its outputs stay those of stop_at). */
        *terminateSimulation = fmi3True;
        if (I->early_return_allowed && stop_at < t + h) {
            *earlyReturn = fmi3True;
            I->time = stop_at;
        }
    }
    *lastSuccessfulTime = I->time;
    return status;
}

fmi3Status fmi3Terminate(fmi3Instance instance) { ((Instance *)instance)->state = S_TERMINATED; return fmi3OK; }

fmi3Status fmi3Reset(fmi3Instance instance) {
    Instance *I = (Instance *)instance;
    memset(&I->m, 0, sizeof I->m);
    I->state = S_INSTANTIATED;
    I->time = 0.0;
    model_start(I);
    return fmi3OK;
}

/* What the conformance FMUs do not offer ---------------------------------------------------------------- */

#define REFUSE(call) do { log_error((Instance *)instance, call " is not supported by this FMU"); return fmi3Error; } while (0)

fmi3Status fmi3EnterEventMode(fmi3Instance instance) { REFUSE("fmi3EnterEventMode"); }
fmi3Status fmi3EnterStepMode(fmi3Instance instance) { REFUSE("fmi3EnterStepMode"); }
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference a, size_t *b) {
    (void)a; (void)b; REFUSE("fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference a, size_t b[], fmi3ValueReference c[],
                                       size_t d[], fmi3DependencyKind e[], size_t f) {
    (void)a; (void)b; (void)c; (void)d; (void)e; (void)f; REFUSE("fmi3GetVariableDependencies");
}
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *s) { (void)s; REFUSE("fmi3GetFMUState"); }
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState s) { (void)s; REFUSE("fmi3SetFMUState"); }
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *s) { (void)s; REFUSE("fmi3FreeFMUState"); }
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState s, size_t *n) {
    (void)s; (void)n; REFUSE("fmi3SerializedFMUStateSize");
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState s, fmi3Byte b[], size_t n) {
    (void)s; (void)b; (void)n; REFUSE("fmi3SerializeFMUState");
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte b[], size_t n, fmi3FMUState *s) {
    (void)s; (void)b; (void)n; REFUSE("fmi3DeserializeFMUState");
}
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference a[], size_t b,
                                        const fmi3ValueReference c[], size_t d, const fmi3Float64 e[], size_t f,
                                        fmi3Float64 g[], size_t h) {
    (void)a; (void)b; (void)c; (void)d; (void)e; (void)f; (void)g; (void)h; REFUSE("fmi3GetDirectionalDerivative");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference a[], size_t b,
                                    const fmi3ValueReference c[], size_t d, const fmi3Float64 e[], size_t f,
                                    fmi3Float64 g[], size_t h) {
    (void)a; (void)b; (void)c; (void)d; (void)e; (void)f; (void)g; (void)h; REFUSE("fmi3GetAdjointDerivative");
}
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference a[], size_t b, fmi3Float64 c[],
                                  fmi3IntervalQualifier d[]) {
    (void)a; (void)b; (void)c; (void)d; REFUSE("fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference a[], size_t b, fmi3UInt64 c[],
                                   fmi3UInt64 d[], fmi3IntervalQualifier e[]) {
    (void)a; (void)b; (void)c; (void)d; (void)e; REFUSE("fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference a[], size_t b, fmi3Float64 c[]) {
    (void)a; (void)b; (void)c; REFUSE("fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference a[], size_t b, fmi3UInt64 c[],
                                fmi3UInt64 d[]) {
    (void)a; (void)b; (void)c; (void)d; REFUSE("fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference a[], size_t b, const fmi3Float64 c[]) {
    (void)a; (void)b; (void)c; REFUSE("fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference a[], size_t b, const fmi3UInt64 c[],
                                   const fmi3UInt64 d[]) {
    (void)a; (void)b; (void)c; (void)d; REFUSE("fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference a[], size_t b, const fmi3Float64 c[]) {
    (void)a; (void)b; (void)c; REFUSE("fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference a[], size_t b, const fmi3UInt64 c[],
                                const fmi3UInt64 d[]) {
    (void)a; (void)b; (void)c; (void)d; REFUSE("fmi3SetShiftFraction");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { REFUSE("fmi3EvaluateDiscreteStates"); }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *a, fmi3Boolean *b, fmi3Boolean *c,
                                    fmi3Boolean *d, fmi3Boolean *e, fmi3Float64 *f) {
    (void)a; (void)b; (void)c; (void)d; (void)e; (void)f; REFUSE("fmi3UpdateDiscreteStates");
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) { REFUSE("fmi3EnterContinuousTimeMode"); }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean a, fmi3Boolean *b, fmi3Boolean *c) {
    (void)a; (void)b; (void)c; REFUSE("fmi3CompletedIntegratorStep");
}
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 t) { (void)t; REFUSE("fmi3SetTime"); }
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t n) {
    (void)x; (void)n; REFUSE("fmi3SetContinuousStates");
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 x[], size_t n) {
    (void)x; (void)n; REFUSE("fmi3GetContinuousStateDerivatives");
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 x[], size_t n) {
    (void)x; (void)n; REFUSE("fmi3GetEventIndicators");
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t n) {
    (void)x; (void)n; REFUSE("fmi3GetContinuousStates");
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t n) {
    (void)x; (void)n; REFUSE("fmi3GetNominalsOfContinuousStates");
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *n) { (void)n; REFUSE("fmi3GetNumberOfEventIndicators"); }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *n) { (void)n; REFUSE("fmi3GetNumberOfContinuousStates"); }
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference a[], size_t b, const fmi3Int32 c[],
                                    fmi3Float64 d[], size_t e) {
    (void)a; (void)b; (void)c; (void)d; (void)e; REFUSE("fmi3GetOutputDerivatives");
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference a, fmi3Float64 b) {
    (void)a; (void)b; REFUSE("fmi3ActivateModelPartition");
}

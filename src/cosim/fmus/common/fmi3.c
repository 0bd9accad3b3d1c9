/* FMI 3.0 co-simulation interface on top of the framework (see framework.h);
 * the Model Exchange functions are in fmi3_me.c.
 * Array variables have one value reference; VR k is VARIABLES[k]. */
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "framework.h"

#define COMP ((ModelInstance *)instance)
#define NOT_SUPPORTED(call)                                                        \
    do {                                                                           \
        logError((ModelInstance *)instance, call " is not supported by this FMU"); \
        return fmi3Error;                                                          \
    } while (0)

static void forward_log(ModelInstance *comp, Status status, const char *category, const char *message) {
    fmi3LogMessageCallback logger = (fmi3LogMessageCallback)comp->logger;
    if (logger) logger(comp->environment, (fmi3Status)status, category, message);
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    (void)nCategories;
    (void)categories;
    COMP->loggingOn = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (!HAS_CO_SIMULATION) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "this FMU was built without co-simulation; instantiate it for Model Exchange");
        return NULL;
    }
    if (eventModeUsed) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "event mode is not supported");
        return NULL;
    }
    return framework_instantiate(instanceName, instantiationToken, instanceEnvironment, (AnyFunction)logMessage, forward_log,
                                 loggingOn);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "only co-simulation is supported");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { framework_free(COMP); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    return (fmi3Status)framework_enter_initialization(COMP, startTime);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) { return (fmi3Status)framework_exit_initialization(COMP); }
fmi3Status fmi3Terminate(fmi3Instance instance) { return (fmi3Status)framework_terminate(COMP); }

fmi3Status fmi3Reset(fmi3Instance instance) {
    framework_reset(COMP);
    return fmi3OK;
}

/* Outputs must reflect the inputs set so far: recompute before reading any. */
static Status update_if_reading_outputs(ModelInstance *comp, const fmi3ValueReference vr[], size_t nvr) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] < N_VARIABLES && (VARIABLES[vr[i]].causality == CAUS_OUTPUT || VARIABLES[vr[i]].causality == CAUS_LOCAL))
            return framework_update(comp);
    }
    return OK;
}

#define GET3(fname, fmitype, vtype, ctype)                                                                     \
    fmi3Status fname(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmitype values[],    \
                     size_t nValues) {                                                                      \
        size_t i, j, k = 0;                                                                                 \
        Status status = update_if_reading_outputs(COMP, vr, nvr);                                           \
        for (i = 0; i < nvr; i++) {                                                                         \
            if (framework_check_type(COMP, vr[i], vtype, #fname) > Warning) return fmi3Error;               \
            if (k + VARIABLES[vr[i]].size > nValues) {                                                      \
                logError(COMP, #fname ": %zu values do not hold all elements", nValues);                   \
                return fmi3Error;                                                                           \
            }                                                                                               \
            if (vr[i] == 0) {                                                                               \
                values[k++] = (fmitype)COMP->time;                                                          \
                continue;                                                                                   \
            }                                                                                               \
            for (j = 0; j < VARIABLES[vr[i]].size; j++)                                                     \
                values[k++] = (fmitype) * (ctype *)framework_address(COMP, vr[i], j);                       \
        }                                                                                                   \
        return (fmi3Status)status;                                                                          \
    }

#define SET3(fname, fmitype, vtype, ctype)                                                                     \
    fmi3Status fname(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmitype values[], \
                     size_t nValues) {                                                                         \
        size_t i, j, k = 0;                                                                                    \
        for (i = 0; i < nvr; i++) {                                                                            \
            if (framework_check_set(COMP, vr[i], vtype) > Warning) return fmi3Error;                           \
            if (k + VARIABLES[vr[i]].size > nValues) {                                                         \
                logError(COMP, #fname ": %zu values do not fill all elements", nValues);                      \
                return fmi3Error;                                                                              \
            }                                                                                                  \
            for (j = 0; j < VARIABLES[vr[i]].size; j++)                                                        \
                *(ctype *)framework_address(COMP, vr[i], j) = (ctype)values[k++];                              \
        }                                                                                                      \
        COMP->isDirty = true;                                                                                  \
        return fmi3OK;                                                                                         \
    }

GET3(fmi3GetFloat64, fmi3Float64, VT_REAL, double)
GET3(fmi3GetInt32, fmi3Int32, VT_INTEGER, int32_t)
GET3(fmi3GetBoolean, fmi3Boolean, VT_BOOLEAN, bool)
SET3(fmi3SetFloat64, fmi3Float64, VT_REAL, double)
SET3(fmi3SetInt32, fmi3Int32, VT_INTEGER, int32_t)
SET3(fmi3SetBoolean, fmi3Boolean, VT_BOOLEAN, bool)

/* Types the models never use: an empty request is fine, anything else is an error. */
#define UNUSED_GET3(fname, fmitype)                                                                         \
    fmi3Status fname(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmitype values[],  \
                     size_t nValues) {                                                                    \
        (void)vr; (void)values; (void)nValues;                                                            \
        if (nvr == 0) return fmi3OK;                                                                      \
        NOT_SUPPORTED(#fname " (the model has no variables of this type)");                              \
    }
#define UNUSED_SET3(fname, fmitype)                                                                              \
    fmi3Status fname(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmitype values[], \
                     size_t nValues) {                                                                         \
        (void)vr; (void)values; (void)nValues;                                                                 \
        if (nvr == 0) return fmi3OK;                                                                           \
        NOT_SUPPORTED(#fname " (the model has no variables of this type)");                                   \
    }

UNUSED_GET3(fmi3GetFloat32, fmi3Float32)
UNUSED_GET3(fmi3GetInt8, fmi3Int8)
UNUSED_GET3(fmi3GetUInt8, fmi3UInt8)
UNUSED_GET3(fmi3GetInt16, fmi3Int16)
UNUSED_GET3(fmi3GetUInt16, fmi3UInt16)
UNUSED_GET3(fmi3GetUInt32, fmi3UInt32)
UNUSED_GET3(fmi3GetInt64, fmi3Int64)
UNUSED_GET3(fmi3GetUInt64, fmi3UInt64)
UNUSED_GET3(fmi3GetString, fmi3String)
UNUSED_SET3(fmi3SetFloat32, fmi3Float32)
UNUSED_SET3(fmi3SetInt8, fmi3Int8)
UNUSED_SET3(fmi3SetUInt8, fmi3UInt8)
UNUSED_SET3(fmi3SetInt16, fmi3Int16)
UNUSED_SET3(fmi3SetUInt16, fmi3UInt16)
UNUSED_SET3(fmi3SetUInt32, fmi3UInt32)
UNUSED_SET3(fmi3SetInt64, fmi3Int64)
UNUSED_SET3(fmi3SetUInt64, fmi3UInt64)
UNUSED_SET3(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (nvr == 0) return fmi3OK;
    NOT_SUPPORTED("fmi3GetBinary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (nvr == 0) return fmi3OK;
    NOT_SUPPORTED("fmi3SetBinary");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)vr; (void)nvr; (void)values; NOT_SUPPORTED("fmi3GetClock");
}
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    (void)vr; (void)nvr; (void)values; NOT_SUPPORTED("fmi3SetClock");
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference vr, size_t *n) {
    (void)vr; (void)n; NOT_SUPPORTED("fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    NOT_SUPPORTED("fmi3GetVariableDependencies");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *s) {
    return (fmi3Status)framework_get_state(COMP, s);
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState s) { return (fmi3Status)framework_set_state(COMP, s); }
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *s) {
    (void)instance;
    framework_free_state(s);
    return fmi3OK;
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState s, size_t *n) {
    (void)instance;
    (void)s;
    *n = framework_serialized_size();
    return fmi3OK;
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState s, fmi3Byte b[], size_t n) {
    return (fmi3Status)framework_serialize_state(COMP, s, (char *)b, n);
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte b[], size_t n, fmi3FMUState *s) {
    *s = NULL;
    return (fmi3Status)framework_deserialize_state(COMP, (const char *)b, n, s);
}

/* Array variables contribute one seed / sensitivity entry per element, in order. */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    size_t *index, *element, i, j, n = 0, nz = 0;
    Status status = OK;
    if (!PROVIDES_DIRECTIONAL_DERIVATIVE) NOT_SUPPORTED("fmi3GetDirectionalDerivative");
    for (i = 0; i < nUnknowns + nKnowns; i++) {
        fmi3ValueReference vr = i < nUnknowns ? unknowns[i] : knowns[i - nUnknowns];
        if (vr >= N_VARIABLES || vr == 0) {
            logError(COMP, "fmi3GetDirectionalDerivative: value reference %u is not a variable of this model", (unsigned)vr);
            return fmi3Error;
        }
        n += VARIABLES[vr].size;
        if (i < nUnknowns) nz = n;
    }
    if (nz != nSensitivity || n - nz != nSeed) {
        logError(COMP, "fmi3GetDirectionalDerivative: %zu seed and %zu sensitivity values given, the variables have %zu "
                 "and %zu elements", nSeed, nSensitivity, n - nz, nz);
        return fmi3Error;
    }
    index = malloc((n + 1) * sizeof(size_t));
    element = malloc((n + 1) * sizeof(size_t));
    if (!index || !element) {
        free(index);
        free(element);
        logError(COMP, "fmi3GetDirectionalDerivative: out of memory");
        return fmi3Error;
    }
    n = 0;
    for (i = 0; i < nUnknowns + nKnowns; i++) {
        fmi3ValueReference vr = i < nUnknowns ? unknowns[i] : knowns[i - nUnknowns];
        for (j = 0; j < VARIABLES[vr].size; j++, n++) {
            index[n] = vr;
            element[n] = j;
        }
    }
    status = framework_directional_derivative(COMP, index, element, nz, index + nz, element + nz, n - nz, seed,
                                              sensitivity);
    free(index);
    free(element);
    return (fmi3Status)status;
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    NOT_SUPPORTED("fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { NOT_SUPPORTED("fmi3EnterConfigurationMode"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { NOT_SUPPORTED("fmi3ExitConfigurationMode"); }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)intervals; (void)qualifiers; NOT_SUPPORTED("fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers; NOT_SUPPORTED("fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts; NOT_SUPPORTED("fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; NOT_SUPPORTED("fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    (void)vr; (void)nvr; (void)intervals; NOT_SUPPORTED("fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; NOT_SUPPORTED("fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts; NOT_SUPPORTED("fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; NOT_SUPPORTED("fmi3SetShiftFraction");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { NOT_SUPPORTED("fmi3EvaluateDiscreteStates"); }
fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    /* Without event mode the instance is in step mode after initialization already. */
    return COMP->state == STATE_STEP ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    NOT_SUPPORTED("fmi3GetOutputDerivatives");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Status status;
    (void)noSetFMUStatePriorToCurrentPoint;
    status = framework_do_step(COMP, currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = COMP->time;
    return (fmi3Status)status;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    NOT_SUPPORTED("fmi3ActivateModelPartition");
}

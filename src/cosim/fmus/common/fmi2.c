/* FMI 2.0 co-simulation interface on top of the framework (see framework.h);
 * the Model Exchange functions are in fmi2_me.c.
 * Arrays appear as one scalar per element; VRs are the generated flat numbering. */
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "framework.h"

#define COMP ((ModelInstance *)c)
#define NOT_SUPPORTED(call)                                            \
    do {                                                               \
        logError((ModelInstance *)c, call " is not supported by this FMU"); \
        return fmi2Error;                                              \
    } while (0)

static void forward_log(ModelInstance *comp, Status status, const char *category, const char *message) {
    fmi2CallbackLogger logger = (fmi2CallbackLogger)comp->logger;
    /* The FMI 2.0 logger takes a printf format: double every '%' of the
     * already formatted message so that it is printed as it is. */
    char escaped[2048];
    size_t i, j = 0;
    for (i = 0; message[i] && j + 2 < sizeof escaped; i++) {
        if (message[i] == '%') escaped[j++] = '%';
        escaped[j++] = message[i];
    }
    escaped[j] = '\0';
    if (logger) logger(comp->environment, comp->instanceName, (fmi2Status)status, category, escaped);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[]) {
    (void)nCategories;
    (void)categories;
    COMP->loggingOn = loggingOn ? true : false;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    ModelInstance *comp;
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->logger) return NULL;
    if ((fmuType == fmi2CoSimulation && !HAS_CO_SIMULATION) || (fmuType == fmi2ModelExchange && !HAS_MODEL_EXCHANGE)) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                          fmuType == fmi2CoSimulation ? "this FMU was built without co-simulation"
                                                      : "this FMU was built without Model Exchange");
        return NULL;
    }
    comp = framework_instantiate(instanceName, fmuGUID, functions->componentEnvironment,
                                 (AnyFunction)functions->logger, forward_log, loggingOn ? true : false);
    if (comp) comp->modelExchange = fmuType == fmi2ModelExchange;
    return comp;
}

void fmi2FreeInstance(fmi2Component c) { framework_free(COMP); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (COMP->state != STATE_INSTANTIATED) {
        logError(COMP, "fmi2SetupExperiment is only allowed after instantiation or reset");
        return fmi2Error;
    }
    COMP->startTime = startTime;
    COMP->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    return (fmi2Status)framework_enter_initialization(COMP, COMP->startTime);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return (fmi2Status)framework_exit_initialization(COMP); }
fmi2Status fmi2Terminate(fmi2Component c) { return (fmi2Status)framework_terminate(COMP); }

fmi2Status fmi2Reset(fmi2Component c) {
    framework_reset(COMP);
    return fmi2OK;
}

/* Finds the variable of FMI 2.0 value reference `vr`; Error for unknown ones. */
static Status lookup(ModelInstance *comp, fmi2ValueReference vr, VariableType type, const char *function,
                     size_t *index, size_t *element) {
    if (vr >= N_SCALARS) {
        logError(comp, "%s: unknown value reference %u", function, (unsigned)vr);
        return Error;
    }
    *index = VR2_VARIABLE[vr];
    *element = vr - VARIABLES[*index].vr2;
    return framework_check_type(comp, *index, type, function);
}

/* Outputs must reflect the inputs set so far: recompute before reading any. */
static Status update_if_reading_outputs(ModelInstance *comp, const fmi2ValueReference vr[], size_t nvr) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] < N_SCALARS) {
            Causality causality = VARIABLES[VR2_VARIABLE[vr[i]]].causality;
            if (causality == CAUS_OUTPUT || causality == CAUS_LOCAL) return framework_update(comp);
        }
    }
    return OK;
}

#define GET2(fname, fmitype, vtype, ctype, conv)                                                  \
    fmi2Status fname(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmitype value[]) { \
        size_t i, index, element;                                                                 \
        Status status = update_if_reading_outputs(COMP, vr, nvr);                                 \
        for (i = 0; i < nvr; i++) {                                                               \
            if (lookup(COMP, vr[i], vtype, #fname, &index, &element) > Warning) return fmi2Error; \
            if (index == 0) {                                                                     \
                value[i] = (fmitype)COMP->time;                                                   \
            } else {                                                                              \
                ctype v = *(ctype *)framework_address(COMP, index, element);                      \
                value[i] = conv;                                                                  \
            }                                                                                     \
        }                                                                                         \
        return (fmi2Status)status;                                                                \
    }

GET2(fmi2GetReal, fmi2Real, VT_REAL, double, v)
GET2(fmi2GetInteger, fmi2Integer, VT_INTEGER, int32_t, (fmi2Integer)v)
GET2(fmi2GetBoolean, fmi2Boolean, VT_BOOLEAN, bool, v ? fmi2True : fmi2False)

#define SET2(fname, fmitype, vtype, ctype, conv)                                                        \
    fmi2Status fname(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmitype value[]) { \
        size_t i, index, element;                                                                       \
        for (i = 0; i < nvr; i++) {                                                                     \
            if (lookup(COMP, vr[i], vtype, #fname, &index, &element) > Warning) return fmi2Error;       \
            if (framework_check_set(COMP, index, vtype) > Warning) return fmi2Error;                    \
            *(ctype *)framework_address(COMP, index, element) = conv;                                   \
        }                                                                                               \
        COMP->isDirty = true;                                                                           \
        return fmi2OK;                                                                                  \
    }

SET2(fmi2SetReal, fmi2Real, VT_REAL, double, value[i])
SET2(fmi2SetInteger, fmi2Integer, VT_INTEGER, int32_t, (int32_t)value[i])
SET2(fmi2SetBoolean, fmi2Boolean, VT_BOOLEAN, bool, value[i] ? true : false)

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)vr; (void)value;
    if (nvr == 0) return fmi2OK;
    NOT_SUPPORTED("fmi2GetString (the model has no String variables)");
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)vr; (void)value;
    if (nvr == 0) return fmi2OK;
    NOT_SUPPORTED("fmi2SetString (the model has no String variables)");
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { return (fmi2Status)framework_get_state(COMP, s); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { return (fmi2Status)framework_set_state(COMP, s); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)c;
    framework_free_state(s);
    return fmi2OK;
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c;
    (void)s;
    *n = framework_serialized_size();
    return fmi2OK;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    return (fmi2Status)framework_serialize_state(COMP, s, b, n);
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    *s = NULL;
    return (fmi2Status)framework_deserialize_state(COMP, b, n, s);
}
/* FMI 2.0 argument order: the unknowns z (vUnknown_ref) first, then the knowns u (vKnown_ref) and their seed. */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference z[], size_t nz,
                                        const fmi2ValueReference u[], size_t nu, const fmi2Real du[], fmi2Real dz[]) {
    size_t *index, *element, i;
    Status status = OK;
    if (!PROVIDES_DIRECTIONAL_DERIVATIVE) NOT_SUPPORTED("fmi2GetDirectionalDerivative");
    index = malloc((nz + nu + 1) * sizeof(size_t));
    element = malloc((nz + nu + 1) * sizeof(size_t));
    if (!index || !element) {
        free(index);
        free(element);
        logError(COMP, "fmi2GetDirectionalDerivative: out of memory");
        return fmi2Error;
    }
    for (i = 0; i < nz + nu && status <= Warning; i++)
        status = lookup(COMP, i < nz ? z[i] : u[i - nz], VT_REAL, "fmi2GetDirectionalDerivative", &index[i], &element[i]);
    if (status <= Warning)
        status = framework_directional_derivative(COMP, index, element, nz, index + nz, element + nz, nu, du, dz);
    free(index);
    free(element);
    return (fmi2Status)status;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    NOT_SUPPORTED("fmi2SetRealInputDerivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    NOT_SUPPORTED("fmi2GetRealOutputDerivatives");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)framework_do_step(COMP, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c) { NOT_SUPPORTED("fmi2CancelStep"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { (void)s; (void)v; NOT_SUPPORTED("fmi2GetStatus"); }

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    if (s == fmi2LastSuccessfulTime) {
        *v = COMP->time;
        return fmi2OK;
    }
    NOT_SUPPORTED("fmi2GetRealStatus");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { (void)s; (void)v; NOT_SUPPORTED("fmi2GetIntegerStatus"); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) { (void)s; (void)v; NOT_SUPPORTED("fmi2GetBooleanStatus"); }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { (void)s; (void)v; NOT_SUPPORTED("fmi2GetStringStatus"); }

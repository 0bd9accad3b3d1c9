/* FMI 3.0 Model Exchange functions on top of the framework (see model_exchange.h). */
#include "fmi3Functions.h"
#include "model_exchange.h"

#define COMP ((ModelInstance *)instance)

static void forward_log(ModelInstance *comp, Status status, const char *category, const char *message) {
    fmi3LogMessageCallback logger = (fmi3LogMessageCallback)comp->logger;
    if (logger) logger(comp->environment, (fmi3Status)status, category, message);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    ModelInstance *comp;
    (void)resourcePath; (void)visible;
    if (!HAS_MODEL_EXCHANGE) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "this FMU was built without Model Exchange; instantiate it for co-simulation");
        return NULL;
    }
    comp = framework_instantiate(instanceName, instantiationToken, instanceEnvironment, (AnyFunction)logMessage,
                                 forward_log, loggingOn);
    if (comp) comp->modelExchange = true;
    return comp;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) { return (fmi3Status)me_enter_event_mode(COMP); }

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    EventInfo info;
    Status status = me_update_discrete_states(COMP, &info);
    if (status > Warning) return (fmi3Status)status;
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = info.newDiscreteStatesNeeded;
    if (terminateSimulation) *terminateSimulation = info.terminateSimulation;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = info.nominalsOfContinuousStatesChanged;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = info.valuesOfContinuousStatesChanged;
    if (nextEventTimeDefined) *nextEventTimeDefined = info.nextEventTimeDefined;
    if (nextEventTime) *nextEventTime = info.nextEventTime;
    return (fmi3Status)status;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return (fmi3Status)me_enter_continuous_time_mode(COMP);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    bool event = false, terminate = false;
    Status status;
    (void)noSetFMUStatePriorToCurrentPoint;
    status = me_completed_integrator_step(COMP, &event, &terminate);
    if (enterEventMode) *enterEventMode = event;
    if (terminateSimulation) *terminateSimulation = terminate;
    return (fmi3Status)status;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) { return (fmi3Status)me_set_time(COMP, time); }

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t n) {
    return (fmi3Status)me_set_states(COMP, x, n);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 dx[], size_t n) {
    return (fmi3Status)me_get_derivatives(COMP, dx, n);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 z[], size_t n) {
    return (fmi3Status)me_get_event_indicators(COMP, z, n);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t n) {
    return (fmi3Status)me_get_states(COMP, x, n);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t n) {
    return (fmi3Status)me_get_nominals(COMP, x, n);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *n) {
    (void)instance;
    *n = N_EVENT_INDICATORS;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *n) {
    (void)instance;
    *n = N_STATES;
    return fmi3OK;
}

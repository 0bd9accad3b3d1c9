/* FMI 2.0 Model Exchange functions on top of the framework (see model_exchange.h). */
#include "fmi2Functions.h"
#include "model_exchange.h"

#define COMP ((ModelInstance *)c)

fmi2Status fmi2EnterEventMode(fmi2Component c) { return (fmi2Status)me_enter_event_mode(COMP); }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    EventInfo info;
    Status status = me_update_discrete_states(COMP, &info);
    if (status > Warning) return (fmi2Status)status;
    eventInfo->newDiscreteStatesNeeded = info.newDiscreteStatesNeeded;
    eventInfo->terminateSimulation = info.terminateSimulation;
    eventInfo->nominalsOfContinuousStatesChanged = info.nominalsOfContinuousStatesChanged;
    eventInfo->valuesOfContinuousStatesChanged = info.valuesOfContinuousStatesChanged;
    eventInfo->nextEventTimeDefined = info.nextEventTimeDefined;
    eventInfo->nextEventTime = info.nextEventTime;
    return (fmi2Status)status;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return (fmi2Status)me_enter_continuous_time_mode(COMP); }

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    bool event = false, terminate = false;
    Status status;
    (void)noSetFMUStatePriorToCurrentPoint;
    status = me_completed_integrator_step(COMP, &event, &terminate);
    if (enterEventMode) *enterEventMode = event ? fmi2True : fmi2False;
    if (terminateSimulation) *terminateSimulation = terminate ? fmi2True : fmi2False;
    return (fmi2Status)status;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) { return (fmi2Status)me_set_time(COMP, time); }

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    return (fmi2Status)me_set_states(COMP, x, nx);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    return (fmi2Status)me_get_derivatives(COMP, derivatives, nx);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    return (fmi2Status)me_get_event_indicators(COMP, eventIndicators, ni);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    return (fmi2Status)me_get_states(COMP, x, nx);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    return (fmi2Status)me_get_nominals(COMP, x_nominal, nx);
}

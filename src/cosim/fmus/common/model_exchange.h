/*
 * The Model Exchange part of the framework (FMI 2.0 and 3.0), shared by
 * fmi2_me.c and fmi3_me.c.  Every FMU links it; only models whose model.json
 * lists "ModelExchange" in "interfaces" can be instantiated that way.
 *
 * What a Model Exchange model declares in model.json:
 *   - continuous states: a Real variable whose entry names it in "derivative"
 *     is the derivative of that state (e.g. {"name": "der_h", "derivative": "h"});
 *   - "eventIndicators": Real variables whose sign changes are state events;
 *   - "needsCompletedIntegratorStep": true when model_step_event may ask for events.
 * The generator writes the tables below (offsets into ModelData) from it.
 *
 * What its model.c adds to the four functions of framework.h:
 *   model_calculate     also computes the derivative and event-indicator
 *                       variables from time, states and inputs;
 *   Status model_event_update(ModelInstance *comp, EventInfo *info)
 *                       in Event Mode, at comp->time: handle time and state
 *                       events (change discrete variables, re-initialise states
 *                       and set info->valuesOfContinuousStatesChanged), and
 *                       announce the next time event in info;
 *   bool model_step_event(ModelInstance *comp)
 *                       after each completed integrator step: true asks the
 *                       environment for an event (a "step event").
 * The generator supplies harmless defaults of the last two for models that
 * do not offer Model Exchange (no states, no events).
 */
#ifndef COSIM_MODEL_EXCHANGE_H
#define COSIM_MODEL_EXCHANGE_H

#include "framework.h"

/* Generated (model_generated.c): where states, derivatives and indicators live in ModelData.
 * The arrays have at least one entry so that they are valid C even when N_STATES is 0. */
extern const size_t STATE_OFFSETS[];
extern const size_t DERIVATIVE_OFFSETS[];
extern const size_t EVENT_INDICATOR_OFFSETS[];

Status model_event_update(ModelInstance *comp, EventInfo *info);
bool model_step_event(ModelInstance *comp);

/* The FMI-version independent Model Exchange calls; each checks the mode and sizes, logs and returns Error on misuse. */
Status me_set_time(ModelInstance *comp, double time);
Status me_set_states(ModelInstance *comp, const double x[], size_t n);
Status me_get_states(ModelInstance *comp, double x[], size_t n);
Status me_get_nominals(ModelInstance *comp, double nominals[], size_t n);
Status me_get_derivatives(ModelInstance *comp, double dx[], size_t n);
Status me_get_event_indicators(ModelInstance *comp, double z[], size_t n);
Status me_enter_event_mode(ModelInstance *comp);
/* One event-iteration step; the result is in *info (and comp->event). */
Status me_update_discrete_states(ModelInstance *comp, EventInfo *info);
Status me_enter_continuous_time_mode(ModelInstance *comp);
Status me_completed_integrator_step(ModelInstance *comp, bool *enterEventMode, bool *terminateSimulation);

#endif

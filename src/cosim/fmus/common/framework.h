/*
 * The shared co-simulation framework of cosim's FMUs.
 *
 * One model = one model.c (the equations) + one model.json (the variables).
 * fmus/model_description.py generates model_generated.h/.c from model.json
 * (the ModelData struct holding every variable, the variable table, the
 * value-reference constants and setStartValues); fmi2.c and fmi3.c turn the
 * small model API below into the FMI 2.0 and FMI 3.0 co-simulation
 * interfaces, so the same model.c is compiled into both FMUs.
 *
 * The model API (implemented by model.c):
 *   Status model_validate(ModelInstance *comp)
 *       at exitInitializationMode: check parameters; log and return Error
 *       for values the model cannot run with.
 *   void model_initialize(ModelInstance *comp)
 *       after a successful validation: set initial states (e.g. x = x0).
 *   Status model_calculate(ModelInstance *comp)
 *       compute outputs from the current inputs and states (direct
 *       feed-through); called before outputs are read after an input changed.
 *   Status model_do_step(ModelInstance *comp, double t, double h)
 *       advance the states from t to t + h with the inputs held constant.
 * Errors are reported with logError(comp, ...), which formats like printf.
 */
#ifndef COSIM_FRAMEWORK_H
#define COSIM_FRAMEWORK_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "model_generated.h"

/* Same numeric values as fmi2Status and fmi3Status. */
typedef enum { OK = 0, Warning = 1, Discard = 2, Error = 3, Fatal = 4 } Status;

typedef enum { VT_REAL, VT_INTEGER, VT_BOOLEAN } VariableType;
typedef enum { CAUS_INDEPENDENT, CAUS_PARAMETER, CAUS_INPUT, CAUS_OUTPUT, CAUS_LOCAL } Causality;

typedef struct {
    const char *name;
    VariableType type;
    Causality causality;
    size_t size;   /* number of elements, 1 for scalars */
    size_t offset; /* offsetof(ModelData, <name>) */
    uint32_t vr2;  /* FMI 2.0 value reference of the first element */
    bool tunable;  /* a parameter that may be set after initialization (FMI variability "tunable") */
    bool exact_start; /* an output or local with initial="exact": its start value may be set before exitInitialization */
} VariableInfo;

extern const VariableInfo VARIABLES[N_VARIABLES];
extern const uint16_t VR2_VARIABLE[N_SCALARS];
void setStartValues(ModelData *d);

typedef enum {
    STATE_INSTANTIATED,
    STATE_INITIALIZATION,
    STATE_STEP,
    STATE_TERMINATED,
    STATE_ERROR,
    STATE_EVENT,     /* Model Exchange: Event Mode (also right after initialization) */
    STATE_CONTINUOUS /* Model Exchange: Continuous-Time Mode */
} ModelState;

/* Model Exchange: what one event update found (fmi2EventInfo / the outputs of
 * fmi3UpdateDiscreteStates); filled by model_event_update, see model_exchange.h. */
typedef struct {
    bool newDiscreteStatesNeeded;
    bool terminateSimulation;
    bool nominalsOfContinuousStatesChanged;
    bool valuesOfContinuousStatesChanged;
    bool nextEventTimeDefined;
    double nextEventTime;
} EventInfo;

struct ModelInstance;
/* Any function pointer: the FMI version's logger callback is stored as this
 * (function pointers convert to each other in ISO C, not to void *). */
typedef void (*AnyFunction)(void);
/* Forwards one formatted message to the FMI version's logger callback. */
typedef void (*LogFunction)(struct ModelInstance *comp, Status status, const char *category, const char *message);

typedef struct ModelInstance {
    char *instanceName;
    double time;
    double startTime;
    ModelState state;
    bool loggingOn;
    bool isDirty;       /* inputs or states changed since outputs were computed */
    void *environment;  /* fmi2 componentEnvironment / fmi3 instanceEnvironment */
    AnyFunction logger; /* the FMI version's callback, called through log */
    LogFunction log;
    bool modelExchange; /* instantiated as Model Exchange (else co-simulation) */
    EventInfo event;    /* Model Exchange: the last event update's result */
    ModelData d;
} ModelInstance;

/* The model API (see the top of this file). */
Status model_validate(ModelInstance *comp);
void model_initialize(ModelInstance *comp);
Status model_calculate(ModelInstance *comp);
Status model_do_step(ModelInstance *comp, double t, double h);

/* Logging: errors and warnings always reach the callback, info only when logging is on. */
void logError(ModelInstance *comp, const char *fmt, ...);
void logInfo(ModelInstance *comp, const char *fmt, ...);

/* Framework core shared by fmi2.c and fmi3.c. */
ModelInstance *framework_instantiate(const char *instanceName, const char *token, void *environment,
                                     AnyFunction logger, LogFunction log, bool loggingOn);
void framework_free(ModelInstance *comp);
void framework_reset(ModelInstance *comp);
Status framework_enter_initialization(ModelInstance *comp, double startTime);
Status framework_exit_initialization(ModelInstance *comp);
Status framework_do_step(ModelInstance *comp, double t, double h);
Status framework_terminate(ModelInstance *comp);
/* Saved FMU states (fmi2GetFMUstate / fmi3GetFMUState and their Set/Free/Serialize companions): a copy of
 * everything an instance changes while it runs (time, mode, the ModelData struct), never of its name or
 * callbacks. `*state` NULL: a new state is allocated; else the given one is overwritten (as FMI allows). */
Status framework_get_state(ModelInstance *comp, void **state);
Status framework_set_state(ModelInstance *comp, const void *state);
void framework_free_state(void **state);
/* Serialized: the saved state's bytes plus a header naming the model build (its instantiation token). */
size_t framework_serialized_size(void);
Status framework_serialize_state(ModelInstance *comp, const void *state, char *bytes, size_t size);
Status framework_deserialize_state(ModelInstance *comp, const char *bytes, size_t size, void **state);
/* Directional derivatives (model.json "directionalDerivatives": true; PROVIDES_DIRECTIONAL_DERIVATIVE):
 *   Status model_partial(ModelInstance *comp, size_t unknown, size_t unknownElement, size_t known,
 *                        size_t knownElement, double *value)
 * gives d(unknown[unknownElement]) / d(known[knownElement]) at the current inputs and states (indices into
 * VARIABLES, 0-based elements; 0 where the unknown does not depend on the known).  The framework composes
 * fmi2GetDirectionalDerivative / fmi3GetDirectionalDerivative from it: dz_i = sum_j partial(z_i, v_j) dv_j. */
Status model_partial(ModelInstance *comp, size_t unknown, size_t unknownElement, size_t known, size_t knownElement,
                     double *value);
/* sensitivity[i] = sum_j d(unknown i)/d(known j) * seed[j] over scalar elements given as (index, element) pairs;
 * Error when the model supplies no partials or a variable is not Real. */
Status framework_directional_derivative(ModelInstance *comp, const size_t unknowns[], const size_t unknownElements[],
                                        size_t nUnknowns, const size_t knowns[], const size_t knownElements[],
                                        size_t nKnowns, const double seed[], double sensitivity[]);
/* Make outputs current (calls model_calculate when inputs changed). */
Status framework_update(ModelInstance *comp);
/* Where element `element` of variable `index` lives; NULL for time. */
void *framework_address(ModelInstance *comp, size_t index, size_t element);
/* Checks that variable `index` of `type` may be set now; logs and returns Error otherwise. */
Status framework_check_set(ModelInstance *comp, size_t index, VariableType type);
/* Checks that `index` names a variable of `type`; logs and returns Error otherwise. */
Status framework_check_type(ModelInstance *comp, size_t index, VariableType type, const char *function);
/* Logs and returns Error when `value` (element `element`, 0-based, of `name`;
 * SCALAR for a scalar) is NaN or infinite. */
#define SCALAR ((size_t)-1)
Status check_finite(ModelInstance *comp, const char *name, size_t element, double value);

#endif

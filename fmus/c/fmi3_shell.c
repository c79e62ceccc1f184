/* FMI 3.0 Co-Simulation interface over the sblsim runtime, generic over the model tables.
 *
 * Compile with -DSBLSIM_MODEL=<model symbol> and -DSBLSIM_FMI3_TABLE=<FMI 3.0 variable table symbol> (e.g.
 * sblsim_platform_model and sblsim_platform_fmi3) together with the model's generated sources, its FMI 3.0
 * table (sblsim_fmi3.h), sblsim_runtime.c and sblsim_fmu_state.c (the FMU state, shared with FMI 2.0).
 * Everything the FMU needs is in these sources: no Python, no environment variables, no resource files; any
 * number of instances. The FMI 2.0 twin is fmi2_shell.c.
 *
 * FMI semantics (docs/model.md, "FMI semantics"), as in FMI 2.0 where FMI 3.0 allows it:
 *  - every function first checks the instance's state against one table of the states it is
 *    allowed in (the FMI 3.0 Co-Simulation state machine); a call in another state returns
 *    fmi3Error and logs "<function>: not allowed in state <state>";
 *  - Event Mode (hasEventMode="true") for an importer that uses it (eventModeUsed): fmi3ExitInitializationMode
 *    then goes to Event Mode, fmi3UpdateDiscreteStates has nothing to update, fmi3EnterStepMode leaves it;
 *    without it, fmi3ExitInitializationMode goes to Step Mode and fmi3EnterEventMode is refused;
 *  - variables are scalars or arrays (sblsim_fmi3.h): a get or set copies the values of every element of
 *    every value reference in turn, and nValues must be their number exactly (fmi3Error and a log line
 *    otherwise); a refused set changes nothing;
 *  - parameters are fixed: set in the instantiated or initialization mode, checked against
 *    their declared ranges at fmi3ExitInitializationMode (fmi3Error and a log line otherwise);
 *  - the structural parameter (the beacon count) is compiled in: fmi3GetUInt64 returns it and fmi3SetUInt64
 *    accepts that value alone, before fmi3ExitInitializationMode (no Configuration Mode is needed);
 *  - fmi3SetFloat64 and fmi3SetInt32 refuse a value outside an input's declared range (and any value that is
 *    not finite) with fmi3Error and a log line;
 *  - fmi3DoStep refuses h <= 0 and a communication point other than the FMU's time (a gap or
 *    an overlap) with fmi3Error and a log line; it never asks to terminate. The channel, in an instance made
 *    with earlyReturnAllowed, returns early at an acoustic arrival inside the step (see step()): the packet is
 *    in its outputs at lastSuccessfulTime = its arrival epoch, and an importer in Event Mode is told
 *    eventHandlingNeeded. Without earlyReturnAllowed it steps as the FMI 2.0 FMU does, to the same numbers;
 *  - errors are always logged (whatever fmi3SetDebugLogging says);
 *  - the state (every vector, the draw counters, the time) can be got, set and serialized; a serialized
 *    state is checked before it is taken (sblsim_fmu_state.c: times finite and ordered, every value finite,
 *    the inputs within their ranges, the parameters within theirs past initialization, a known state number):
 *    fmi3Error and a log line
 *    otherwise, and the caller's state object is left as it was;
 *  - Model Exchange, Scheduled Execution, clocks, Configuration Mode, derivatives and the types the FMU has
 *    no variable of are refused with fmi3Error and a log line saying why.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "sblsim_fmi3.h"
#include "sblsim_fmu_state.h"
#include "sblsim_runtime.h"

#ifndef SBLSIM_MODEL
#error "define SBLSIM_MODEL as the model symbol, e.g. -DSBLSIM_MODEL=sblsim_platform_model"
#endif
#ifndef SBLSIM_FMI3_TABLE
#error "define SBLSIM_FMI3_TABLE as the FMI 3.0 table symbol, e.g. -DSBLSIM_FMI3_TABLE=sblsim_platform_fmi3"
#endif

extern const sblsim_model SBLSIM_MODEL;
extern const sblsim_fmi3_table SBLSIM_FMI3_TABLE;

/* The states of the FMI 3.0 Co-Simulation state machine (FMI 3.0.1, chapter 4) this FMU can be in. It has no
   Event Mode, no Configuration Mode and no intermediate update; doStep always runs to its end and a failed step
   returns fmi3Error (never fmi3Discard), so EventMode, ConfigurationMode, ReconfigurationMode,
   IntermediateUpdateMode and StepDiscarded are never entered; no call returns fmi3Fatal. Saved states store
   the number: append only. */
typedef enum { INSTANTIATED, INITIALIZATION_MODE, STEP_MODE, TERMINATED, ERROR_STATE, EVENT_MODE, N_STATES } State;
static const char* const state_names[N_STATES] = {"Instantiated", "InitializationMode", "StepMode", "Terminated",
                                                  "Error", "EventMode"};

/* Sets of states, as bits; the groups the standard's table repeats (restricted to the states above). */
#define IN(state) (1u << (state))
#define ANY_STATE (IN(INSTANTIATED) | IN(INITIALIZATION_MODE) | IN(STEP_MODE) | IN(TERMINATED) | IN(ERROR_STATE) | \
                   IN(EVENT_MODE))
#define SETTABLE (IN(INSTANTIATED) | IN(INITIALIZATION_MODE) | IN(STEP_MODE) | IN(EVENT_MODE))
#define INITIALIZED (IN(INITIALIZATION_MODE) | IN(STEP_MODE) | IN(TERMINATED) | IN(ERROR_STATE) | IN(EVENT_MODE))
/* The functions of modes this FMU never enters (Event Mode, Configuration Mode, Clock Activation Mode; Model
   Exchange's Continuous-Time Mode; Scheduled Execution): no state here. */
#define NEVER 0u

/* Every FMI function with an instance, and the states it may be called in. */
typedef enum {
    SET_DEBUG_LOGGING, FREE_INSTANCE, ENTER_INITIALIZATION_MODE, EXIT_INITIALIZATION_MODE, ENTER_EVENT_MODE,
    TERMINATE, RESET,
    GET_FLOAT32, GET_FLOAT64, GET_INT8, GET_UINT8, GET_INT16, GET_UINT16, GET_INT32, GET_UINT32, GET_INT64,
    GET_UINT64, GET_BOOLEAN, GET_STRING, GET_BINARY, GET_CLOCK,
    SET_FLOAT32, SET_FLOAT64, SET_INT8, SET_UINT8, SET_INT16, SET_UINT16, SET_INT32, SET_UINT32, SET_INT64,
    SET_UINT64, SET_BOOLEAN, SET_STRING, SET_BINARY, SET_CLOCK,
    GET_NUMBER_OF_VARIABLE_DEPENDENCIES, GET_VARIABLE_DEPENDENCIES,
    GET_FMU_STATE, SET_FMU_STATE, FREE_FMU_STATE, SERIALIZED_FMU_STATE_SIZE, SERIALIZE_FMU_STATE,
    DESERIALIZE_FMU_STATE, GET_DIRECTIONAL_DERIVATIVE, GET_ADJOINT_DERIVATIVE, ENTER_CONFIGURATION_MODE,
    EXIT_CONFIGURATION_MODE, GET_INTERVAL_DECIMAL, GET_INTERVAL_FRACTION, GET_SHIFT_DECIMAL, GET_SHIFT_FRACTION,
    SET_INTERVAL_DECIMAL, SET_INTERVAL_FRACTION, SET_SHIFT_DECIMAL, SET_SHIFT_FRACTION, EVALUATE_DISCRETE_STATES,
    UPDATE_DISCRETE_STATES,
    ENTER_CONTINUOUS_TIME_MODE, COMPLETED_INTEGRATOR_STEP, SET_TIME, SET_CONTINUOUS_STATES,
    GET_CONTINUOUS_STATE_DERIVATIVES, GET_EVENT_INDICATORS, GET_CONTINUOUS_STATES,
    GET_NOMINALS_OF_CONTINUOUS_STATES, GET_NUMBER_OF_EVENT_INDICATORS, GET_NUMBER_OF_CONTINUOUS_STATES,
    ENTER_STEP_MODE, GET_OUTPUT_DERIVATIVES, DO_STEP, ACTIVATE_MODEL_PARTITION,
    N_CALLS
} Call;

static const struct {
    const char* name;
    unsigned states;
} calls[N_CALLS] = {
    [SET_DEBUG_LOGGING] = {"fmi3SetDebugLogging", ANY_STATE},
    [FREE_INSTANCE] = {"fmi3FreeInstance", ANY_STATE},
    [ENTER_INITIALIZATION_MODE] = {"fmi3EnterInitializationMode", IN(INSTANTIATED)},
    [EXIT_INITIALIZATION_MODE] = {"fmi3ExitInitializationMode", IN(INITIALIZATION_MODE)},
    [ENTER_EVENT_MODE] = {"fmi3EnterEventMode", IN(STEP_MODE)},
    [TERMINATE] = {"fmi3Terminate", IN(STEP_MODE) | IN(EVENT_MODE)},
    [RESET] = {"fmi3Reset", ANY_STATE},
    [GET_FLOAT32] = {"fmi3GetFloat32", INITIALIZED},
    [GET_FLOAT64] = {"fmi3GetFloat64", INITIALIZED},
    [GET_INT8] = {"fmi3GetInt8", INITIALIZED},
    [GET_UINT8] = {"fmi3GetUInt8", INITIALIZED},
    [GET_INT16] = {"fmi3GetInt16", INITIALIZED},
    [GET_UINT16] = {"fmi3GetUInt16", INITIALIZED},
    [GET_INT32] = {"fmi3GetInt32", INITIALIZED},
    [GET_UINT32] = {"fmi3GetUInt32", INITIALIZED},
    [GET_INT64] = {"fmi3GetInt64", INITIALIZED},
    [GET_UINT64] = {"fmi3GetUInt64", INITIALIZED},
    [GET_BOOLEAN] = {"fmi3GetBoolean", INITIALIZED},
    [GET_STRING] = {"fmi3GetString", INITIALIZED},
    [GET_BINARY] = {"fmi3GetBinary", INITIALIZED},
    [GET_CLOCK] = {"fmi3GetClock", NEVER},
    [SET_FLOAT32] = {"fmi3SetFloat32", SETTABLE},
    [SET_FLOAT64] = {"fmi3SetFloat64", SETTABLE},
    [SET_INT8] = {"fmi3SetInt8", SETTABLE},
    [SET_UINT8] = {"fmi3SetUInt8", SETTABLE},
    [SET_INT16] = {"fmi3SetInt16", SETTABLE},
    [SET_UINT16] = {"fmi3SetUInt16", SETTABLE},
    [SET_INT32] = {"fmi3SetInt32", SETTABLE},
    [SET_UINT32] = {"fmi3SetUInt32", SETTABLE},
    [SET_INT64] = {"fmi3SetInt64", SETTABLE},
    [SET_UINT64] = {"fmi3SetUInt64", SETTABLE},
    [SET_BOOLEAN] = {"fmi3SetBoolean", SETTABLE},
    [SET_STRING] = {"fmi3SetString", SETTABLE},
    [SET_BINARY] = {"fmi3SetBinary", SETTABLE},
    [SET_CLOCK] = {"fmi3SetClock", NEVER},
    [GET_NUMBER_OF_VARIABLE_DEPENDENCIES] = {"fmi3GetNumberOfVariableDependencies", ANY_STATE},
    [GET_VARIABLE_DEPENDENCIES] = {"fmi3GetVariableDependencies", ANY_STATE},
    [GET_FMU_STATE] = {"fmi3GetFMUState", ANY_STATE},
    [SET_FMU_STATE] = {"fmi3SetFMUState", ANY_STATE},
    [FREE_FMU_STATE] = {"fmi3FreeFMUState", ANY_STATE},
    [SERIALIZED_FMU_STATE_SIZE] = {"fmi3SerializedFMUStateSize", ANY_STATE},
    [SERIALIZE_FMU_STATE] = {"fmi3SerializeFMUState", ANY_STATE},
    [DESERIALIZE_FMU_STATE] = {"fmi3DeserializeFMUState", ANY_STATE},
    [GET_DIRECTIONAL_DERIVATIVE] = {"fmi3GetDirectionalDerivative", INITIALIZED},
    [GET_ADJOINT_DERIVATIVE] = {"fmi3GetAdjointDerivative", INITIALIZED},
    [ENTER_CONFIGURATION_MODE] = {"fmi3EnterConfigurationMode", IN(INSTANTIATED) | IN(STEP_MODE)},
    [EXIT_CONFIGURATION_MODE] = {"fmi3ExitConfigurationMode", NEVER},
    /* the interval and shift functions and fmi3EvaluateDiscreteStates, whose states depend on the kind of
       clock or mode, are allowed in any state and refused for their reason: this FMU has no clock */
    [GET_INTERVAL_DECIMAL] = {"fmi3GetIntervalDecimal", ANY_STATE},
    [GET_INTERVAL_FRACTION] = {"fmi3GetIntervalFraction", ANY_STATE},
    [GET_SHIFT_DECIMAL] = {"fmi3GetShiftDecimal", ANY_STATE},
    [GET_SHIFT_FRACTION] = {"fmi3GetShiftFraction", ANY_STATE},
    [SET_INTERVAL_DECIMAL] = {"fmi3SetIntervalDecimal", ANY_STATE},
    [SET_INTERVAL_FRACTION] = {"fmi3SetIntervalFraction", ANY_STATE},
    [SET_SHIFT_DECIMAL] = {"fmi3SetShiftDecimal", ANY_STATE},
    [SET_SHIFT_FRACTION] = {"fmi3SetShiftFraction", ANY_STATE},
    [EVALUATE_DISCRETE_STATES] = {"fmi3EvaluateDiscreteStates", ANY_STATE},
    [UPDATE_DISCRETE_STATES] = {"fmi3UpdateDiscreteStates", IN(EVENT_MODE)},
    [ENTER_CONTINUOUS_TIME_MODE] = {"fmi3EnterContinuousTimeMode", NEVER},
    [COMPLETED_INTEGRATOR_STEP] = {"fmi3CompletedIntegratorStep", NEVER},
    [SET_TIME] = {"fmi3SetTime", NEVER},
    [SET_CONTINUOUS_STATES] = {"fmi3SetContinuousStates", NEVER},
    [GET_CONTINUOUS_STATE_DERIVATIVES] = {"fmi3GetContinuousStateDerivatives", NEVER},
    [GET_EVENT_INDICATORS] = {"fmi3GetEventIndicators", NEVER},
    [GET_CONTINUOUS_STATES] = {"fmi3GetContinuousStates", NEVER},
    [GET_NOMINALS_OF_CONTINUOUS_STATES] = {"fmi3GetNominalsOfContinuousStates", NEVER},
    [GET_NUMBER_OF_EVENT_INDICATORS] = {"fmi3GetNumberOfEventIndicators", NEVER},
    [GET_NUMBER_OF_CONTINUOUS_STATES] = {"fmi3GetNumberOfContinuousStates", NEVER},
    [ENTER_STEP_MODE] = {"fmi3EnterStepMode", IN(EVENT_MODE)},
    [GET_OUTPUT_DERIVATIVES] = {"fmi3GetOutputDerivatives", IN(STEP_MODE) | IN(TERMINATED) | IN(ERROR_STATE)},
    [DO_STEP] = {"fmi3DoStep", IN(STEP_MODE)},
    [ACTIVATE_MODEL_PARTITION] = {"fmi3ActivateModelPartition", NEVER},
};

typedef struct {
    sblsim_instance run; /* its vectors (sblsim_vectors_new), the state buffers x and x_next apart */
    double *x, *x_next;
    State state;
    double start_time;
    int logging;
    /* What the importer can handle (fmi3InstantiateCoSimulation): for an early return from doStep at an
       acoustic arrival, later. eventModeUsed is refused while the FMU has no Event Mode. */
    int event_mode_used, early_return_allowed;
    /* With early return allowed, for a model that delivers packets: the state before a step, where it is tried
       whole (NULL otherwise), and the positions in y of the packet counter and arrival epoch. */
    sblsim_saved* trial;
    int seq_index, rx_index;
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log_message;
    fmi3IntermediateUpdateCallback intermediate_update;
} Instance;

static const sblsim_model* model(void) { return &SBLSIM_MODEL; }
static const sblsim_fmi3_table* table(void) { return &SBLSIM_FMI3_TABLE; }

/* Log a message through an FMI 3.0 logger. Unlike FMI 2.0's, its message is not a printf format but the
   text itself (the callback has no variadic arguments), so a '%' is passed as it is. */
static void vlog(fmi3LogMessageCallback log_message, fmi3InstanceEnvironment environment, fmi3Status status,
                 const char* category, const char* format, va_list args) {
    char text[1024];
    if (log_message == NULL) return;
    vsnprintf(text, sizeof text, format, args);
    log_message(environment, status, category, text);
}

/* Log an error before there is an instance (a refused instantiation). */
static void log_error(fmi3LogMessageCallback log_message, fmi3InstanceEnvironment environment,
                      const char* format, ...) {
    va_list args;
    va_start(args, format);
    vlog(log_message, environment, fmi3Error, "logStatusError", format, args);
    va_end(args);
}

/* Log a message of an instance: errors always, the rest with debug logging on. */
static void logf_(Instance* s, fmi3Status status, const char* category, const char* format, ...) {
    va_list args;
    if (s == NULL) return;
    if (status == fmi3OK && !s->logging) return;
    va_start(args, format);
    vlog(s->log_message, s->environment, status, category, format, args);
    va_end(args);
}

#define FAIL(s, ...)                                              \
    do {                                                          \
        logf_((s), fmi3Error, "logStatusError", __VA_ARGS__);     \
        return fmi3Error;                                         \
    } while (0)

/* Whether `call` may be called on instance `c` in its state (a log line says why not). */
static int allowed(fmi3Instance c, Call call) {
    Instance* s = (Instance*)c;
    if (s == NULL) return 0;
    if (calls[call].states & IN(s->state)) return 1;
    logf_(s, fmi3Error, "logStatusError", "%s: not allowed in state %s", calls[call].name, state_names[s->state]);
    return 0;
}

/* The entry check of every FMI function with an instance: fmi3Error unless `call` is allowed. */
#define ENTER(c, call)                               \
    do {                                             \
        if (!allowed((c), (call))) return fmi3Error; \
    } while (0)

/* The refusal of a function this FMU does not provide, once its state is checked. */
#define REFUSE(c, call, ...)                                         \
    do {                                                             \
        ENTER((c), (call));                                          \
        FAIL((Instance*)(c), __VA_ARGS__);                           \
    } while (0)

static void set_defaults(Instance* s) {
    sblsim_vectors_reset(&s->run, s->x, s->x_next);
    s->state = INSTANTIATED;
    s->start_time = 0.0;
}

static void free_instance(Instance* s) {
    if (s == NULL) return;
    sblsim_vectors_free(&s->run, s->x, s->x_next);
    sblsim_saved_free(s->trial);
    free(s);
}

/* ---------------------------------------------------------------------------------------- */

const char* fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    Instance* s = (Instance*)c;
    (void)nCategories;
    (void)categories;
    ENTER(c, SET_DEBUG_LOGGING);
    s->logging = loggingOn ? 1 : 0;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    log_error(logMessage, instanceEnvironment,
              "fmi3InstantiateModelExchange: %s supports Co-Simulation only", model()->name);
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    const sblsim_model* m = model();
    Instance* s;
    (void)instanceName; /* an FMI 3.0 logger takes no instance name: the environment tells instances apart */
    (void)resourcePath; /* the FMU needs no resources */
    (void)visible;
    (void)requiredIntermediateVariables; /* it never enters Intermediate Update Mode */
    (void)nRequiredIntermediateVariables;
    if (instantiationToken == NULL || strcmp(instantiationToken, m->guid) != 0) {
        log_error(logMessage, instanceEnvironment, "instantiationToken %s does not match this binary's %s",
                  instantiationToken ? instantiationToken : "(null)", m->guid);
        return NULL;
    }
    s = (Instance*)calloc(1, sizeof(Instance));
    if (s == NULL) {
        log_error(logMessage, instanceEnvironment, "out of memory");
        return NULL;
    }
    s->environment = instanceEnvironment;
    s->log_message = logMessage;
    s->intermediate_update = intermediateUpdate;
    s->logging = loggingOn ? 1 : 0;
    s->event_mode_used = eventModeUsed ? 1 : 0;
    s->early_return_allowed = earlyReturnAllowed ? 1 : 0;
    if (sblsim_vectors_new(&s->run, m, &s->x, &s->x_next)) {
        logf_(s, fmi3Error, "logStatusError", "out of memory");
        free_instance(s);
        return NULL;
    }
    if (s->early_return_allowed && table()->arrival_seq >= 0) {
        s->seq_index = table()->arrival_seq;
        s->rx_index = table()->arrival_time;
        s->trial = sblsim_saved_new(m);
        if (s->trial == NULL) {
            logf_(s, fmi3Error, "logStatusError", "out of memory");
            free_instance(s);
            return NULL;
        }
    }
    set_defaults(s);
    return s;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)clockUpdate;
    (void)lockPreemption;
    (void)unlockPreemption;
    log_error(logMessage, instanceEnvironment,
              "fmi3InstantiateScheduledExecution: %s supports Co-Simulation only", model()->name);
    return NULL;
}

void fmi3FreeInstance(fmi3Instance c) {
    if (allowed(c, FREE_INSTANCE)) free_instance((Instance*)c);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Instance* s = (Instance*)c;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    ENTER(c, ENTER_INITIALIZATION_MODE);
    if (!isfinite(startTime)) FAIL(s, "fmi3EnterInitializationMode: startTime %g is not finite", startTime);
    s->start_time = startTime;
    s->state = INITIALIZATION_MODE;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
    Instance* s = (Instance*)c;
    char message[SBLSIM_MESSAGE];
    ENTER(c, EXIT_INITIALIZATION_MODE);
    if (sblsim_check_parameters(model(), s->run.p, message, sizeof message)) {
        s->state = ERROR_STATE;
        FAIL(s, "%s", message);
    }
    s->run.x = s->x;
    s->run.x_next = s->x_next;
    if (sblsim_initialize(&s->run, s->start_time, message, sizeof message)) {
        s->state = ERROR_STATE;
        FAIL(s, "%s", message);
    }
    s->state = s->event_mode_used ? EVENT_MODE : STEP_MODE; /* an importer that uses Event Mode starts there */
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance c) {
    Instance* s = (Instance*)c;
    ENTER(c, ENTER_EVENT_MODE);
    if (!s->event_mode_used)
        FAIL(s, "fmi3EnterEventMode: the instance was made with eventModeUsed=false");
    s->state = EVENT_MODE;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance c) {
    Instance* s = (Instance*)c;
    ENTER(c, TERMINATE);
    s->state = TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance c) {
    Instance* s = (Instance*)c;
    ENTER(c, RESET);
    set_defaults(s);
    return fmi3OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Get and set                                                                              */

static const char* const type_names[] = {"Float64", "Int32", "Boolean", "UInt64"}; /* by SBLSIM_REAL... */

/* The value reference of the independent variable, time: the one after the table's (modelDescription.xml). */
static fmi3ValueReference time_reference(void) { return (fmi3ValueReference)table()->n_variables; }

/* The FMI 3.0 variable with value reference vr (NULL and a log line if there is none or it is not of `type`). */
static const sblsim_fmi3_variable* find(Instance* s, fmi3ValueReference vr, int type, Call call) {
    const sblsim_fmi3_table* t = table();
    const sblsim_fmi3_variable* v;
    if (vr >= (fmi3ValueReference)t->n_variables) {
        logf_(s, fmi3Error, "logStatusError", "%s: no variable with value reference %u", calls[call].name,
              (unsigned)vr);
        return NULL;
    }
    v = &t->variables[vr];
    if (v->type != type) {
        logf_(s, fmi3Error, "logStatusError", "%s: %s (value reference %u) is of type %s, not %s",
              calls[call].name, v->name, (unsigned)vr, type_names[v->type], type_names[type]);
        return NULL;
    }
    return v;
}

/* The number of values of a variable: its elements, or the structural parameter's one. */
static size_t size_of(const sblsim_fmi3_variable* v) {
    return v->causality == SBLSIM_STRUCTURAL ? 1u : (size_t)v->n_elements;
}

/* Element k of a variable: a variable of the model record. */
static const sblsim_variable* element(const sblsim_fmi3_variable* v, int k) {
    return &model()->variables[v->elements[k]];
}

/* Whether every value reference is a variable of `type` and nValues the number of their values (a log line
   says why not). */
static fmi3Status check_references(Instance* s, const fmi3ValueReference vr[], size_t nvr, size_t nValues,
                                   int type, Call call) {
    size_t i, total = 0;
    for (i = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v;
        if (call == GET_FLOAT64 && vr[i] == time_reference()) { /* the independent variable */
            total += 1;
            continue;
        }
        v = find(s, vr[i], type, call);
        if (v == NULL) return fmi3Error;
        total += size_of(v);
    }
    if (total != nValues)
        FAIL(s, "%s: nValues is %lu, the %lu value references hold %lu values", calls[call].name,
             (unsigned long)nValues, (unsigned long)nvr, (unsigned long)total);
    return fmi3OK;
}

static fmi3Status check_range(Instance* s, const sblsim_variable* v, double value, Call call) {
    char range[96];
    if (sblsim_in_range(v, value)) return fmi3OK;
    sblsim_describe_range(v, range, sizeof range);
    FAIL(s, "%s: %s = %g is outside the allowed range %s", calls[call].name, v->name, value, range);
}

static fmi3Status check_set(Instance* s, const sblsim_fmi3_variable* v, Call call) {
    if (v->causality == SBLSIM_OUTPUT) FAIL(s, "%s: %s is an output and cannot be set", calls[call].name, v->name);
    if ((v->causality == SBLSIM_PARAMETER || v->causality == SBLSIM_STRUCTURAL) && s->state != INSTANTIATED &&
        s->state != INITIALIZATION_MODE)
        FAIL(s, "%s: %s is a fixed parameter; set it before fmi3ExitInitializationMode", calls[call].name, v->name);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    Instance* s = (Instance*)c;
    size_t i, j = 0;
    int k;
    ENTER(c, GET_FLOAT64);
    if (check_references(s, vr, nvr, nValues, SBLSIM_REAL, GET_FLOAT64) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v;
        if (vr[i] == time_reference()) {
            values[j++] = s->run.t;
            continue;
        }
        v = &table()->variables[vr[i]];
        for (k = 0; k < v->n_elements; k++) values[j++] = *sblsim_slot(&s->run, element(v, k));
    }
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[],
                        size_t nValues) {
    Instance* s = (Instance*)c;
    size_t i, j = 0;
    int k;
    ENTER(c, GET_INT32);
    if (check_references(s, vr, nvr, nValues, SBLSIM_INTEGER, GET_INT32) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v = &table()->variables[vr[i]];
        for (k = 0; k < v->n_elements; k++) values[j++] = (fmi3Int32)floor(*sblsim_slot(&s->run, element(v, k)) + 0.5);
    }
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
    Instance* s = (Instance*)c;
    size_t i, j = 0;
    int k;
    ENTER(c, GET_BOOLEAN);
    if (check_references(s, vr, nvr, nValues, SBLSIM_BOOLEAN, GET_BOOLEAN) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v = &table()->variables[vr[i]];
        for (k = 0; k < v->n_elements; k++)
            values[j++] = *sblsim_slot(&s->run, element(v, k)) > 0.5 ? fmi3True : fmi3False;
    }
    return fmi3OK;
}

fmi3Status fmi3GetUInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 values[],
                         size_t nValues) {
    Instance* s = (Instance*)c;
    size_t i;
    ENTER(c, GET_UINT64);
    if (check_references(s, vr, nvr, nValues, SBLSIM_UINT64, GET_UINT64) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) values[i] = (fmi3UInt64)table()->variables[vr[i]].constant; /* one value each */
    return fmi3OK;
}

/* A set checks every value before it writes any: a refused set changes nothing. */

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[],
                          size_t nValues) {
    Instance* s = (Instance*)c;
    size_t i, j = 0;
    int k;
    ENTER(c, SET_FLOAT64);
    if (check_references(s, vr, nvr, nValues, SBLSIM_REAL, SET_FLOAT64) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v = &table()->variables[vr[i]];
        if (check_set(s, v, SET_FLOAT64) != fmi3OK) return fmi3Error;
        for (k = 0; k < v->n_elements; k++, j++) {
            const sblsim_variable* e = element(v, k);
            if (!isfinite(values[j])) FAIL(s, "fmi3SetFloat64: %s = %g is not finite", e->name, values[j]);
            if (check_range(s, e, values[j], SET_FLOAT64) != fmi3OK) return fmi3Error;
        }
    }
    for (i = 0, j = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v = &table()->variables[vr[i]];
        for (k = 0; k < v->n_elements; k++) *sblsim_slot(&s->run, element(v, k)) = values[j++];
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[],
                        size_t nValues) {
    Instance* s = (Instance*)c;
    size_t i, j = 0;
    int k;
    ENTER(c, SET_INT32);
    if (check_references(s, vr, nvr, nValues, SBLSIM_INTEGER, SET_INT32) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v = &table()->variables[vr[i]];
        if (check_set(s, v, SET_INT32) != fmi3OK) return fmi3Error;
        for (k = 0; k < v->n_elements; k++, j++)
            if (check_range(s, element(v, k), (double)values[j], SET_INT32) != fmi3OK) return fmi3Error;
    }
    for (i = 0, j = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v = &table()->variables[vr[i]];
        for (k = 0; k < v->n_elements; k++) *sblsim_slot(&s->run, element(v, k)) = (double)values[j++];
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Boolean values[],
                          size_t nValues) {
    Instance* s = (Instance*)c;
    size_t i, j = 0;
    int k;
    ENTER(c, SET_BOOLEAN);
    if (check_references(s, vr, nvr, nValues, SBLSIM_BOOLEAN, SET_BOOLEAN) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++)
        if (check_set(s, &table()->variables[vr[i]], SET_BOOLEAN) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v = &table()->variables[vr[i]];
        for (k = 0; k < v->n_elements; k++) *sblsim_slot(&s->run, element(v, k)) = values[j++] ? 1.0 : 0.0;
    }
    return fmi3OK;
}

/* The structural parameter is compiled in: setting it to its value is accepted (and changes nothing). */
fmi3Status fmi3SetUInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt64 values[],
                         size_t nValues) {
    Instance* s = (Instance*)c;
    size_t i;
    ENTER(c, SET_UINT64);
    if (check_references(s, vr, nvr, nValues, SBLSIM_UINT64, SET_UINT64) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        const sblsim_fmi3_variable* v = &table()->variables[vr[i]];
        if (check_set(s, v, SET_UINT64) != fmi3OK) return fmi3Error;
        if (values[i] != (fmi3UInt64)v->constant)
            FAIL(s, "fmi3SetUInt64: %s: this FMU is compiled for %llu (build it with --beacons %llu)", v->name,
                 (unsigned long long)v->constant, (unsigned long long)values[i]);
    }
    return fmi3OK;
}

/* The types this FMU has no variable of: a call with value references is refused (one without does nothing). */
#define NO_VARIABLES_OF(function, call, type_name, value_type)                                                \
    fmi3Status function(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, value_type values[],     \
                        size_t nValues) {                                                                    \
        (void)vr;                                                                                            \
        (void)values;                                                                                        \
        (void)nValues;                                                                                       \
        ENTER(c, call);                                                                                      \
        if (nvr == 0) return fmi3OK;                                                                         \
        FAIL((Instance*)c, "%s: this FMU has no %s variables", calls[call].name, type_name);                \
    }

NO_VARIABLES_OF(fmi3GetFloat32, GET_FLOAT32, "Float32", fmi3Float32)
NO_VARIABLES_OF(fmi3GetInt8, GET_INT8, "Int8", fmi3Int8)
NO_VARIABLES_OF(fmi3GetUInt8, GET_UINT8, "UInt8", fmi3UInt8)
NO_VARIABLES_OF(fmi3GetInt16, GET_INT16, "Int16", fmi3Int16)
NO_VARIABLES_OF(fmi3GetUInt16, GET_UINT16, "UInt16", fmi3UInt16)
NO_VARIABLES_OF(fmi3GetUInt32, GET_UINT32, "UInt32", fmi3UInt32)
NO_VARIABLES_OF(fmi3GetInt64, GET_INT64, "Int64", fmi3Int64)
NO_VARIABLES_OF(fmi3GetString, GET_STRING, "String", fmi3String)
NO_VARIABLES_OF(fmi3SetFloat32, SET_FLOAT32, "Float32", const fmi3Float32)
NO_VARIABLES_OF(fmi3SetInt8, SET_INT8, "Int8", const fmi3Int8)
NO_VARIABLES_OF(fmi3SetUInt8, SET_UINT8, "UInt8", const fmi3UInt8)
NO_VARIABLES_OF(fmi3SetInt16, SET_INT16, "Int16", const fmi3Int16)
NO_VARIABLES_OF(fmi3SetUInt16, SET_UINT16, "UInt16", const fmi3UInt16)
NO_VARIABLES_OF(fmi3SetUInt32, SET_UINT32, "UInt32", const fmi3UInt32)
NO_VARIABLES_OF(fmi3SetInt64, SET_INT64, "Int64", const fmi3Int64)
NO_VARIABLES_OF(fmi3SetString, SET_STRING, "String", const fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    (void)vr;
    (void)valueSizes;
    (void)values;
    (void)nValues;
    ENTER(c, GET_BINARY);
    if (nvr == 0) return fmi3OK;
    FAIL((Instance*)c, "fmi3GetBinary: this FMU has no Binary variables");
}

fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)vr;
    (void)valueSizes;
    (void)values;
    (void)nValues;
    ENTER(c, SET_BINARY);
    if (nvr == 0) return fmi3OK;
    FAIL((Instance*)c, "fmi3SetBinary: this FMU has no Binary variables");
}

fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)vr;
    (void)nvr;
    (void)values;
    REFUSE(c, GET_CLOCK, "fmi3GetClock: this FMU has no clocks");
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    (void)vr;
    (void)nvr;
    (void)values;
    REFUSE(c, SET_CLOCK, "fmi3SetClock: this FMU has no clocks");
}

/* ---------------------------------------------------------------------------------------- */
/* Variable dependencies: no output depends on an input (an output is a function of the state, */
/* the parameters and the time: sblsim_runtime.h, output(x, p, d, t)).                        */

/* The output with value reference vr (NULL and a log line if there is none or it is not an output). */
static const sblsim_fmi3_variable* find_output(Instance* s, fmi3ValueReference vr, Call call) {
    const sblsim_fmi3_table* t = table();
    if (vr >= (fmi3ValueReference)t->n_variables) {
        logf_(s, fmi3Error, "logStatusError", "%s: no variable with value reference %u", calls[call].name,
              (unsigned)vr);
        return NULL;
    }
    if (t->variables[vr].causality != SBLSIM_OUTPUT) {
        logf_(s, fmi3Error, "logStatusError", "%s: %s (value reference %u) is not an output; only outputs have "
              "dependencies", calls[call].name, t->variables[vr].name, (unsigned)vr);
        return NULL;
    }
    return &t->variables[vr];
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference valueReference,
                                               size_t* nDependencies) {
    Instance* s = (Instance*)c;
    ENTER(c, GET_NUMBER_OF_VARIABLE_DEPENDENCIES);
    if (find_output(s, valueReference, GET_NUMBER_OF_VARIABLE_DEPENDENCIES) == NULL) return fmi3Error;
    if (nDependencies == NULL) FAIL(s, "fmi3GetNumberOfVariableDependencies: no place for the number");
    *nDependencies = 0;
    return fmi3OK;
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    Instance* s = (Instance*)c;
    (void)elementIndicesOfDependent;
    (void)independents;
    (void)elementIndicesOfIndependents;
    (void)dependencyKinds;
    ENTER(c, GET_VARIABLE_DEPENDENCIES);
    if (find_output(s, dependent, GET_VARIABLE_DEPENDENCIES) == NULL) return fmi3Error;
    if (nDependencies != 0)
        FAIL(s, "fmi3GetVariableDependencies: nDependencies is %lu, value reference %u has 0",
             (unsigned long)nDependencies, (unsigned)dependent);
    return fmi3OK;
}

/* ---------------------------------------------------------------------------------------- */
/* FMU state: a sblsim_saved (sblsim_fmu_state.h)                                           */

#define SBLSIM_MAGIC 0x53424c53494d3033ULL /* "SBLSIM03": the serialized layout of sblsim_fmu_state.h */
/* The states past initialization: a deserialized state in one of them has its parameters checked. */
#define PAST_INITIALIZATION (IN(STEP_MODE) | IN(TERMINATED) | IN(EVENT_MODE))

/* The instance as it was at `from`, its state and start time too. */
static void restore(Instance* s, const sblsim_saved* from) {
    sblsim_restore(&s->run, s->x, s->x_next, from);
    s->state = (State)from->state;
    s->start_time = from->start_time;
}

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState* FMUState) {
    Instance* s = (Instance*)c;
    ENTER(c, GET_FMU_STATE);
    if (FMUState == NULL) FAIL(s, "fmi3GetFMUState: no place for the state");
    if (*FMUState == NULL) {
        *FMUState = (fmi3FMUState)sblsim_saved_new(model());
        if (*FMUState == NULL) FAIL(s, "fmi3GetFMUState: out of memory");
    }
    sblsim_save(&s->run, s->state, s->start_time, (sblsim_saved*)*FMUState);
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState FMUState) {
    Instance* s = (Instance*)c;
    ENTER(c, SET_FMU_STATE);
    if (FMUState == NULL) FAIL(s, "fmi3SetFMUState: no state");
    restore(s, (const sblsim_saved*)FMUState);
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState* FMUState) {
    ENTER(c, FREE_FMU_STATE);
    if (FMUState == NULL || *FMUState == NULL) return fmi3OK;
    sblsim_saved_free((sblsim_saved*)*FMUState);
    *FMUState = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState FMUState, size_t* size) {
    (void)FMUState;
    ENTER(c, SERIALIZED_FMU_STATE_SIZE);
    if (size == NULL) FAIL((Instance*)c, "fmi3SerializedFMUStateSize: no place for the size");
    *size = sblsim_serialized_size(model());
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState FMUState, fmi3Byte serializedState[], size_t size) {
    Instance* s = (Instance*)c;
    size_t needed = sblsim_serialized_size(model());
    ENTER(c, SERIALIZE_FMU_STATE);
    if (FMUState == NULL || serializedState == NULL || size < needed)
        FAIL(s, "fmi3SerializeFMUState: buffer of %lu bytes, %lu needed", (unsigned long)size, (unsigned long)needed);
    sblsim_serialize(model(), SBLSIM_MAGIC, (const sblsim_saved*)FMUState, serializedState);
    return fmi3OK;
}

/* Checked before it is taken: the caller's state object changes only if it is (sblsim_deserialize). */
fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState* FMUState) {
    Instance* s = (Instance*)c;
    char message[SBLSIM_STATE_MESSAGE];
    sblsim_saved* into;
    ENTER(c, DESERIALIZE_FMU_STATE);
    if (FMUState == NULL) FAIL(s, "fmi3DeserializeFMUState: no place for the state");
    into = *FMUState != NULL ? (sblsim_saved*)*FMUState : sblsim_saved_new(model());
    if (into == NULL) FAIL(s, "fmi3DeserializeFMUState: out of memory");
    if (sblsim_deserialize(model(), SBLSIM_MAGIC, N_STATES, PAST_INITIALIZATION, serializedState, size, into,
                           message, sizeof message)) {
        if (*FMUState == NULL) sblsim_saved_free(into);
        FAIL(s, "fmi3DeserializeFMUState: %s", message);
    }
    *FMUState = (fmi3FMUState)into;
    return fmi3OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Derivatives, Configuration Mode, clocks and discrete states: not provided                */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns;
    (void)nUnknowns;
    (void)knowns;
    (void)nKnowns;
    (void)seed;
    (void)nSeed;
    (void)sensitivity;
    (void)nSensitivity;
    REFUSE(c, GET_DIRECTIONAL_DERIVATIVE,
           "fmi3GetDirectionalDerivative: not provided (providesDirectionalDerivatives=false)");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns;
    (void)nUnknowns;
    (void)knowns;
    (void)nKnowns;
    (void)seed;
    (void)nSeed;
    (void)sensitivity;
    (void)nSensitivity;
    REFUSE(c, GET_ADJOINT_DERIVATIVE, "fmi3GetAdjointDerivative: not provided (providesAdjointDerivatives=false)");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) {
    REFUSE(c, ENTER_CONFIGURATION_MODE, "fmi3EnterConfigurationMode: this FMU has no Configuration Mode (its "
                                        "structural parameter is compiled in; fmi3SetUInt64 accepts its value)");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) {
    REFUSE(c, EXIT_CONFIGURATION_MODE, "fmi3ExitConfigurationMode: this FMU has no Configuration Mode");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr;
    (void)nvr;
    (void)intervals;
    (void)qualifiers;
    REFUSE(c, GET_INTERVAL_DECIMAL, "fmi3GetIntervalDecimal: this FMU has no clocks");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    (void)qualifiers;
    REFUSE(c, GET_INTERVAL_FRACTION, "fmi3GetIntervalFraction: this FMU has no clocks");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[]) {
    (void)vr;
    (void)nvr;
    (void)shifts;
    REFUSE(c, GET_SHIFT_DECIMAL, "fmi3GetShiftDecimal: this FMU has no clocks");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    REFUSE(c, GET_SHIFT_FRACTION, "fmi3GetShiftFraction: this FMU has no clocks");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    (void)vr;
    (void)nvr;
    (void)intervals;
    REFUSE(c, SET_INTERVAL_DECIMAL, "fmi3SetIntervalDecimal: this FMU has no clocks");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    REFUSE(c, SET_INTERVAL_FRACTION, "fmi3SetIntervalFraction: this FMU has no clocks");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr;
    (void)nvr;
    (void)shifts;
    REFUSE(c, SET_SHIFT_DECIMAL, "fmi3SetShiftDecimal: this FMU has no clocks");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    REFUSE(c, SET_SHIFT_FRACTION, "fmi3SetShiftFraction: this FMU has no clocks");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) {
    REFUSE(c, EVALUATE_DISCRETE_STATES,
           "fmi3EvaluateDiscreteStates: not provided (providesEvaluateDiscreteStates=false)");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean* discreteStatesNeedUpdate,
                                    fmi3Boolean* terminateSimulation, fmi3Boolean* nominalsOfContinuousStatesChanged,
                                    fmi3Boolean* valuesOfContinuousStatesChanged, fmi3Boolean* nextEventTimeDefined,
                                    fmi3Float64* nextEventTime) {
    ENTER(c, UPDATE_DISCRETE_STATES);
    /* nothing waits for an event: doStep has delivered the packet of the arrival it returned at */
    if (discreteStatesNeedUpdate != NULL) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation != NULL) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged != NULL) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged != NULL) *valuesOfContinuousStatesChanged = fmi3False;
    if (nextEventTimeDefined != NULL) *nextEventTimeDefined = fmi3False;
    if (nextEventTime != NULL) *nextEventTime = 0.0;
    return fmi3OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Model Exchange: not provided (Co-Simulation only)                                        */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) {
    REFUSE(c, ENTER_CONTINUOUS_TIME_MODE, "fmi3EnterContinuousTimeMode: this FMU is Co-Simulation only");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean* enterEventMode, fmi3Boolean* terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    (void)enterEventMode;
    (void)terminateSimulation;
    REFUSE(c, COMPLETED_INTEGRATOR_STEP, "fmi3CompletedIntegratorStep: this FMU is Co-Simulation only");
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time) {
    (void)time;
    REFUSE(c, SET_TIME, "fmi3SetTime: this FMU is Co-Simulation only");
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 continuousStates[], size_t nContinuousStates) {
    (void)continuousStates;
    (void)nContinuousStates;
    REFUSE(c, SET_CONTINUOUS_STATES, "fmi3SetContinuousStates: this FMU is Co-Simulation only");
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 derivatives[], size_t nContinuousStates) {
    (void)derivatives;
    (void)nContinuousStates;
    REFUSE(c, GET_CONTINUOUS_STATE_DERIVATIVES, "fmi3GetContinuousStateDerivatives: this FMU is Co-Simulation only");
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    (void)eventIndicators;
    (void)nEventIndicators;
    REFUSE(c, GET_EVENT_INDICATORS, "fmi3GetEventIndicators: this FMU is Co-Simulation only");
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    (void)continuousStates;
    (void)nContinuousStates;
    REFUSE(c, GET_CONTINUOUS_STATES, "fmi3GetContinuousStates: this FMU is Co-Simulation only");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[], size_t nContinuousStates) {
    (void)nominals;
    (void)nContinuousStates;
    REFUSE(c, GET_NOMINALS_OF_CONTINUOUS_STATES, "fmi3GetNominalsOfContinuousStates: this FMU is Co-Simulation only");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t* nEventIndicators) {
    (void)nEventIndicators;
    REFUSE(c, GET_NUMBER_OF_EVENT_INDICATORS, "fmi3GetNumberOfEventIndicators: this FMU is Co-Simulation only");
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t* nContinuousStates) {
    (void)nContinuousStates;
    REFUSE(c, GET_NUMBER_OF_CONTINUOUS_STATES, "fmi3GetNumberOfContinuousStates: this FMU is Co-Simulation only");
}

/* ---------------------------------------------------------------------------------------- */
/* Co-Simulation                                                                            */

fmi3Status fmi3EnterStepMode(fmi3Instance c) {
    Instance* s = (Instance*)c;
    ENTER(c, ENTER_STEP_MODE);
    s->state = STEP_MODE;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    (void)vr;
    (void)nvr;
    (void)orders;
    (void)values;
    (void)nValues;
    REFUSE(c, GET_OUTPUT_DERIVATIVES, "fmi3GetOutputDerivatives: not supported (maxOutputDerivativeOrder=0)");
}

/* The runtime's step from t to t + h (0), or the Error state and a log line (-1). */
static int advance(Instance* s, double t, double h) {
    char message[SBLSIM_MESSAGE];
    if (sblsim_do_step(&s->run, t, h, message, sizeof message)) {
        s->state = ERROR_STATE;
        logf_(s, fmi3Error, "logStatusError", "%s", message);
        return -1;
    }
    return 0;
}

/* One communication step from t to t + h, its arguments checked: s->run.t is the time reached and
   *early_return whether it stopped short of t + h.
   Early return at an acoustic arrival (an importer that allows it, a model that delivers packets: outputs
   packet_seq and rx_time): the step is tried whole from a saved state; when it delivers a packet that arrived
   strictly inside the step (rx_time in (t, t + h), beyond the delivery slack), the state is restored and the
   step taken to rx_time only, which delivers the same packet (the channel's slots and draws follow its own
   clock, not the host's steps: docs/model.md), and doStep returns there. */
static fmi3Status step(Instance* s, double t, double h, fmi3Boolean* early_return) {
    *early_return = fmi3False;
    if (s->trial != NULL) {
        double seq = s->run.y[s->seq_index], arrival;
        sblsim_save(&s->run, s->state, s->start_time, s->trial);
        if (advance(s, t, h)) return fmi3Error;
        arrival = s->run.y[s->rx_index];
        if (s->run.y[s->seq_index] != seq && arrival - t > SBLSIM_ARRIVAL_SLACK &&
            t + h - arrival > SBLSIM_ARRIVAL_SLACK) {
            double delivered = s->run.y[s->seq_index];
            restore(s, s->trial);
            if (advance(s, t, arrival - t)) return fmi3Error;
            if (s->run.y[s->seq_index] == delivered) {
                *early_return = fmi3True;
                return fmi3OK;
            }
            restore(s, s->trial); /* not delivered at its arrival after all: the whole step, as without */
            if (advance(s, t, h)) return fmi3Error;
        }
        return fmi3OK;
    }
    if (advance(s, t, h)) return fmi3Error;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean* eventHandlingNeeded,
                      fmi3Boolean* terminateSimulation, fmi3Boolean* earlyReturn, fmi3Float64* lastSuccessfulTime) {
    Instance* s = (Instance*)c;
    double t = currentCommunicationPoint, h = communicationStepSize;
    fmi3Boolean early = fmi3False;
    (void)noSetFMUStatePriorToCurrentPoint;
    ENTER(c, DO_STEP);
    if (!(h > 0.0) || !isfinite(h)) FAIL(s, "fmi3DoStep: communicationStepSize %g must be positive and finite", h);
    if (!isfinite(t) || !(fabs(t - s->run.t) <= 1e-9 * (1.0 + fabs(t)))) /* a NaN time is a gap too */
        FAIL(s, "fmi3DoStep: currentCommunicationPoint %.17g s differs from the FMU's time %.17g s (a gap or an "
                "overlap between steps)", t, s->run.t);
    if (step(s, t, h, &early) != fmi3OK) return fmi3Error;
    /* an importer in Event Mode gets the arrival as an event (nothing to update: the packet is in the outputs) */
    if (eventHandlingNeeded != NULL) *eventHandlingNeeded = early && s->event_mode_used ? fmi3True : fmi3False;
    if (terminateSimulation != NULL) *terminateSimulation = fmi3False;
    if (earlyReturn != NULL) *earlyReturn = early;
    if (lastSuccessfulTime != NULL) *lastSuccessfulTime = s->run.t;
    return fmi3OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Scheduled Execution: not provided (Co-Simulation only)                                   */

fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference;
    (void)activationTime;
    REFUSE(c, ACTIVATE_MODEL_PARTITION, "fmi3ActivateModelPartition: this FMU is Co-Simulation only");
}

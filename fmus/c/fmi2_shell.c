/* FMI 2.0 Co-Simulation interface over the sblsim runtime, generic over the model tables.
 *
 * Compile with -DSBLSIM_MODEL=<model symbol> (e.g. sblsim_platform_model) together with the
 * model's generated sources, sblsim_runtime.c and sblsim_fmu_state.c. Everything the FMU needs is in
 * these sources: no Python, no environment variables, no resource files; any number of instances.
 *
 * FMI semantics (docs/model.md, "FMI semantics"):
 *  - every function first checks the instance's state against one table of the states it is
 *    allowed in (the FMI 2.0 Co-Simulation state machine); a call in another state returns
 *    fmi2Error and logs "<function>: not allowed in state <state>";
 *  - parameters are fixed: set in the instantiated or initialization mode, checked against
 *    their declared ranges at fmi2ExitInitializationMode (fmi2Error and a log line otherwise);
 *  - fmi2SetReal and fmi2SetInteger refuse a value outside an input's declared range (and any value that is
 *    not finite) with fmi2Error and a log line;
 *  - fmi2DoStep refuses h <= 0 and a communication point other than the FMU's time (a gap or
 *    an overlap) with fmi2Error and a log line;
 *  - errors are always logged (whatever fmi2SetDebugLogging says);
 *  - the state (every vector, the draw counters, the time) can be got, set and serialized; a serialized
 *    state is checked before it is taken (sblsim_fmu_state.c: times finite and ordered, every value finite,
 *    the inputs within their ranges, the parameters within theirs past initialization, a known state number):
 *    fmi2Error and a log line
 *    otherwise, and the caller's state object is left as it was.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "sblsim_fmu_state.h"
#include "sblsim_runtime.h"

#ifndef SBLSIM_MODEL
#error "define SBLSIM_MODEL as the model symbol, e.g. -DSBLSIM_MODEL=sblsim_platform_model"
#endif

extern const sblsim_model SBLSIM_MODEL;

/* The states of the FMI 2.0 Co-Simulation state machine (FMI 2.0.4, section 4.2.4) this FMU can be in.
   doStep always runs to its end (never fmi2Pending) and a failed step returns fmi2Error (never fmi2Discard),
   so stepInProgress, stepFailed and stepCanceled are never entered; no call returns fmi2Fatal. Saved states
   store the number: append only. */
typedef enum { INSTANTIATED, INITIALIZATION_MODE, STEP_COMPLETE, TERMINATED, ERROR_STATE, N_STATES } State;
static const char* const state_names[N_STATES] = {"Instantiated", "InitializationMode", "StepComplete",
                                                  "Terminated", "Error"};

/* Sets of states, as bits; the groups the standard's table repeats (restricted to the states above). */
#define IN(state) (1u << (state))
#define ANY_STATE (IN(INSTANTIATED) | IN(INITIALIZATION_MODE) | IN(STEP_COMPLETE) | IN(TERMINATED) | IN(ERROR_STATE))
#define SETTABLE (IN(INSTANTIATED) | IN(INITIALIZATION_MODE) | IN(STEP_COMPLETE))
#define INITIALIZED (IN(INITIALIZATION_MODE) | IN(STEP_COMPLETE) | IN(TERMINATED) | IN(ERROR_STATE))
#define STEPPED (IN(STEP_COMPLETE) | IN(TERMINATED))

/* Every FMI function with an instance, and the states it may be called in. */
typedef enum {
    SET_DEBUG_LOGGING, FREE_INSTANCE, SETUP_EXPERIMENT, ENTER_INITIALIZATION_MODE, EXIT_INITIALIZATION_MODE,
    TERMINATE, RESET, GET_REAL, GET_INTEGER, GET_BOOLEAN, GET_STRING, SET_REAL, SET_INTEGER, SET_BOOLEAN,
    SET_STRING, GET_FMU_STATE, SET_FMU_STATE, FREE_FMU_STATE, SERIALIZED_FMU_STATE_SIZE, SERIALIZE_FMU_STATE,
    DESERIALIZE_FMU_STATE, GET_DIRECTIONAL_DERIVATIVE, SET_REAL_INPUT_DERIVATIVES, GET_REAL_OUTPUT_DERIVATIVES,
    DO_STEP, CANCEL_STEP, GET_STATUS, GET_REAL_STATUS, GET_INTEGER_STATUS, GET_BOOLEAN_STATUS, GET_STRING_STATUS,
    N_CALLS
} Call;

static const struct {
    const char* name;
    unsigned states;
} calls[N_CALLS] = {
    [SET_DEBUG_LOGGING] = {"fmi2SetDebugLogging", ANY_STATE},
    [FREE_INSTANCE] = {"fmi2FreeInstance", ANY_STATE},
    [SETUP_EXPERIMENT] = {"fmi2SetupExperiment", IN(INSTANTIATED)},
    [ENTER_INITIALIZATION_MODE] = {"fmi2EnterInitializationMode", IN(INSTANTIATED)},
    [EXIT_INITIALIZATION_MODE] = {"fmi2ExitInitializationMode", IN(INITIALIZATION_MODE)},
    [TERMINATE] = {"fmi2Terminate", IN(STEP_COMPLETE)},
    [RESET] = {"fmi2Reset", ANY_STATE},
    [GET_REAL] = {"fmi2GetReal", INITIALIZED},
    [GET_INTEGER] = {"fmi2GetInteger", INITIALIZED},
    [GET_BOOLEAN] = {"fmi2GetBoolean", INITIALIZED},
    [GET_STRING] = {"fmi2GetString", INITIALIZED},
    [SET_REAL] = {"fmi2SetReal", SETTABLE},
    [SET_INTEGER] = {"fmi2SetInteger", SETTABLE},
    [SET_BOOLEAN] = {"fmi2SetBoolean", SETTABLE},
    [SET_STRING] = {"fmi2SetString", SETTABLE},
    [GET_FMU_STATE] = {"fmi2GetFMUstate", ANY_STATE},
    [SET_FMU_STATE] = {"fmi2SetFMUstate", ANY_STATE},
    [FREE_FMU_STATE] = {"fmi2FreeFMUstate", ANY_STATE},
    [SERIALIZED_FMU_STATE_SIZE] = {"fmi2SerializedFMUstateSize", ANY_STATE},
    [SERIALIZE_FMU_STATE] = {"fmi2SerializeFMUstate", ANY_STATE},
    [DESERIALIZE_FMU_STATE] = {"fmi2DeSerializeFMUstate", ANY_STATE},
    [GET_DIRECTIONAL_DERIVATIVE] = {"fmi2GetDirectionalDerivative", INITIALIZED},
    [SET_REAL_INPUT_DERIVATIVES] = {"fmi2SetRealInputDerivatives", SETTABLE},
    [GET_REAL_OUTPUT_DERIVATIVES] = {"fmi2GetRealOutputDerivatives", IN(STEP_COMPLETE) | IN(TERMINATED) |
                                                                     IN(ERROR_STATE)},
    [DO_STEP] = {"fmi2DoStep", IN(STEP_COMPLETE)},
    [CANCEL_STEP] = {"fmi2CancelStep", 0u}, /* only while a step is in progress: never here */
    [GET_STATUS] = {"fmi2GetStatus", STEPPED},
    [GET_REAL_STATUS] = {"fmi2GetRealStatus", STEPPED},
    [GET_INTEGER_STATUS] = {"fmi2GetIntegerStatus", STEPPED},
    [GET_BOOLEAN_STATUS] = {"fmi2GetBooleanStatus", STEPPED},
    [GET_STRING_STATUS] = {"fmi2GetStringStatus", STEPPED},
};

typedef struct {
    sblsim_instance run; /* its vectors (sblsim_vectors_new), the state buffers x and x_next apart */
    double *x, *x_next;
    State state;
    double start_time;
    int logging;
    char* name;
    fmi2CallbackFunctions callbacks;
} Instance;

static const sblsim_model* model(void) { return &SBLSIM_MODEL; }

/* Log a message. The FMI logger takes a printf format; the text is passed as that format with
   every '%' doubled, so that hosts which format it (C hosts) and hosts which print it as it is
   (fmpy) both show the whole message. */
static void logf_(Instance* s, fmi2Status status, const char* category, const char* format, ...) {
    char text[1024], escaped[2048];
    size_t i, j = 0;
    va_list args;
    if (s == NULL || s->callbacks.logger == NULL) return;
    if (status == fmi2OK && !s->logging) return;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    for (i = 0; text[i] != 0 && j + 2 < sizeof escaped; i++) {
        if (text[i] == '%') escaped[j++] = '%';
        escaped[j++] = text[i];
    }
    escaped[j] = 0;
    s->callbacks.logger(s->callbacks.componentEnvironment, s->name, status, category, escaped);
}

#define FAIL(s, ...)                                              \
    do {                                                          \
        logf_((s), fmi2Error, "logStatusError", __VA_ARGS__);     \
        return fmi2Error;                                         \
    } while (0)

/* Whether `call` may be called on instance `c` in its state (a log line says why not). */
static int allowed(fmi2Component c, Call call) {
    Instance* s = (Instance*)c;
    if (s == NULL) return 0;
    if (calls[call].states & IN(s->state)) return 1;
    logf_(s, fmi2Error, "logStatusError", "%s: not allowed in state %s", calls[call].name, state_names[s->state]);
    return 0;
}

/* The entry check of every FMI function with an instance: fmi2Error unless `call` is allowed. */
#define ENTER(c, call)                               \
    do {                                             \
        if (!allowed((c), (call))) return fmi2Error; \
    } while (0)

static void set_defaults(Instance* s) {
    sblsim_vectors_reset(&s->run, s->x, s->x_next);
    s->state = INSTANTIATED;
    s->start_time = 0.0;
}

static void free_instance(Instance* s) {
    if (s == NULL) return;
    sblsim_vectors_free(&s->run, s->x, s->x_next);
    free(s->name);
    free(s);
}

/* ---------------------------------------------------------------------------------------- */

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Instance* s = (Instance*)c;
    (void)nCategories;
    (void)categories;
    ENTER(c, SET_DEBUG_LOGGING);
    s->logging = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    const sblsim_model* m = model();
    Instance* s;
    (void)fmuResourceLocation; /* the FMU needs no resources */
    (void)visible;
    s = (Instance*)calloc(1, sizeof(Instance));
    if (s == NULL) return NULL;
    if (functions != NULL) s->callbacks = *functions;
    s->logging = loggingOn ? 1 : 0;
    s->name = (char*)malloc(strlen(instanceName ? instanceName : "") + 1);
    if (s->name != NULL) strcpy(s->name, instanceName ? instanceName : "");
    if (fmuType != fmi2CoSimulation) {
        logf_(s, fmi2Error, "logStatusError", "%s supports Co-Simulation only (fmuType %d)", m->name, (int)fmuType);
        free_instance(s);
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, m->guid) != 0) {
        logf_(s, fmi2Error, "logStatusError", "GUID %s does not match this binary's %s", fmuGUID ? fmuGUID : "(null)",
              m->guid);
        free_instance(s);
        return NULL;
    }
    if (!s->name || sblsim_vectors_new(&s->run, m, &s->x, &s->x_next)) {
        logf_(s, fmi2Error, "logStatusError", "out of memory");
        free_instance(s);
        return NULL;
    }
    set_defaults(s);
    return s;
}

void fmi2FreeInstance(fmi2Component c) {
    if (allowed(c, FREE_INSTANCE)) free_instance((Instance*)c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance* s = (Instance*)c;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    ENTER(c, SETUP_EXPERIMENT);
    if (!isfinite(startTime)) FAIL(s, "fmi2SetupExperiment: startTime %g is not finite", startTime);
    s->start_time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance* s = (Instance*)c;
    ENTER(c, ENTER_INITIALIZATION_MODE);
    s->state = INITIALIZATION_MODE;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
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
    s->state = STEP_COMPLETE;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance* s = (Instance*)c;
    ENTER(c, TERMINATE);
    s->state = TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance* s = (Instance*)c;
    ENTER(c, RESET);
    set_defaults(s);
    return fmi2OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Get and set                                                                              */

static const sblsim_variable* find(Instance* s, fmi2ValueReference vr, int type, const char* caller) {
    const sblsim_model* m = model();
    if (vr >= (fmi2ValueReference)m->n_variables || m->variables[vr].type != type) {
        logf_(s, fmi2Error, "logStatusError", "%s: no variable of this type with value reference %u", caller,
              (unsigned)vr);
        return NULL;
    }
    return &m->variables[vr];
}

static fmi2Status check_range(Instance* s, const sblsim_variable* v, double value, const char* caller) {
    char range[96];
    if (sblsim_in_range(v, value)) return fmi2OK;
    sblsim_describe_range(v, range, sizeof range);
    FAIL(s, "%s: %s = %g is outside the allowed range %s", caller, v->name, value, range);
}

static fmi2Status check_set(Instance* s, const sblsim_variable* v, const char* caller) {
    if (v->causality == SBLSIM_OUTPUT) FAIL(s, "%s: %s is an output and cannot be set", caller, v->name);
    if (v->causality == SBLSIM_PARAMETER && s->state != INSTANTIATED && s->state != INITIALIZATION_MODE)
        FAIL(s, "%s: %s is a fixed parameter; set it before fmi2ExitInitializationMode", caller, v->name);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance* s = (Instance*)c;
    size_t i;
    ENTER(c, GET_REAL);
    for (i = 0; i < nvr; i++) {
        const sblsim_variable* v = find(s, vr[i], SBLSIM_REAL, "fmi2GetReal");
        if (v == NULL) return fmi2Error;
        value[i] = *sblsim_slot(&s->run, v);
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    Instance* s = (Instance*)c;
    size_t i;
    ENTER(c, GET_INTEGER);
    for (i = 0; i < nvr; i++) {
        const sblsim_variable* v = find(s, vr[i], SBLSIM_INTEGER, "fmi2GetInteger");
        if (v == NULL) return fmi2Error;
        value[i] = (fmi2Integer)floor(*sblsim_slot(&s->run, v) + 0.5);
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    Instance* s = (Instance*)c;
    size_t i;
    ENTER(c, GET_BOOLEAN);
    for (i = 0; i < nvr; i++) {
        const sblsim_variable* v = find(s, vr[i], SBLSIM_BOOLEAN, "fmi2GetBoolean");
        if (v == NULL) return fmi2Error;
        value[i] = *sblsim_slot(&s->run, v) > 0.5 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    Instance* s = (Instance*)c;
    (void)vr;
    (void)value;
    ENTER(c, GET_STRING);
    if (nvr == 0) return fmi2OK;
    FAIL(s, "fmi2GetString: this FMU has no String variables");
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance* s = (Instance*)c;
    size_t i;
    ENTER(c, SET_REAL);
    for (i = 0; i < nvr; i++) {
        const sblsim_variable* v = find(s, vr[i], SBLSIM_REAL, "fmi2SetReal");
        if (v == NULL || check_set(s, v, "fmi2SetReal") != fmi2OK) return fmi2Error;
        if (!isfinite(value[i])) FAIL(s, "fmi2SetReal: %s = %g is not finite", v->name, value[i]);
        if (check_range(s, v, value[i], "fmi2SetReal") != fmi2OK) return fmi2Error;
        *sblsim_slot(&s->run, v) = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    Instance* s = (Instance*)c;
    size_t i;
    ENTER(c, SET_INTEGER);
    for (i = 0; i < nvr; i++) {
        const sblsim_variable* v = find(s, vr[i], SBLSIM_INTEGER, "fmi2SetInteger");
        if (v == NULL || check_set(s, v, "fmi2SetInteger") != fmi2OK) return fmi2Error;
        if (check_range(s, v, (double)value[i], "fmi2SetInteger") != fmi2OK) return fmi2Error;
        *sblsim_slot(&s->run, v) = (double)value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    Instance* s = (Instance*)c;
    size_t i;
    ENTER(c, SET_BOOLEAN);
    for (i = 0; i < nvr; i++) {
        const sblsim_variable* v = find(s, vr[i], SBLSIM_BOOLEAN, "fmi2SetBoolean");
        if (v == NULL || check_set(s, v, "fmi2SetBoolean") != fmi2OK) return fmi2Error;
        *sblsim_slot(&s->run, v) = value[i] ? 1.0 : 0.0;
    }
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    Instance* s = (Instance*)c;
    (void)vr;
    (void)value;
    ENTER(c, SET_STRING);
    if (nvr == 0) return fmi2OK;
    FAIL(s, "fmi2SetString: this FMU has no String variables");
}

/* ---------------------------------------------------------------------------------------- */
/* FMU state: a sblsim_saved (sblsim_fmu_state.h)                                           */

#define SBLSIM_MAGIC 0x53424c53494d3032ULL /* "SBLSIM02": the serialized layout of sblsim_fmu_state.h */
/* The states past initialization: a deserialized state in one of them has its parameters checked. */
#define PAST_INITIALIZATION (IN(STEP_COMPLETE) | IN(TERMINATED))

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state) {
    Instance* s = (Instance*)c;
    ENTER(c, GET_FMU_STATE);
    if (state == NULL) FAIL(s, "fmi2GetFMUstate: no place for the state");
    if (*state == NULL) {
        *state = (fmi2FMUstate)sblsim_saved_new(model());
        if (*state == NULL) FAIL(s, "fmi2GetFMUstate: out of memory");
    }
    sblsim_save(&s->run, s->state, s->start_time, (sblsim_saved*)*state);
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    Instance* s = (Instance*)c;
    const sblsim_saved* from = (const sblsim_saved*)state;
    ENTER(c, SET_FMU_STATE);
    if (from == NULL) FAIL(s, "fmi2SetFMUstate: no state");
    sblsim_restore(&s->run, s->x, s->x_next, from);
    s->state = (State)from->state;
    s->start_time = from->start_time;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state) {
    ENTER(c, FREE_FMU_STATE);
    if (state == NULL || *state == NULL) return fmi2OK;
    sblsim_saved_free((sblsim_saved*)*state);
    *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size) {
    (void)state;
    ENTER(c, SERIALIZED_FMU_STATE_SIZE);
    *size = sblsim_serialized_size(model());
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    Instance* s = (Instance*)c;
    size_t needed = sblsim_serialized_size(model());
    ENTER(c, SERIALIZE_FMU_STATE);
    if (state == NULL || size < needed) FAIL(s, "fmi2SerializeFMUstate: buffer of %lu bytes, %lu needed",
                                                          (unsigned long)size, (unsigned long)needed);
    sblsim_serialize(model(), SBLSIM_MAGIC, (const sblsim_saved*)state, bytes);
    return fmi2OK;
}

/* Checked before it is taken: the caller's state object changes only if it is (sblsim_deserialize). */
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate* state) {
    Instance* s = (Instance*)c;
    char message[SBLSIM_STATE_MESSAGE];
    sblsim_saved* into;
    ENTER(c, DESERIALIZE_FMU_STATE);
    if (state == NULL) FAIL(s, "fmi2DeSerializeFMUstate: no place for the state");
    into = *state != NULL ? (sblsim_saved*)*state : sblsim_saved_new(model());
    if (into == NULL) FAIL(s, "fmi2DeSerializeFMUstate: out of memory");
    if (sblsim_deserialize(model(), SBLSIM_MAGIC, N_STATES, PAST_INITIALIZATION, bytes, size, into, message,
                           sizeof message)) {
        if (*state == NULL) sblsim_saved_free(into);
        FAIL(s, "fmi2DeSerializeFMUstate: %s", message);
    }
    *state = (fmi2FMUstate)into;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown_ref;
    (void)nUnknown;
    (void)vKnown_ref;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    ENTER(c, GET_DIRECTIONAL_DERIVATIVE);
    FAIL((Instance*)c, "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative=false)");
}

/* ---------------------------------------------------------------------------------------- */
/* Co-Simulation                                                                            */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    ENTER(c, SET_REAL_INPUT_DERIVATIVES);
    FAIL((Instance*)c, "fmi2SetRealInputDerivatives: not supported (canInterpolateInputs=false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    ENTER(c, GET_REAL_OUTPUT_DERIVATIVES);
    FAIL((Instance*)c, "fmi2GetRealOutputDerivatives: not supported (maxOutputDerivativeOrder=0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance* s = (Instance*)c;
    char message[SBLSIM_MESSAGE];
    double t = currentCommunicationPoint, h = communicationStepSize;
    (void)noSetFMUStatePriorToCurrentPoint;
    ENTER(c, DO_STEP);
    if (!(h > 0.0) || !isfinite(h)) FAIL(s, "fmi2DoStep: communicationStepSize %g must be positive and finite", h);
    if (!isfinite(t) || !(fabs(t - s->run.t) <= 1e-9 * (1.0 + fabs(t)))) /* a NaN time is a gap too */
        FAIL(s, "fmi2DoStep: currentCommunicationPoint %.17g s differs from the FMU's time %.17g s (a gap or an "
                "overlap between steps)", t, s->run.t);
    if (sblsim_do_step(&s->run, t, h, message, sizeof message)) {
        s->state = ERROR_STATE;
        FAIL(s, "%s", message);
    }
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    ENTER(c, CANCEL_STEP);
    FAIL((Instance*)c, "fmi2CancelStep: doStep never runs asynchronously");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Status* value) {
    (void)kind;
    (void)value;
    ENTER(c, GET_STATUS);
    FAIL((Instance*)c, "fmi2GetStatus: doStep never returns fmi2Pending");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real* value) {
    Instance* s = (Instance*)c;
    ENTER(c, GET_REAL_STATUS);
    if (kind != fmi2LastSuccessfulTime) FAIL(s, "fmi2GetRealStatus: only fmi2LastSuccessfulTime is available");
    *value = s->run.t;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Integer* value) {
    (void)kind;
    (void)value;
    ENTER(c, GET_INTEGER_STATUS);
    FAIL((Instance*)c, "fmi2GetIntegerStatus: not available");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Boolean* value) {
    (void)kind;
    (void)value;
    ENTER(c, GET_BOOLEAN_STATUS);
    FAIL((Instance*)c, "fmi2GetBooleanStatus: not available");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind kind, fmi2String* value) {
    (void)kind;
    (void)value;
    ENTER(c, GET_STRING_STATUS);
    FAIL((Instance*)c, "fmi2GetStringStatus: not available");
}

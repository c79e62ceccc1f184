/* A plain C host that calls every FMI 2.0 function of a Co-Simulation FMU in every state it can reach.
 *
 *   c_states BINARY GUID BAD_VR BAD_VALUE
 *
 * For each state (Instantiated, InitializationMode, StepComplete, Terminated, Error) and each FMI function
 * taking an instance, it instantiates the FMU afresh, drives it into the state (the Error state by setting
 * the Real parameter BAD_VR to BAD_VALUE, outside its range, before fmi2ExitInitializationMode), makes the
 * call with harmless arguments (no variables, a state got just before) and prints one line:
 *   "<state> <function> <status> <the last message the FMU logged, or nothing>".
 * The test compares these lines with the FMI 2.0 state machine. A crash ends the output early.
 * Uses nothing but the C library, dlopen and the FMI headers.
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static char last[1024];

static void log_message(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                        fmi2String message, ...) {
    va_list args;
    (void)env;
    (void)name;
    (void)status;
    (void)category;
    va_start(args, message);
    vsnprintf(last, sizeof last, message, args);
    va_end(args);
}

static const char* const states[] = {"Instantiated", "InitializationMode", "StepComplete", "Terminated", "Error"};
static const char* const functions[] = {
    "fmi2SetDebugLogging", "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean",
    "fmi2GetString", "fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate",
    "fmi2SetFMUstate", "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate",
    "fmi2DeSerializeFMUstate", "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives",
    "fmi2GetRealOutputDerivatives", "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus",
    "fmi2GetIntegerStatus", "fmi2GetBooleanStatus", "fmi2GetStringStatus"};

static void* lib;

static void* load(const char* name) {
    void* f = dlsym(lib, name);
    if (f == NULL) {
        fprintf(stderr, "no %s\n", name);
        exit(2);
    }
    return f;
}

#define FN(name) ((name##TYPE*)load(#name))

/* An instance in state `state` (NULL if the FMU did not get there). */
static fmi2Component drive(int state, const char* guid, const fmi2CallbackFunctions* callbacks, unsigned bad_vr,
                           double bad_value) {
    fmi2Component c = FN(fmi2Instantiate)("states", fmi2CoSimulation, guid, "", callbacks, fmi2False, fmi2False);
    int ok = c != NULL;
    if (ok && state >= 1) {
        ok = FN(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK &&
             FN(fmi2EnterInitializationMode)(c) == fmi2OK;
    }
    if (ok && state == 4) {
        ok = FN(fmi2SetReal)(c, &bad_vr, 1, &bad_value) == fmi2OK && FN(fmi2ExitInitializationMode)(c) == fmi2Error;
    } else if (ok && state >= 2) {
        ok = FN(fmi2ExitInitializationMode)(c) == fmi2OK && FN(fmi2DoStep)(c, 0.0, 0.1, fmi2True) == fmi2OK;
        if (ok && state == 3) ok = FN(fmi2Terminate)(c) == fmi2OK;
    }
    if (!ok && c != NULL) {
        FN(fmi2FreeInstance)(c);
        c = NULL;
    }
    return c;
}

/* Call function `k` on `c` with harmless arguments; its status (fmi2FreeInstance: fmi2OK, `c` is gone). */
static int call(int k, fmi2Component c, double t) {
    fmi2ValueReference vr[1] = {0};
    fmi2Real real[1];
    fmi2Integer integer[1] = {0};
    fmi2Boolean boolean[1];
    fmi2String string[1] = {""};
    fmi2Status status_value;
    fmi2FMUstate state = NULL;
    size_t size = 0;
    int status = fmi2OK;
    /* the state functions act on a state got in this state of the instance (fmi2GetFMUstate is allowed in each) */
    if (k >= 16 && k <= 20) {
        if (FN(fmi2GetFMUstate)(c, &state) != fmi2OK) return -1;
        last[0] = 0;
    }
    switch (k) {
        case 0: return FN(fmi2SetDebugLogging)(c, fmi2False, 0, NULL);
        case 1: FN(fmi2FreeInstance)(c); return fmi2OK;
        case 2: return FN(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        case 3: return FN(fmi2EnterInitializationMode)(c);
        case 4: return FN(fmi2ExitInitializationMode)(c);
        case 5: return FN(fmi2Terminate)(c);
        case 6: return FN(fmi2Reset)(c);
        case 7: return FN(fmi2GetReal)(c, vr, 0, real);
        case 8: return FN(fmi2GetInteger)(c, vr, 0, integer);
        case 9: return FN(fmi2GetBoolean)(c, vr, 0, boolean);
        case 10: return FN(fmi2GetString)(c, vr, 0, string);
        case 11: return FN(fmi2SetReal)(c, vr, 0, real);
        case 12: return FN(fmi2SetInteger)(c, vr, 0, integer);
        case 13: return FN(fmi2SetBoolean)(c, vr, 0, boolean);
        case 14: return FN(fmi2SetString)(c, vr, 0, string);
        case 15: status = FN(fmi2GetFMUstate)(c, &state); break;
        case 16: status = FN(fmi2SetFMUstate)(c, state); break;
        case 17: status = FN(fmi2FreeFMUstate)(c, &state); break;
        case 18: status = FN(fmi2SerializedFMUstateSize)(c, state, &size); break;
        case 19: {
            size_t needed = 0;
            fmi2Byte* buffer;
            FN(fmi2SerializedFMUstateSize)(c, state, &needed);
            buffer = (fmi2Byte*)malloc(needed ? needed : 1);
            last[0] = 0;
            status = FN(fmi2SerializeFMUstate)(c, state, buffer, needed);
            free(buffer);
            break;
        }
        case 20: {
            size_t needed = 0;
            fmi2Byte* buffer;
            fmi2FMUstate copy = NULL;
            FN(fmi2SerializedFMUstateSize)(c, state, &needed);
            buffer = (fmi2Byte*)malloc(needed ? needed : 1);
            FN(fmi2SerializeFMUstate)(c, state, buffer, needed);
            last[0] = 0;
            status = FN(fmi2DeSerializeFMUstate)(c, buffer, needed, &copy);
            if (copy != NULL) {
                char keep[1024];
                strcpy(keep, last);
                FN(fmi2FreeFMUstate)(c, &copy);
                strcpy(last, keep);
            }
            free(buffer);
            break;
        }
        case 21: return FN(fmi2GetDirectionalDerivative)(c, vr, 0, vr, 0, real, real);
        case 22: return FN(fmi2SetRealInputDerivatives)(c, vr, 0, integer, real);
        case 23: return FN(fmi2GetRealOutputDerivatives)(c, vr, 0, integer, real);
        case 24: return FN(fmi2DoStep)(c, t, 0.1, fmi2True);
        case 25: return FN(fmi2CancelStep)(c);
        case 26: return FN(fmi2GetStatus)(c, fmi2DoStepStatus, &status_value);
        case 27: return FN(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, real);
        case 28: return FN(fmi2GetIntegerStatus)(c, fmi2DoStepStatus, integer);
        case 29: return FN(fmi2GetBooleanStatus)(c, fmi2Terminated, boolean);
        default: return FN(fmi2GetStringStatus)(c, fmi2PendingStatus, string);
    }
    if (state != NULL) {
        char keep[1024];
        strcpy(keep, last);
        FN(fmi2FreeFMUstate)(c, &state);
        strcpy(last, keep);
    }
    return status;
}

int main(int argc, char** argv) {
    fmi2CallbackFunctions callbacks = {log_message, calloc, free, NULL, NULL};
    unsigned bad_vr;
    int s, k, n = (int)(sizeof functions / sizeof functions[0]);
    if (argc != 5) {
        fprintf(stderr, "usage: c_states BINARY GUID BAD_VR BAD_VALUE\n");
        return 1;
    }
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
        return 2;
    }
    bad_vr = (unsigned)strtoul(argv[3], NULL, 10);
    for (s = 0; s < 5; s++) {
        for (k = 0; k < n; k++) {
            fmi2Component c = drive(s, argv[2], &callbacks, bad_vr, atof(argv[4]));
            int status;
            if (c == NULL) {
                printf("%s %s drive-failed %s\n", states[s], functions[k], last);
                continue;
            }
            last[0] = 0;
            status = call(k, c, s >= 2 ? 0.1 : 0.0);
            printf("%s %s %d %s\n", states[s], functions[k], status, last);
            fflush(stdout);
            if (k != 1) FN(fmi2FreeInstance)(c);
        }
    }
    dlclose(lib);
    return 0;
}

/* A plain C FMI 2.0 Co-Simulation host, as OMSimulator, Simulink or the OSP cosim tool load an FMU.
 *
 *   c_host BINARY GUID RESOURCE_URI STEPS H [VR=VALUE ...] < output value references
 *
 * dlopen()s the FMU binary, instantiates it TWICE (the second instance with every Real parameter
 * given as VR=VALUE, the first with the defaults), initializes both at t = 0, steps both STEPS
 * times by H [s], and prints every Real output of both instances after each step:
 *   "a <k> <value> <value> ..." and "b <k> <value> ...". Exit status 0 only if every call
 * returned fmi2OK. Uses nothing but the C library, dlopen and the FMI headers.
 *
 *   c_host --system STEPS H < system
 *
 * runs a system of FMUs as an FMI host that sets no parameter does (the FMUs' own start values): each FMU
 * instantiated once, initialized at t = 0, then STEPS Jacobi steps of H [s] (every input set from the outputs
 * at the start of the step, the initial outputs at the first, then every FMU stepped), printing the listed
 * outputs after each step as "s <k> <value> ...". The system comes on stdin, one item a line:
 *   fmu BINARY GUID RESOURCE_URI
 *   link FROM_FMU FROM_VR TO_FMU TO_VR TYPE      (FMUs by their order, from 0; TYPE r, i or b)
 *   out FMU VR TYPE
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list args;
    (void)env;
    va_start(args, message);
    fprintf(stderr, "[%s %d %s] ", name, (int)status, category);
    vfprintf(stderr, message, args);
    fprintf(stderr, "\n");
    va_end(args);
}

#define LOAD(name) name##TYPE* name = (name##TYPE*)dlsym(lib, #name); if (!name) { fprintf(stderr, "no %s\n", #name); return 2; }
#define CHECK(call) if ((call) != fmi2OK) { fprintf(stderr, "failed: %s\n", #call); return 3; }

/* One FMU of a system: its library, instance and the FMI functions the system mode calls. */
typedef struct {
    void* lib;
    fmi2Component c;
    fmi2DoStepTYPE* doStep;
    fmi2GetRealTYPE* getReal;
    fmi2GetIntegerTYPE* getInteger;
    fmi2GetBooleanTYPE* getBoolean;
    fmi2SetRealTYPE* setReal;
    fmi2SetIntegerTYPE* setInteger;
    fmi2SetBooleanTYPE* setBoolean;
    fmi2TerminateTYPE* terminate;
    fmi2FreeInstanceTYPE* freeInstance;
} unit;

typedef struct {
    int from, to;
    unsigned int from_vr, to_vr;
    char type;
} wire;

/* The value of one variable as a double (Integer and Boolean converted). */
static int get_value(unit* u, unsigned int vr, char type, double* out) {
    fmi2Real r;
    fmi2Integer i;
    fmi2Boolean b;
    if (type == 'r') {
        if (u->getReal(u->c, &vr, 1, &r) != fmi2OK) return 1;
        *out = r;
    } else if (type == 'i') {
        if (u->getInteger(u->c, &vr, 1, &i) != fmi2OK) return 1;
        *out = i;
    } else {
        if (u->getBoolean(u->c, &vr, 1, &b) != fmi2OK) return 1;
        *out = b ? 1.0 : 0.0;
    }
    return 0;
}

static int set_value(unit* u, unsigned int vr, char type, double value) {
    fmi2Real r = value;
    fmi2Integer i = (fmi2Integer)value;
    fmi2Boolean b = value != 0.0;
    if (type == 'r') return u->setReal(u->c, &vr, 1, &r) != fmi2OK;
    if (type == 'i') return u->setInteger(u->c, &vr, 1, &i) != fmi2OK;
    return u->setBoolean(u->c, &vr, 1, &b) != fmi2OK;
}

#define MAX_UNITS 16
#define MAX_WIRES 1024
#define SYSTEM_LOAD(u, name, field) \
    if (!((u)->field = (name##TYPE*)dlsym((u)->lib, #name))) { fprintf(stderr, "no %s\n", #name); return 2; }

static int run_system(int steps, double h) {
    static unit units[MAX_UNITS];
    static wire wires[MAX_WIRES], outs[MAX_WIRES];
    static double held[MAX_WIRES];
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    char kind[16], binary[4096], guid[256], uri[4096];
    int n_units = 0, n_wires = 0, n_outs = 0, i, k;
    double value;
    while (scanf("%15s", kind) == 1) {
        if (!strcmp(kind, "fmu") && n_units < MAX_UNITS && scanf("%4095s %255s %4095s", binary, guid, uri) == 3) {
            unit* u = &units[n_units];
            fmi2InstantiateTYPE* instantiate;
            fmi2SetupExperimentTYPE* setup;
            fmi2EnterInitializationModeTYPE* enter;
            fmi2ExitInitializationModeTYPE* exit_init;
            u->lib = dlopen(binary, RTLD_NOW | RTLD_LOCAL);
            if (!u->lib) {
                fprintf(stderr, "dlopen: %s\n", dlerror());
                return 2;
            }
            instantiate = (fmi2InstantiateTYPE*)dlsym(u->lib, "fmi2Instantiate");
            setup = (fmi2SetupExperimentTYPE*)dlsym(u->lib, "fmi2SetupExperiment");
            enter = (fmi2EnterInitializationModeTYPE*)dlsym(u->lib, "fmi2EnterInitializationMode");
            exit_init = (fmi2ExitInitializationModeTYPE*)dlsym(u->lib, "fmi2ExitInitializationMode");
            if (!instantiate || !setup || !enter || !exit_init) {
                fprintf(stderr, "%s lacks an FMI function\n", binary);
                return 2;
            }
            SYSTEM_LOAD(u, fmi2DoStep, doStep) SYSTEM_LOAD(u, fmi2GetReal, getReal)
            SYSTEM_LOAD(u, fmi2GetInteger, getInteger) SYSTEM_LOAD(u, fmi2GetBoolean, getBoolean)
            SYSTEM_LOAD(u, fmi2SetReal, setReal) SYSTEM_LOAD(u, fmi2SetInteger, setInteger)
            SYSTEM_LOAD(u, fmi2SetBoolean, setBoolean) SYSTEM_LOAD(u, fmi2Terminate, terminate)
            SYSTEM_LOAD(u, fmi2FreeInstance, freeInstance)
            u->c = instantiate(binary, fmi2CoSimulation, guid, uri, &callbacks, fmi2False, fmi2False);
            if (!u->c) {
                fprintf(stderr, "fmi2Instantiate returned NULL for %s\n", binary);
                return 3;
            }
            /* no parameter is set: the FMU runs its start values */
            CHECK(setup(u->c, fmi2False, 0.0, 0.0, fmi2False, 0.0))
            CHECK(enter(u->c))
            CHECK(exit_init(u->c))
            n_units++;
        } else if (!strcmp(kind, "link") && n_wires < MAX_WIRES) {
            wire* w = &wires[n_wires++];
            if (scanf("%d %u %d %u %c", &w->from, &w->from_vr, &w->to, &w->to_vr, &w->type) != 5) return 1;
        } else if (!strcmp(kind, "out") && n_outs < MAX_WIRES) {
            wire* w = &outs[n_outs++];
            if (scanf("%d %u %c", &w->from, &w->from_vr, &w->type) != 3) return 1;
        } else {
            fprintf(stderr, "bad system line: %s\n", kind);
            return 1;
        }
    }
    for (i = 0; i < n_wires; i++) {
        if (wires[i].from < 0 || wires[i].from >= n_units || wires[i].to < 0 || wires[i].to >= n_units) return 1;
    }
    for (i = 0; i < n_outs; i++) {
        if (outs[i].from < 0 || outs[i].from >= n_units) return 1;
    }
    for (k = 1; k <= steps; k++) {
        for (i = 0; i < n_wires; i++) /* Jacobi: every input from the outputs at the start of the step */
            if (get_value(&units[wires[i].from], wires[i].from_vr, wires[i].type, &held[i])) return 3;
        for (i = 0; i < n_wires; i++)
            if (set_value(&units[wires[i].to], wires[i].to_vr, wires[i].type, held[i])) return 3;
        for (i = 0; i < n_units; i++) CHECK(units[i].doStep(units[i].c, (k - 1) * h, h, fmi2True))
        printf("s %d", k);
        for (i = 0; i < n_outs; i++) {
            if (get_value(&units[outs[i].from], outs[i].from_vr, outs[i].type, &value)) return 3;
            printf(" %.17g", value);
        }
        printf("\n");
    }
    for (i = 0; i < n_units; i++) {
        CHECK(units[i].terminate(units[i].c))
        units[i].freeInstance(units[i].c);
        dlclose(units[i].lib);
    }
    return 0;
}

int main(int argc, char** argv) {
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c[2];
    unsigned int vr[4096], pvr[256], ivr[256];
    double value[4096], pval[256];
    int ival[256];
    int n_out = 0, n_par = 0, n_int = 0, k, i, j, steps;
    double h;
    void* lib;
    if (argc == 4 && !strcmp(argv[1], "--system")) return run_system(atoi(argv[2]), atof(argv[3]));
    if (argc < 6) {
        fprintf(stderr, "usage: c_host BINARY GUID RESOURCE_URI STEPS H [VR=VALUE | iVR=INTEGER ...]\n");
        return 1;
    }
    steps = atoi(argv[4]);
    h = atof(argv[5]);
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
        return 2;
    }
    {
        LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
        LOAD(fmi2ExitInitializationMode) LOAD(fmi2DoStep) LOAD(fmi2GetReal) LOAD(fmi2SetReal) LOAD(fmi2SetInteger)
        LOAD(fmi2FreeInstance) LOAD(fmi2Terminate)
        /* output value references come on stdin, one per line; parameters as VR=VALUE (Real) and iVR=VALUE
           (Integer) arguments */
        while (n_out < 4096 && scanf("%u", &vr[n_out]) == 1) n_out++;
        for (i = 6; i < argc; i++) {
            if (n_int < 256 && sscanf(argv[i], "i%u=%d", &ivr[n_int], &ival[n_int]) == 2) n_int++;
            else if (n_par < 256 && sscanf(argv[i], "%u=%lf", &pvr[n_par], &pval[n_par]) == 2) n_par++;
        }
        for (i = 0; i < 2; i++) {
            c[i] = fmi2Instantiate(i ? "b" : "a", fmi2CoSimulation, argv[2], argv[3], &callbacks, fmi2False, fmi2False);
            if (!c[i]) {
                fprintf(stderr, "fmi2Instantiate returned NULL\n");
                return 3;
            }
            CHECK(fmi2SetupExperiment(c[i], fmi2False, 0.0, 0.0, fmi2False, 0.0))
            CHECK(fmi2EnterInitializationMode(c[i]))
            if (i == 1 && n_par) CHECK(fmi2SetReal(c[i], pvr, (size_t)n_par, pval))
            if (i == 1 && n_int) CHECK(fmi2SetInteger(c[i], ivr, (size_t)n_int, ival))
            CHECK(fmi2ExitInitializationMode(c[i]))
        }
        for (k = 1; k <= steps; k++) {
            for (i = 0; i < 2; i++) {
                CHECK(fmi2DoStep(c[i], (k - 1) * h, h, fmi2True))
                CHECK(fmi2GetReal(c[i], vr, (size_t)n_out, value))
                printf("%c %d", i ? 'b' : 'a', k);
                for (j = 0; j < n_out; j++) printf(" %.17g", value[j]);
                printf("\n");
            }
        }
        for (i = 0; i < 2; i++) {
            CHECK(fmi2Terminate(c[i]))
            fmi2FreeInstance(c[i]);
        }
    }
    dlclose(lib);
    return 0;
}

/* A plain C FMI 2.0 Co-Simulation host, as OMSimulator, Simulink or the OSP cosim tool load an FMU.
 *
 *   c_host BINARY GUID RESOURCE_URI STEPS H [VR=VALUE ...] < output value references
 *
 * dlopen()s the FMU binary, instantiates it TWICE (the second instance with every Real parameter
 * given as VR=VALUE, the first with the defaults), initializes both at t = 0, steps both STEPS
 * times by H [s], and prints every Real output of both instances after each step:
 *   "a <k> <value> <value> ..." and "b <k> <value> ...". Exit status 0 only if every call
 * returned fmi2OK. Uses nothing but the C library, dlopen and the FMI headers.
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

int main(int argc, char** argv) {
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c[2];
    unsigned int vr[4096], pvr[256], ivr[256];
    double value[4096], pval[256];
    int ival[256];
    int n_out = 0, n_par = 0, n_int = 0, k, i, j, steps;
    double h;
    void* lib;
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

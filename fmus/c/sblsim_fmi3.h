/* The FMI 3.0 view of a component's variables (fmus/arrays.py, generated into <stem>_fmi3.c).
 *
 * An FMI 3.0 variable is a scalar or an array; its elements, in row-major order, are variables of the model
 * record (their FMI 2.0 value references, i.e. indices into sblsim_model.variables). An output's element may
 * repeat (the covariance matrix shows each off-diagonal entry twice). The structural parameter that carries the
 * beacon count has no element: its value is `constant` (it is compiled in; only that value is accepted).
 */
#ifndef SBLSIM_FMI3_H
#define SBLSIM_FMI3_H

#include "sblsim_runtime.h"

/* Beside SBLSIM_REAL (Float64), SBLSIM_INTEGER (Int32) and SBLSIM_BOOLEAN: a UInt64 structural parameter. */
enum { SBLSIM_UINT64 = 3 };
/* Beside SBLSIM_PARAMETER, SBLSIM_INPUT and SBLSIM_OUTPUT: the causality structuralParameter. */
enum { SBLSIM_STRUCTURAL = 3 };

typedef struct {
    const char* name;
    unsigned int vr;   /* its FMI 3.0 value reference */
    int type;          /* SBLSIM_REAL, SBLSIM_INTEGER, SBLSIM_BOOLEAN or SBLSIM_UINT64 */
    int causality;     /* SBLSIM_PARAMETER, SBLSIM_INPUT, SBLSIM_OUTPUT or SBLSIM_STRUCTURAL */
    int n_elements;    /* 1 for a scalar; 0 for the structural parameter */
    const int* elements;
    unsigned long long constant; /* the structural parameter's value */
} sblsim_fmi3_variable;

typedef struct {
    const sblsim_fmi3_variable* variables; /* in value-reference order: variables[k].vr == k */
    int n_variables;
    /* A model that delivers packets at their arrival (the channel): the indices in y of the packet counter and of
       the arrival epoch (fmus/arrays.py, ARRIVAL_OUTPUTS); -1 for the others. doStep may return early there. */
    int arrival_seq, arrival_time;
} sblsim_fmi3_table;

#endif

/* sblsim embedded API: see sblsim_embedded.h. */
#include "sblsim_embedded.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct sblsim_handle {
    sblsim_instance run;
    double* memory;
    uint64_t* draws;
    sblsim_work* work;
    int started;
    char error[SBLSIM_MESSAGE];
};

sblsim_handle* sblsim_new(const sblsim_model* m) {
    size_t total = (size_t)(m->n_p + m->n_d + 2 * m->n_x + m->n_u + m->n_y) + 1;
    sblsim_handle* h = (sblsim_handle*)calloc(1, sizeof(sblsim_handle));
    if (h == NULL) return NULL;
    h->memory = (double*)calloc(total, sizeof(double));
    h->draws = (uint64_t*)calloc((size_t)(m->n_purposes > 0 ? m->n_purposes : 1), sizeof(uint64_t));
    h->work = sblsim_work_new(m);
    if (h->memory == NULL || h->draws == NULL || h->work == NULL) {
        sblsim_free(h);
        return NULL;
    }
    h->run.model = m;
    h->run.p = h->memory;
    h->run.d = h->run.p + m->n_p;
    h->run.x = h->run.d + m->n_d;
    h->run.x_next = h->run.x + m->n_x;
    h->run.u = h->run.x_next + m->n_x;
    h->run.y = h->run.u + m->n_u;
    h->run.draws = h->draws;
    h->run.work = h->work;
    memcpy(h->run.p, m->p_start, sizeof(double) * (size_t)m->n_p);
    memcpy(h->run.u, m->u_start, sizeof(double) * (size_t)m->n_u);
    return h;
}

static const sblsim_variable* lookup(const sblsim_model* m, const char* name) {
    int k;
    for (k = 0; k < m->n_variables; k++)
        if (strcmp(m->variables[k].name, name) == 0) return &m->variables[k];
    return NULL;
}

int sblsim_set(sblsim_handle* h, const char* name, double value) {
    const sblsim_variable* v = lookup(h->run.model, name);
    if (v == NULL || v->causality == SBLSIM_OUTPUT) {
        snprintf(h->error, sizeof h->error, "%s: not a parameter or input of %s", name, h->run.model->name);
        return -1;
    }
    if (v->causality == SBLSIM_PARAMETER && h->started) {
        snprintf(h->error, sizeof h->error, "%s: parameters are set before sblsim_start", name);
        return -1;
    }
    if (!isfinite(value)) {
        snprintf(h->error, sizeof h->error, "%s: %g is not finite", name, value);
        return -1;
    }
    (v->causality == SBLSIM_PARAMETER ? h->run.p : h->run.u)[v->index] = value;
    return 0;
}

double sblsim_get(const sblsim_handle* h, const char* name) {
    const sblsim_variable* v = lookup(h->run.model, name);
    if (v == NULL) return NAN;
    if (v->causality == SBLSIM_PARAMETER) return h->run.p[v->index];
    if (v->causality == SBLSIM_INPUT) return h->run.u[v->index];
    return h->run.y[v->index];
}

int sblsim_start(sblsim_handle* h, double t0) {
    if (sblsim_check_parameters(h->run.model, h->run.p, h->error, sizeof h->error)) return -1;
    if (sblsim_initialize(&h->run, t0, h->error, sizeof h->error)) return -1;
    h->started = 1;
    return 0;
}

int sblsim_step(sblsim_handle* h, double t, double step) {
    if (!h->started) {
        snprintf(h->error, sizeof h->error, "sblsim_step: call sblsim_start first");
        return -1;
    }
    if (!(step > 0.0)) {
        snprintf(h->error, sizeof h->error, "sblsim_step: step %g must be positive", step);
        return -1;
    }
    return sblsim_do_step(&h->run, t, step, h->error, sizeof h->error);
}

const char* sblsim_error(const sblsim_handle* h) { return h->error; }

void sblsim_free(sblsim_handle* h) {
    if (h == NULL) return;
    free(h->memory);
    free(h->draws);
    sblsim_work_free(h->work);
    free(h);
}

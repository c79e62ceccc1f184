/* sblsim FMU state: see sblsim_fmu_state.h. */
#include "sblsim_fmu_state.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The five value blocks of a state, in order: p, d, x, u, y. */
enum { N_BLOCKS = 5 };

static size_t value_count(const sblsim_model* m) { return (size_t)(m->n_p + m->n_d + m->n_x + m->n_u + m->n_y); }

static int block_size(const sblsim_model* m, int k) {
    const int sizes[N_BLOCKS] = {m->n_p, m->n_d, m->n_x, m->n_u, m->n_y};
    return sizes[k];
}

/* The instance's vectors in block order (x: the current state, run->x). */
static void value_blocks(const sblsim_instance* run, double* blocks[N_BLOCKS]) {
    blocks[0] = run->p;
    blocks[1] = run->d;
    blocks[2] = run->x;
    blocks[3] = run->u;
    blocks[4] = run->y;
}

static size_t purposes(const sblsim_model* m) { return (size_t)m->n_purposes; }

static double* vector(int n) { return (double*)calloc((size_t)(n > 0 ? n : 1), sizeof(double)); }

int sblsim_vectors_new(sblsim_instance* run, const sblsim_model* m, double** x, double** x_next) {
    run->model = m;
    run->p = vector(m->n_p);
    run->d = vector(m->n_d);
    run->u = vector(m->n_u);
    run->y = vector(m->n_y);
    run->draws = (uint64_t*)calloc(purposes(m) > 0 ? purposes(m) : 1, sizeof(uint64_t));
    run->work = sblsim_work_new(m);
    *x = vector(m->n_x);
    *x_next = vector(m->n_x);
    run->x = *x;
    run->x_next = *x_next;
    return run->p && run->d && run->u && run->y && run->draws && run->work && *x && *x_next ? 0 : -1;
}

void sblsim_vectors_reset(sblsim_instance* run, double* x, double* x_next) {
    const sblsim_model* m = run->model;
    memcpy(run->p, m->p_start, sizeof(double) * (size_t)m->n_p);
    memcpy(run->u, m->u_start, sizeof(double) * (size_t)m->n_u);
    memset(run->y, 0, sizeof(double) * (size_t)m->n_y);
    memset(x, 0, sizeof(double) * (size_t)m->n_x);
    memset(run->d, 0, sizeof(double) * (size_t)m->n_d);
    run->x = x;
    run->x_next = x_next;
    run->t0 = run->t = 0.0;
}

void sblsim_vectors_free(sblsim_instance* run, double* x, double* x_next) {
    free(run->p);
    free(run->d);
    free(x);
    free(x_next);
    free(run->u);
    free(run->y);
    free(run->draws);
    sblsim_work_free(run->work);
}

double* sblsim_slot(sblsim_instance* run, const sblsim_variable* v) {
    if (v->causality == SBLSIM_PARAMETER) return &run->p[v->index];
    if (v->causality == SBLSIM_INPUT) return &run->u[v->index];
    return &run->y[v->index];
}

sblsim_saved* sblsim_saved_new(const sblsim_model* m) {
    sblsim_saved* out = (sblsim_saved*)calloc(1, sizeof(sblsim_saved));
    size_t n = value_count(m);
    if (out == NULL) return NULL;
    out->values = (double*)calloc(n > 0 ? n : 1, sizeof(double));
    out->draws = (uint64_t*)calloc(purposes(m) > 0 ? purposes(m) : 1, sizeof(uint64_t));
    if (out->values == NULL || out->draws == NULL) {
        sblsim_saved_free(out);
        return NULL;
    }
    return out;
}

void sblsim_saved_free(sblsim_saved* s) {
    if (s == NULL) return;
    free(s->values);
    free(s->draws);
    free(s);
}

/* Copies the state number, times, values and draws of `from` into `to`. */
static void copy_saved(const sblsim_model* m, const sblsim_saved* from, sblsim_saved* to) {
    to->state = from->state;
    to->start_time = from->start_time;
    to->t0 = from->t0;
    to->t = from->t;
    memcpy(to->values, from->values, sizeof(double) * value_count(m));
    memcpy(to->draws, from->draws, sizeof(uint64_t) * purposes(m));
}

void sblsim_save(const sblsim_instance* run, int state, double start_time, sblsim_saved* to) {
    const sblsim_model* m = run->model;
    double* blocks[N_BLOCKS];
    size_t offset = 0;
    int k;
    value_blocks(run, blocks);
    to->state = state;
    to->start_time = start_time;
    to->t0 = run->t0;
    to->t = run->t;
    for (k = 0; k < N_BLOCKS; k++) {
        memcpy(to->values + offset, blocks[k], sizeof(double) * (size_t)block_size(m, k));
        offset += (size_t)block_size(m, k);
    }
    memcpy(to->draws, run->draws, sizeof(uint64_t) * purposes(m));
}

void sblsim_restore(sblsim_instance* run, double* x, double* x_next, const sblsim_saved* from) {
    const sblsim_model* m = run->model;
    double* blocks[N_BLOCKS];
    size_t offset = 0;
    int k;
    run->x = x;
    run->x_next = x_next;
    value_blocks(run, blocks);
    run->t0 = from->t0;
    run->t = from->t;
    for (k = 0; k < N_BLOCKS; k++) {
        memcpy(blocks[k], from->values + offset, sizeof(double) * (size_t)block_size(m, k));
        offset += (size_t)block_size(m, k);
    }
    memcpy(run->draws, from->draws, sizeof(uint64_t) * purposes(m));
    sblsim_choose_events(run); /* its parameters */
}

/* ---------------------------------------------------------------------------------------- */
/* Serialization                                                                            */

enum { HEADER_WORDS = 4, TIME_WORDS = 3 }; /* magic, value count, purposes, state; start_time, t0, t */

size_t sblsim_serialized_size(const sblsim_model* m) {
    return sizeof(uint64_t) * (HEADER_WORDS + TIME_WORDS + value_count(m) + purposes(m));
}

void sblsim_serialize(const sblsim_model* m, uint64_t magic, const sblsim_saved* saved, void* bytes) {
    uint64_t header[HEADER_WORDS];
    double times[TIME_WORDS];
    char* out = (char*)bytes;
    header[0] = magic;
    header[1] = (uint64_t)value_count(m);
    header[2] = (uint64_t)m->n_purposes;
    header[3] = (uint64_t)saved->state;
    times[0] = saved->start_time;
    times[1] = saved->t0;
    times[2] = saved->t;
    memcpy(out, header, sizeof header);
    out += sizeof header;
    memcpy(out, times, sizeof times);
    out += sizeof times;
    memcpy(out, saved->values, sizeof(double) * value_count(m));
    out += sizeof(double) * value_count(m);
    memcpy(out, saved->draws, sizeof(uint64_t) * purposes(m));
}

/* The FMU variable of causality `causality` at `index` of its vector (NULL if none: a table row, say). */
static const sblsim_variable* variable_at(const sblsim_model* m, int causality, int index) {
    int k;
    for (k = 0; k < m->n_variables; k++)
        if (m->variables[k].causality == causality && m->variables[k].index == index) return &m->variables[k];
    return NULL;
}

/* Whether the outputs a state holds as NaN are NaN where the model's output function puts them, at the state's
   own x, p, d and t: a receiver's estimate before its first fix (undefined, NaN; models/receiver/core.py's
   NO_ESTIMATE). 0 if every NaN output is the model's, else -1 with a message naming the first that is not (the
   output function gives a value there: the state was changed). Called only for a state past initialization whose
   values are otherwise finite and whose parameters are checked, so the function runs on what a step would. */
static int check_undefined_outputs(const sblsim_model* m, const sblsim_saved* v, char* message, size_t size) {
    const double* p = v->values;
    const double* d = p + m->n_p;
    const double* x = d + m->n_d;
    const double* y = x + m->n_x + m->n_u;
    double* model_y = (double*)calloc((size_t)(m->n_y > 0 ? m->n_y : 1), sizeof(double));
    int i, failed = 0;
    if (model_y == NULL) {
        snprintf(message, size, "out of memory");
        return -1;
    }
    if (sblsim_output_at(m, x, p, d, v->t, model_y)) {
        snprintf(message, size, "its outputs cannot be computed from its state");
        failed = -1;
    }
    for (i = 0; !failed && i < m->n_y; i++) {
        if (isnan(y[i]) && !isnan(model_y[i])) {
            const sblsim_variable* named = variable_at(m, SBLSIM_OUTPUT, i);
            if (named != NULL)
                snprintf(message, size, "%s = nan is not finite (its state gives %.17g)", named->name, model_y[i]);
            else
                snprintf(message, size, "y[%d] = nan is not finite (its state gives %.17g)", i, model_y[i]);
            failed = -1;
        }
    }
    free(model_y);
    return failed;
}

/* Why a deserialized state cannot be taken: 0 if it can, else -1 with a message naming what is wrong. Every value
   is finite but for an output that is NaN where the model's output function makes it NaN (an undefined output: a
   receiver's estimate before its first fix), in a state past initialization. */
static int check_saved(const sblsim_model* m, const sblsim_saved* v, unsigned past_init_states, char* message,
                       size_t size) {
    static const char* const blocks[N_BLOCKS] = {"p", "d", "x", "u", "y"};
    const double* u = v->values + m->n_p + m->n_d + m->n_x;
    int past_init = (past_init_states >> v->state) & 1u;
    int undefined = 0; /* NaN outputs, checked against the model's output function once the rest is */
    size_t offset = 0;
    int k, i;
    if (!isfinite(v->start_time) || !isfinite(v->t0) || !isfinite(v->t)) {
        snprintf(message, size, "its times are not finite (start %g s, t0 %g s, t %g s)", v->start_time, v->t0, v->t);
        return -1;
    }
    if (v->t < v->t0 || (past_init && v->t0 < v->start_time)) {
        snprintf(message, size, "its times are out of order (start %.17g s, t0 %.17g s, t %.17g s)", v->start_time,
                 v->t0, v->t);
        return -1;
    }
    for (k = 0; k < N_BLOCKS; k++) {
        for (i = 0; i < block_size(m, k); i++) {
            double value = v->values[offset + (size_t)i];
            if (k == 4 && past_init && isnan(value)) {
                undefined = 1;
                continue;
            }
            if (!isfinite(value)) {
                const sblsim_variable* named = k == 3 ? variable_at(m, SBLSIM_INPUT, i)
                                               : k == 4 ? variable_at(m, SBLSIM_OUTPUT, i) : NULL;
                if (k == 0)
                    snprintf(message, size, "parameter %s = %g is not finite", m->parameters[i].name, value);
                else if (named != NULL)
                    snprintf(message, size, "%s = %g is not finite", named->name, value);
                else
                    snprintf(message, size, "%s[%d] = %g is not finite", blocks[k], i, value);
                return -1;
            }
        }
        offset += (size_t)block_size(m, k);
    }
    if (past_init && sblsim_check_parameters(m, v->values, message, size)) return -1;
    for (k = 0; k < m->n_variables; k++) {
        const sblsim_variable* in = &m->variables[k];
        if (in->causality == SBLSIM_INPUT && !sblsim_in_range(in, u[in->index])) {
            char range[96];
            sblsim_describe_range(in, range, sizeof range);
            snprintf(message, size, "%s = %g is outside the allowed range %s", in->name, u[in->index], range);
            return -1;
        }
    }
    if (undefined && check_undefined_outputs(m, v, message, size)) return -1;
    return 0;
}

int sblsim_deserialize(const sblsim_model* m, uint64_t magic, int n_states, unsigned past_init_states,
                       const void* bytes, size_t size, sblsim_saved* into, char* message, size_t message_size) {
    size_t needed = sblsim_serialized_size(m);
    uint64_t header[HEADER_WORDS];
    double times[TIME_WORDS];
    char why[SBLSIM_MESSAGE];
    const char* in = (const char*)bytes;
    sblsim_saved* fresh;
    if (bytes == NULL || size != needed) {
        snprintf(message, message_size, "%lu bytes, expected %lu", (unsigned long)size, (unsigned long)needed);
        return -1;
    }
    memcpy(header, in, sizeof header);
    in += sizeof header;
    if (header[0] != magic || header[1] != (uint64_t)value_count(m) || header[2] != (uint64_t)m->n_purposes) {
        snprintf(message, message_size, "not a serialized state of %s", m->name);
        return -1;
    }
    if (header[3] >= (uint64_t)n_states) {
        snprintf(message, message_size, "state number %llu is not one of the %d states; the state is refused",
                 (unsigned long long)header[3], n_states);
        return -1;
    }
    /* read into a new state object and check it: the caller's object changes only if it is taken */
    fresh = sblsim_saved_new(m);
    if (fresh == NULL) {
        snprintf(message, message_size, "out of memory");
        return -1;
    }
    memcpy(times, in, sizeof times);
    in += sizeof times;
    fresh->state = (int)header[3];
    fresh->start_time = times[0];
    fresh->t0 = times[1];
    fresh->t = times[2];
    memcpy(fresh->values, in, sizeof(double) * value_count(m));
    in += sizeof(double) * value_count(m);
    memcpy(fresh->draws, in, sizeof(uint64_t) * purposes(m));
    if (check_saved(m, fresh, past_init_states, why, sizeof why)) {
        sblsim_saved_free(fresh);
        snprintf(message, message_size, "%s; the state is refused", why);
        return -1;
    }
    copy_saved(m, fresh, into);
    sblsim_saved_free(fresh);
    return 0;
}

/* ---------------------------------------------------------------------------------------- */
/* Declared ranges                                                                          */

void sblsim_describe_range(const sblsim_variable* v, char* text, size_t size) {
    char lo[32], hi[32];
    int unit = v->unit && v->unit[0] && strcmp(v->unit, "1") != 0; /* "1": no unit to name */
    if (v->has_min) snprintf(lo, sizeof lo, "%g", v->min); else snprintf(lo, sizeof lo, "-inf");
    if (v->has_max) snprintf(hi, sizeof hi, "%g", v->max); else snprintf(hi, sizeof hi, "inf");
    snprintf(text, size, "%s%s, %s%s%s%s", v->has_min ? "[" : "(", lo, hi, v->has_max ? "]" : ")",
             unit ? " " : "", unit ? v->unit : "");
}

int sblsim_in_range(const sblsim_variable* v, double value) {
    return !(v->has_min && !(value >= v->min)) && !(v->has_max && !(value <= v->max));
}

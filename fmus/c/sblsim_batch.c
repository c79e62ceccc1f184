/* A batch of instances of one model stepped together: the local engine's compiled path.
 *
 * The caller fills the parameters (R x n_p: R parameter rows, 1 <= R <= B) and inputs (B x n_u),
 * says which row each of the B replicates uses (sblsim_batch_rows: the replicates of a design cell
 * differ only in their random streams, so they share one row and its derived values, prepared once),
 * and reads the outputs (B x n_y) through the pointers this API returns; one call steps every
 * replicate, with the same runtime (and so the same numbers) as the FMUs.
 */
#if !defined(_WIN32) && !defined(_POSIX_C_SOURCE)
#define _POSIX_C_SOURCE 199309L /* clock_gettime under -std=c99 */
#endif
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#if defined(_WIN32)
#include <windows.h>
#else
#include <time.h>
#endif

#include "sblsim_runtime.h"

#if defined(_WIN32)
#define SBLSIM_EXPORT __declspec(dllexport)
#else
#define SBLSIM_EXPORT __attribute__((visibility("default")))
#endif

/* Generated: the models compiled into this library. */
extern const sblsim_model* const sblsim_models[];

typedef struct {
    const sblsim_model* m;
    int B, R;
    int* row_of; /* each replicate's parameter row */
    double* vectors[SBLSIM_VECTOR_DRAWS]; /* every vector but the draw counters (numbered last) */
    uint64_t* draws;
    sblsim_instance* instances;
    sblsim_work* work;
    char message[SBLSIM_MESSAGE];
} sblsim_batch;

static int is_row_vector(int which) { return which == SBLSIM_VECTOR_P || which == SBLSIM_VECTOR_D; }

static int length(const sblsim_model* m, int which) {
    switch (which) {
        case SBLSIM_VECTOR_P: return m->n_p;
        case SBLSIM_VECTOR_D: return m->n_d;
        case SBLSIM_VECTOR_X: return m->n_x;
        case SBLSIM_VECTOR_U: return m->n_u;
        case SBLSIM_VECTOR_Y: return m->n_y;
        case SBLSIM_VECTOR_X_NEXT: return m->n_x;
        default: return m->n_purposes;
    }
}

SBLSIM_EXPORT const sblsim_model* sblsim_find_model(const char* name) {
    int k;
    for (k = 0; sblsim_models[k] != NULL; k++)
        if (strcmp(sblsim_models[k]->name, name) == 0) return sblsim_models[k];
    return NULL;
}

/* Length per replicate of vector `which` (SBLSIM_VECTOR_*); -1: no such model. */
SBLSIM_EXPORT int sblsim_model_size(const char* name, int which) {
    const sblsim_model* m = sblsim_find_model(name);
    return m == NULL ? -1 : length(m, which);
}

SBLSIM_EXPORT void sblsim_batch_free(sblsim_batch* b) {
    int k;
    if (b == NULL) return;
    for (k = 0; k < SBLSIM_VECTOR_DRAWS; k++) free(b->vectors[k]);
    free(b->draws);
    free(b->row_of);
    free(b->instances);
    sblsim_work_free(b->work);
    free(b);
}

/* B replicates of model `name` with R parameter rows (1 <= R <= B); replicate i uses row i % R until
   sblsim_batch_rows says otherwise. NULL: no such model, a bad count, or out of memory. */
SBLSIM_EXPORT sblsim_batch* sblsim_batch_new(const char* name, int B, int R) {
    const sblsim_model* m = sblsim_find_model(name);
    sblsim_batch* b;
    int k, i;
    if (m == NULL || B < 1 || R < 1 || R > B) return NULL;
    b = (sblsim_batch*)calloc(1, sizeof(sblsim_batch));
    if (b == NULL) return NULL;
    b->m = m;
    b->B = B;
    b->R = R;
    for (k = 0; k < SBLSIM_VECTOR_DRAWS; k++) {
        int n = length(m, k);
        b->vectors[k] = (double*)calloc((size_t)(is_row_vector(k) ? R : B) * (size_t)(n > 0 ? n : 1),
                                        sizeof(double));
        if (b->vectors[k] == NULL) goto failed;
    }
    b->draws = (uint64_t*)calloc((size_t)B * (size_t)(m->n_purposes > 0 ? m->n_purposes : 1), sizeof(uint64_t));
    b->row_of = (int*)calloc((size_t)B, sizeof(int));
    b->instances = (sblsim_instance*)calloc((size_t)B, sizeof(sblsim_instance));
    b->work = sblsim_work_new(m);
    if (b->draws == NULL || b->row_of == NULL || b->instances == NULL || b->work == NULL) goto failed;
    for (i = 0; i < B; i++) {
        sblsim_instance* s = &b->instances[i];
        s->model = m;
        b->row_of[i] = i % R;
        s->p = b->vectors[SBLSIM_VECTOR_P] + (size_t)(i % R) * m->n_p;
        s->d = b->vectors[SBLSIM_VECTOR_D] + (size_t)(i % R) * m->n_d;
        s->x = b->vectors[SBLSIM_VECTOR_X] + (size_t)i * m->n_x;
        s->u = b->vectors[SBLSIM_VECTOR_U] + (size_t)i * m->n_u;
        s->y = b->vectors[SBLSIM_VECTOR_Y] + (size_t)i * m->n_y;
        s->x_next = b->vectors[SBLSIM_VECTOR_X_NEXT] + (size_t)i * m->n_x;
        s->draws = b->draws + (size_t)i * m->n_purposes;
        s->work = b->work;
    }
    for (i = 0; i < R; i++) memcpy(b->instances[i].p, m->p_start, sizeof(double) * (size_t)m->n_p);
    for (i = 0; i < B; i++) memcpy(b->instances[i].u, m->u_start, sizeof(double) * (size_t)m->n_u);
    return b;
failed:
    sblsim_batch_free(b);
    return NULL;
}

/* Replicate i uses parameter row row_of[i] (0 <= row_of[i] < R) and, when `replicate` is not NULL, draws
   its random streams as replicate replicate[i] (else as its row's `replicate` parameter). 0 on success, else
   1 + the first replicate whose row is out of range. */
SBLSIM_EXPORT int sblsim_batch_rows(sblsim_batch* b, const int* row_of, const long long* replicate) {
    int i;
    for (i = 0; i < b->B; i++)
        if (row_of[i] < 0 || row_of[i] >= b->R) {
            snprintf(b->message, sizeof b->message, "parameter row %d of %d rows", row_of[i], b->R);
            return 1 + i;
        }
    for (i = 0; i < b->B; i++) {
        sblsim_instance* s = &b->instances[i];
        b->row_of[i] = row_of[i];
        s->p = b->vectors[SBLSIM_VECTOR_P] + (size_t)row_of[i] * b->m->n_p;
        s->d = b->vectors[SBLSIM_VECTOR_D] + (size_t)row_of[i] * b->m->n_d;
        s->own_replicate = replicate != NULL;
        s->replicate = replicate != NULL ? (uint64_t)replicate[i] : 0;
    }
    return 0;
}

/* The batch's vector `which`: p or d (R rows), u or y (B rows), each row of length sblsim_model_size (the
   states swap while stepping: sblsim_batch_states copies them). */
SBLSIM_EXPORT double* sblsim_batch_vector(sblsim_batch* b, int which) {
    return (which == SBLSIM_VECTOR_P || which == SBLSIM_VECTOR_D || which == SBLSIM_VECTOR_U ||
            which == SBLSIM_VECTOR_Y) ? b->vectors[which] : NULL;
}

/* Copy the current states (B x n_x) into `out` (the state buffers swap while stepping). */
SBLSIM_EXPORT void sblsim_batch_states(sblsim_batch* b, double* out) {
    int i;
    for (i = 0; i < b->B; i++)
        memcpy(out + (size_t)i * b->m->n_x, b->instances[i].x, sizeof(double) * (size_t)b->m->n_x);
}

SBLSIM_EXPORT const char* sblsim_batch_message(sblsim_batch* b) { return b->message; }

/* Check every parameter row, then prepare each row once, and init and output every replicate at t0. 0 on
   success, else 1 + the index of the first failing replicate (the message names the parameter). */
SBLSIM_EXPORT int sblsim_batch_initialize(sblsim_batch* b, double t0) {
    int i, status = 0;
    char* seen = (char*)calloc((size_t)b->R, 1); /* rows checked, then rows prepared */
    if (seen == NULL) {
        snprintf(b->message, sizeof b->message, "out of memory");
        return 1;
    }
    for (i = 0; i < b->B && !status; i++) {
        if (seen[b->row_of[i]]) continue;
        seen[b->row_of[i]] = 1;
        if (sblsim_check_parameters(b->m, b->instances[i].p, b->message, sizeof b->message)) status = 1 + i;
    }
    memset(seen, 0, (size_t)b->R);
    for (i = 0; i < b->B && !status; i++) {
        int prepare = !seen[b->row_of[i]];
        seen[b->row_of[i]] = 1;
        if (sblsim_initialize_shared(&b->instances[i], t0, prepare, b->message, sizeof b->message)) status = 1 + i;
    }
    free(seen);
    return status;
}

/* One step of every replicate; before each, *cancel (when not NULL) is read: set, the steps stop there and -1 is
   returned (the batch is then half-stepped: a run that is abandoned). 0 on success, else 1 + the failing
   replicate. */
static int batch_steps(sblsim_batch* b, double t, double h, const volatile int* cancel) {
    int i;
    for (i = 0; i < b->B; i++) {
        if (cancel != NULL && *cancel) return -1;
        if (sblsim_do_step(&b->instances[i], t, h, b->message, sizeof b->message)) return 1 + i;
    }
    return 0;
}

SBLSIM_EXPORT int sblsim_batch_do_step(sblsim_batch* b, double t, double h) { return batch_steps(b, t, h, NULL); }

/* The random streams, for the tests that pin them against numpy's Philox. */
SBLSIM_EXPORT void sblsim_stream_uniforms(const uint64_t keys[4], int component, int purpose, uint64_t draw,
                                          int count, double* out) {
    sblsim_uniforms(keys, component, purpose, draw, count, out);
}

SBLSIM_EXPORT void sblsim_stream_normals(const uint64_t keys[4], int component, int purpose, uint64_t draw,
                                         int count, double* out) {
    sblsim_normals(keys, component, purpose, draw, count, out);
}

/* Seconds on a monotonic clock (for the per-component timing of sblsim_system_run). */
static double now(void) {
#if defined(_WIN32)
    LARGE_INTEGER count, frequency;
    QueryPerformanceCounter(&count);
    QueryPerformanceFrequency(&frequency);
    return (double)count.QuadPart / (double)frequency.QuadPart;
#else
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#endif
}

static void feed(sblsim_batch** batches, int c, const int* link_offsets, const int* link_src, const int* link_out,
                 const int* link_in) {
    sblsim_batch* dst = batches[c];
    int i, k, n_u = dst->m->n_u, first = link_offsets[c], n = link_offsets[c + 1] - link_offsets[c];
    if (n <= 0) return;
    {
        /* each run of links that copy consecutive outputs of one source to consecutive inputs (the lanes of a
           delivery: one block), its first source output (replicate 0), the stride between replicates, its first
           input and its length, found once */
        const double* from[n];
        size_t stride[n];
        int to[n], length[n], runs = 0, r;
        for (k = 0; k < n; k += length[runs++]) {
            const sblsim_batch* src = batches[link_src[first + k]];
            from[runs] = src->vectors[SBLSIM_VECTOR_Y] + link_out[first + k];
            stride[runs] = (size_t)src->m->n_y;
            to[runs] = link_in[first + k];
            length[runs] = 1;
            while (k + length[runs] < n && link_src[first + k + length[runs]] == link_src[first + k] &&
                   link_out[first + k + length[runs]] == link_out[first + k] + length[runs] &&
                   link_in[first + k + length[runs]] == link_in[first + k] + length[runs])
                length[runs]++;
        }
        for (i = 0; i < dst->B; i++) { /* replicate by replicate: each touches a few cache lines */
            double* u = dst->vectors[SBLSIM_VECTOR_U] + (size_t)i * n_u;
            for (r = 0; r < runs; r++) {
                if (length[r] == 1)
                    u[to[r]] = from[r][(size_t)i * stride[r]];
                else
                    memcpy(u + to[r], from[r] + (size_t)i * stride[r], sizeof(double) * (size_t)length[r]);
            }
        }
    }
}

/* The master loop of the local engine in C (orchestrator/master.py, simulate, is the reference: the same
   operations in the same order). `batches` in execution order, all with B replicates; the links of component c
   (source component, its output index, c's input index) are link_offsets[c] .. link_offsets[c + 1] - 1.
   Macro steps k0 .. k0 + n_steps - 1 of size T from t0; component c takes rates[c] communication steps per macro
   step. After each macro step the outputs (rec_comp[j], rec_out[j]) go to record[(k - k0) x n_record x B].
   timing[c] accumulates the seconds of c's steps. 0 on success, -1 when *cancel was set (by another thread:
   read before every replicate's step, so that a run of minutes stops within one), else 1 + the failing
   component's index (its batch message says why, `failed_replicate` which replicate). */
SBLSIM_EXPORT int sblsim_system_run(int n, sblsim_batch** batches, const int* rates, const int* link_offsets,
                                    const int* link_src, const int* link_out, const int* link_in, int n_record,
                                    const int* rec_comp, const int* rec_out, double* record, double t0, double T,
                                    int k0, int n_steps, int jacobi, double* timing, int* failed_replicate,
                                    const volatile int* cancel) {
    int k, c, j, i;
    int B = batches[0]->B;
    for (k = k0; k < k0 + n_steps; k++) {
        double t = t0 + k * T;
        if (jacobi)
            for (c = 0; c < n; c++) feed(batches, c, link_offsets, link_src, link_out, link_in);
        for (c = 0; c < n; c++) {
            double sub = T / rates[c], start;
            if (!jacobi) feed(batches, c, link_offsets, link_src, link_out, link_in);
            start = now();
            for (j = 0; j < rates[c]; j++) {
                int status = batch_steps(batches[c], t + j * sub, sub, cancel);
                if (status < 0) return -1;
                if (status) {
                    *failed_replicate = status - 1;
                    return 1 + c;
                }
            }
            timing[c] += now() - start;
        }
        {
            double* step = record + (size_t)(k - k0) * (size_t)n_record * (size_t)B; /* record[k - k0][j][i] */
            for (i = 0; i < B; i++) /* replicate by replicate: reads one output row, writes n_record cache lines */
                for (j = 0; j < n_record; j++) {
                    const sblsim_batch* b = batches[rec_comp[j]];
                    const double* y = b->vectors[SBLSIM_VECTOR_Y];
                    step[(size_t)j * (size_t)B + (size_t)i] = y[(size_t)i * b->m->n_y + rec_out[j]];
                }
        }
    }
    return 0;
}

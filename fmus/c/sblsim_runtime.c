/* sblsim runtime: see sblsim_runtime.h. */
#include "sblsim_runtime.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ---------------------------------------------------------------------------------------- */
/* Philox-4x64-10 (Salmon, Moraes, Dror, Shaw, SC'11), as numpy.random.Philox.              */

static void mulhilo64(uint64_t a, uint64_t b, uint64_t* hi, uint64_t* lo) {
#if defined(__SIZEOF_INT128__)
    unsigned __int128 product = (unsigned __int128)a * b; /* one instruction on 64-bit targets */
    *lo = (uint64_t)product;
    *hi = (uint64_t)(product >> 64);
#else
    /* portable 64 x 64 -> 128-bit product from 32-bit halves */
    uint64_t a0 = a & 0xffffffffu, a1 = a >> 32, b0 = b & 0xffffffffu, b1 = b >> 32;
    uint64_t p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
    uint64_t middle = (p00 >> 32) + (p01 & 0xffffffffu) + (p10 & 0xffffffffu);
    *lo = (middle << 32) | (p00 & 0xffffffffu);
    *hi = p11 + (p01 >> 32) + (p10 >> 32) + (middle >> 32);
#endif
}

void sblsim_philox4x64_10(const uint64_t counter[4], const uint64_t key[2], uint64_t out[4]) {
    const uint64_t M0 = 0xD2E7470EE14C6C93ULL, M1 = 0xCA5A826395121157ULL;
    const uint64_t W0 = 0x9E3779B97F4A7C15ULL, W1 = 0xBB67AE8584CAA73BULL;
    uint64_t c0 = counter[0], c1 = counter[1], c2 = counter[2], c3 = counter[3];
    uint64_t k0 = key[0], k1 = key[1];
    int round;
    for (round = 0; round < 10; round++) {
        uint64_t hi0, lo0, hi1, lo1;
        if (round > 0) {
            k0 += W0;
            k1 += W1;
        }
        mulhilo64(M0, c0, &hi0, &lo0);
        mulhilo64(M1, c2, &hi1, &lo1);
        c0 = hi1 ^ c1 ^ k0;
        c1 = lo1;
        c2 = hi0 ^ c3 ^ k1;
        c3 = lo0;
    }
    out[0] = c0;
    out[1] = c1;
    out[2] = c2;
    out[3] = c3;
}

/* The four 64-bit words of block `block` of draw `draw` of a stream.
   keys: seed, scenario_key, cell, replicate; key (seed, scenario_key 2^32 + component 2^16 + purpose),
   counter (block, draw, cell, replicate). */
static void stream_block(const uint64_t keys[4], int component, int purpose, uint64_t draw, uint64_t block,
                         uint64_t words[4]) {
    uint64_t key[2], counter[4];
    key[0] = keys[0];
    key[1] = (keys[1] << 32) | ((uint64_t)component << 16) | (uint64_t)purpose;
    counter[0] = block;
    counter[1] = draw;
    counter[2] = keys[2];
    counter[3] = keys[3];
    sblsim_philox4x64_10(counter, key, words);
}

static double uniform(uint64_t word) { return (double)(word >> 11) * (1.0 / 9007199254740992.0); }

void sblsim_uniforms(const uint64_t keys[4], int component, int purpose, uint64_t draw, int count, double* out) {
    uint64_t words[4];
    int i;
    for (i = 0; i < count; i++) {
        if (i % 4 == 0) stream_block(keys, component, purpose, draw, (uint64_t)(i / 4), words);
        out[i] = uniform(words[i % 4]);
    }
}

void sblsim_normals(const uint64_t keys[4], int component, int purpose, uint64_t draw, int count, double* out) {
    /* normal i from uniforms 2i and 2i + 1 of the draw, which lie in the same block of four */
    uint64_t words[4];
    int i;
    for (i = 0; i < count; i++) {
        int j = 2 * i;
        if (j % 4 == 0) stream_block(keys, component, purpose, draw, (uint64_t)(j / 4), words);
        out[i] = sqrt(-2.0 * log(1.0 - uniform(words[j % 4]))) * cos(2.0 * M_PI * uniform(words[j % 4 + 1]));
    }
}

/* ---------------------------------------------------------------------------------------- */
/* Work space                                                                               */

static void grow(sblsim_work_fn work, casadi_int* arg, casadi_int* res, casadi_int* iw, casadi_int* w) {
    casadi_int a = 0, r = 0, i = 0, f = 0;
    if (work == NULL) return;
    work(&a, &r, &i, &f);
    if (a > *arg) *arg = a;
    if (r > *res) *res = r;
    if (i > *iw) *iw = i;
    if (f > *w) *w = f;
}

static int noise_width(const sblsim_function* f) {
    int k, total = 0;
    for (k = 0; k < f->n_streams; k++) total += f->streams[k].width;
    return total;
}

sblsim_work* sblsim_work_new(const sblsim_model* m) {
    casadi_int arg = 8, res = 2, iw = 1, w = 1;
    int k, noise = 1;
    const sblsim_function* fs[4];
    sblsim_work* out;
    fs[0] = &m->prepare;
    fs[1] = &m->init;
    fs[2] = &m->step;
    fs[3] = &m->output;
    for (k = 0; k < 4; k++) {
        grow(fs[k]->work, &arg, &res, &iw, &w);
        if (noise_width(fs[k]) > noise) noise = noise_width(fs[k]);
    }
    for (k = 0; k < m->n_events; k++) {
        grow(m->events[k].guard_work, &arg, &res, &iw, &w);
        grow(m->events[k].handler.work, &arg, &res, &iw, &w);
        if (noise_width(&m->events[k].handler) > noise) noise = noise_width(&m->events[k].handler);
    }
    out = (sblsim_work*)calloc(1, sizeof(sblsim_work));
    if (out == NULL) return NULL;
    out->arg = (const double**)calloc((size_t)arg, sizeof(double*));
    out->res = (double**)calloc((size_t)res, sizeof(double*));
    out->iw = (casadi_int*)calloc((size_t)iw, sizeof(casadi_int));
    out->w = (double*)calloc((size_t)w, sizeof(double));
    out->noise = (double*)calloc((size_t)noise, sizeof(double));
    if (!out->arg || !out->res || !out->iw || !out->w || !out->noise) {
        sblsim_work_free(out);
        return NULL;
    }
    return out;
}

void sblsim_work_free(sblsim_work* w) {
    if (w == NULL) return;
    free((void*)w->arg);
    free(w->res);
    free(w->iw);
    free(w->w);
    free(w->noise);
    free(w);
}

/* ---------------------------------------------------------------------------------------- */
/* Parameter checks                                                                         */

static void describe(const sblsim_parameter* q, char* text, size_t size) {
    char lo[32], hi[32];
    int unit = q->unit && q->unit[0] && strcmp(q->unit, "1") != 0; /* "1": no unit to name */
    if (q->type == SBLSIM_BOOLEAN) {
        snprintf(text, size, "true or false");
        return;
    }
    if (q->has_min) snprintf(lo, sizeof lo, "%g", q->min); else snprintf(lo, sizeof lo, "-inf");
    if (q->has_max) snprintf(hi, sizeof hi, "%g", q->max); else snprintf(hi, sizeof hi, "inf");
    snprintf(text, size, "%s%s, %s%s%s%s", (!q->has_min || q->min_exclusive) ? "(" : "[", lo, hi,
             q->has_max ? "]" : ")", unit ? " " : "", unit ? q->unit : "");
}

static int rows_in_use(const sblsim_model* m, const double* p, int table) {
    return (int)p[m->tables[table].rows_index];
}

int sblsim_check_parameters(const sblsim_model* m, const double* p, char* message, size_t size) {
    int k;
    char range[96];
    for (k = 0; k < m->n_p; k++) {
        const sblsim_parameter* q = &m->parameters[k];
        double v = p[k];
        int bad;
        if (q->table >= 0 && q->row > rows_in_use(m, p, q->table)) continue; /* a row not in use */
        bad = !isfinite(v);
        if (!bad && q->type == SBLSIM_INTEGER) bad = (v != floor(v));
        if (!bad && q->has_min) bad = q->min_exclusive ? !(v > q->min) : !(v >= q->min);
        if (!bad && q->has_max) bad = !(v <= q->max);
        if (bad) {
            describe(q, range, sizeof range);
            snprintf(message, size, "%s: %.17g is outside the allowed range %s", q->name, v, range);
            return -1;
        }
    }
    for (k = 0; k < m->n_tables; k++) {
        const sblsim_table* tab = &m->tables[k];
        int n = rows_in_use(m, p, k), r;
        const char* name = m->parameters[tab->rows_index].name;
        if (tab->when_index < 0 || p[tab->when_index] == tab->when_value) {
            if (n < tab->min_rows) {
                snprintf(message, size, "%s: %d rows in use; this setting needs at least %d", name, n, tab->min_rows);
                return -1;
            }
        }
        if (tab->increasing) {
            for (r = 1; r < n; r++) {
                if (!(p[tab->first_index + r] > p[tab->first_index + r - 1])) {
                    snprintf(message, size, "%s: must be greater than row %d (%.17g)",
                             m->parameters[tab->first_index + r].name, r, p[tab->first_index + r - 1]);
                    return -1;
                }
            }
        }
    }
    return 0;
}

/* ---------------------------------------------------------------------------------------- */
/* Stepping                                                                                 */

static uint64_t key_of(const sblsim_instance* s, int k) {
    int index = s->model->seed_index[k];
    if (k == SBLSIM_SEED_REPLICATE && s->own_replicate) return index < 0 ? 0 : s->replicate;
    return index < 0 ? 0 : (uint64_t)s->p[index];
}

static const double* draw(sblsim_instance* s, const sblsim_function* f) {
    uint64_t keys[4];
    double* noise = s->work->noise;
    int k, offset = 0;
    if (f->n_streams == 0) return noise; /* a function without random numbers reads none */
    for (k = 0; k < 4; k++) keys[k] = key_of(s, k);
    for (k = 0; k < f->n_streams; k++) {
        const sblsim_stream* st = &f->streams[k];
        uint64_t n;
        if (st->when_index >= 0 && s->p[st->when_index] != st->when_value) {
            memset(noise + offset, 0, sizeof(double) * (size_t)st->width);
            offset += st->width;
            continue;
        }
        n = s->draws[st->slot]++;
        if (st->kind == SBLSIM_UNIFORM)
            sblsim_uniforms(keys, s->model->component, st->purpose, n, st->width, noise + offset);
        else
            sblsim_normals(keys, s->model->component, st->purpose, n, st->width, noise + offset);
        offset += st->width;
    }
    return noise;
}

static int call(sblsim_instance* s, sblsim_fn f, double* result) {
    s->work->res[0] = result;
    return f(s->work->arg, s->work->res, s->work->iw, s->work->w, 0);
}

static void swap_state(sblsim_instance* s) {
    double* tmp = s->x;
    s->x = s->x_next;
    s->x_next = tmp;
}

static int output(sblsim_instance* s, double t) {
    const double** a = s->work->arg;
    a[0] = s->x;
    a[1] = s->p;
    a[2] = s->d;
    a[3] = &t;
    return call(s, s->model->output.f, s->y);
}

int sblsim_output_at(const sblsim_model* m, const double* x, const double* p, const double* d, double t, double* y) {
    sblsim_work* w = sblsim_work_new(m);
    int failed;
    if (w == NULL) return -1;
    w->arg[0] = x;
    w->arg[1] = p;
    w->arg[2] = d;
    w->arg[3] = &t;
    w->res[0] = y;
    failed = m->output.f(w->arg, w->res, w->iw, w->w, 0) ? -1 : 0;
    sblsim_work_free(w);
    return failed;
}

/* Whether event e runs in this run: for each of its conditions, the choice parameter's bit in its mask. */
static int event_runs(const sblsim_instance* s, const sblsim_event* e) {
    int c;
    for (c = 0; c < e->n_when; c++) {
        double choice = s->p[e->when_index[c]];
        if (!(choice >= 0.0 && choice < 64.0) || !((e->when_mask[c] >> (int)choice) & 1u)) return 0;
    }
    return 1;
}

void sblsim_choose_events(sblsim_instance* s) {
    int k;
    s->events_on = 0;
    for (k = 0; k < s->model->n_events && k < 64; k++)
        if (event_runs(s, &s->model->events[k])) s->events_on |= (uint64_t)1 << k;
}

int sblsim_initialize(sblsim_instance* s, double t0, char* message, size_t size) {
    return sblsim_initialize_shared(s, t0, 1, message, size);
}

int sblsim_initialize_shared(sblsim_instance* s, double t0, int prepare, char* message, size_t size) {
    const sblsim_model* m = s->model;
    const double** a = s->work->arg;
    int k;
    for (k = 0; k < m->n_purposes; k++) s->draws[k] = 0;
    sblsim_choose_events(s);
    a[0] = s->p;
    if (prepare && call(s, m->prepare.f, s->d)) goto failed;
    a[0] = s->p;
    a[1] = s->d;
    a[2] = draw(s, &m->init);
    a[3] = &t0;
    if (call(s, m->init.f, s->x)) goto failed;
    s->t0 = t0;
    s->t = t0;
    if (output(s, t0)) goto failed;
    return 0;
failed:
    snprintf(message, size, "%s: a generated function failed during initialization", m->name);
    return -1;
}

/* Most times a guard may fire in one step (a safeguard against a model error). */
#define SBLSIM_MAX_EVENTS 100000000L

int sblsim_do_step(sblsim_instance* s, double t, double h, char* message, size_t size) {
    const sblsim_model* m = s->model;
    const double** a = s->work->arg;
    double g;
    int k;
    if (m->step.f != NULL) {
        a[0] = s->x;
        a[1] = s->u;
        a[2] = s->p;
        a[3] = s->d;
        a[4] = draw(s, &m->step);
        a[5] = &t;
        a[6] = &h;
        if (call(s, m->step.f, s->x_next)) goto failed;
        swap_state(s);
    }
    /* x, u, p, d are the first arguments of every guard and handler (a generated function uses the arguments
       after its own as work space, never its own) */
    a[1] = s->u;
    a[2] = s->p;
    a[3] = s->d;
    for (k = 0; k < m->n_events; k++) {
        const sblsim_event* e = &m->events[k];
        long fired = 0;
        int c;
        if (!(k < 64 ? (s->events_on >> k) & 1u : event_runs(s, e))) continue; /* not this run's */
        for (;;) {
            a[0] = s->x;
            a[4] = &t;
            a[5] = &h;
            if (call(s, e->guard, &g)) goto failed;
            if (!(g > 0.5)) break;
            if (++fired > SBLSIM_MAX_EVENTS) {
                snprintf(message, size, "%s: event %s fired more than %ld times in one step", m->name, e->name,
                         SBLSIM_MAX_EVENTS);
                return -1;
            }
            a[0] = s->x;
            a[4] = draw(s, &e->handler);
            a[5] = &t;
            a[6] = &h;
            if (call(s, e->handler.f, s->x_next)) goto failed;
            if (e->n_writes < 0)
                swap_state(s); /* every state */
            else
                for (c = 0; c < e->n_writes; c++) s->x[e->writes[c]] = s->x_next[c]; /* these alone */
        }
    }
    s->t = t + h;
    if (output(s, t + h)) goto failed;
    return 0;
failed:
    snprintf(message, size, "%s: a generated function failed at t = %g s", m->name, t);
    return -1;
}

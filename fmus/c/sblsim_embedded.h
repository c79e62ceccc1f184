/* sblsim embedded API: run one generated component (e.g. the receiver on a diver's computer)
 * from plain C. No FMI, no Python, no allocation after sblsim_new.
 *
 *   sblsim_handle* r = sblsim_new(&sblsim_receiver_model);
 *   sblsim_set(r, "x0_y", -15.0);                // parameters by name, before sblsim_start
 *   sblsim_start(r, 0.0);                        // checks every parameter, initializes at t0 [s]
 *   sblsim_set(r, "range", 15.6); ...            // inputs by name, before each step
 *   sblsim_step(r, t, h);                        // one step from t to t + h [s]
 *   double x = sblsim_get(r, "est_x");           // outputs (or any variable) by name
 *   sblsim_free(r);
 *
 * Every function returning int returns 0 on success; sblsim_error() says what went wrong.
 */
#ifndef SBLSIM_EMBEDDED_H
#define SBLSIM_EMBEDDED_H

#include "sblsim_runtime.h"

typedef struct sblsim_handle sblsim_handle;

sblsim_handle* sblsim_new(const sblsim_model* model);
int sblsim_set(sblsim_handle* h, const char* name, double value);
double sblsim_get(const sblsim_handle* h, const char* name);
int sblsim_start(sblsim_handle* h, double t0);
int sblsim_step(sblsim_handle* h, double t, double step);
const char* sblsim_error(const sblsim_handle* h);
void sblsim_free(sblsim_handle* h);

#endif

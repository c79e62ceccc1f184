/* sblsim FMU state: the instance state of an FMU shell, whatever its FMI version (fmi2_shell.c, fmi3_shell.c).
 *
 * A saved state is a flat copy of an instance (sblsim_runtime.h): its shell's state number, the times and
 * every vector, p, d, x, u, y in that order, and the draw counters. The shells keep their FMI functions and
 * state machines; an instance's vectors (allocated, reset, freed, a variable's place among them) and what a state
 * holds, how it is saved, restored, serialized and checked are here, once.
 *
 *   sblsim_saved* saved = sblsim_saved_new(m);                         // fmiXGetFMUstate
 *   sblsim_save(&instance->run, state, start_time, saved);
 *   sblsim_restore(&instance->run, instance->x, instance->x_next, saved);  // fmiXSetFMUstate, then the shell
 *   state = saved->state; start_time = saved->start_time;              // takes its own state and start time
 *
 * Serialized layout: magic, value count, purposes, state number, then start_time, t0, t, the values and the
 * draw counters, all as 8-byte words in the machine's byte order. The magic tells the shells apart ("SBLSIM02"
 * for FMI 2.0, "SBLSIM03" for FMI 3.0).
 */
#ifndef SBLSIM_FMU_STATE_H
#define SBLSIM_FMU_STATE_H

#include <stddef.h>
#include <stdint.h>

#include "sblsim_runtime.h"

/* An FMU instance's vectors live in its sblsim_instance `run` (p, d, u, y, the draw counters, the work space) and
   in the two state buffers it owns, x and x_next, between which run->x and run->x_next swap while stepping.
   sblsim_vectors_new allocates them for model m (0; -1 when memory runs out, whatever was allocated left for
   sblsim_vectors_free), sblsim_vectors_reset sets the defaults (the start values of p and u, zeros elsewhere,
   run->x = x, time 0), sblsim_vectors_free frees them (any of them NULL). */
int sblsim_vectors_new(sblsim_instance* run, const sblsim_model* m, double** x, double** x_next);
void sblsim_vectors_reset(sblsim_instance* run, double* x, double* x_next);
void sblsim_vectors_free(sblsim_instance* run, double* x, double* x_next);

/* Where a variable's value is kept: run->p, run->u or run->y at its index, by its causality. */
double* sblsim_slot(sblsim_instance* run, const sblsim_variable* v);

/* What a saved FMU state holds (a flat copy). */
typedef struct {
    int state; /* the shell's own state number */
    double start_time, t0, t;
    double* values; /* p, d, x, u, y */
    uint64_t* draws;
} sblsim_saved;

/* A message buffer big enough for sblsim_deserialize (a runtime message and what it adds). */
#define SBLSIM_STATE_MESSAGE (SBLSIM_MESSAGE + 64)

/* A saved state for model m, zeroed (NULL on allocation failure); sblsim_saved_free(NULL) does nothing. */
sblsim_saved* sblsim_saved_new(const sblsim_model* m);
void sblsim_saved_free(sblsim_saved* s);

/* Copies the instance (its current state run->x: x and x_next swap while stepping) and the shell's state
   number and start time into `to`. */
void sblsim_save(const sblsim_instance* run, int state, double start_time, sblsim_saved* to);

/* Copies `from` back into the instance, its state into x (run->x and run->x_next are reset to the instance's
   buffers x and x_next), and chooses the events of its parameters (sblsim_choose_events). The shell then
   takes its own state number and start time from `from`. */
void sblsim_restore(sblsim_instance* run, double* x, double* x_next, const sblsim_saved* from);

/* The size in bytes of a serialized state of model m. */
size_t sblsim_serialized_size(const sblsim_model* m);

/* Writes `saved` into `bytes` (sblsim_serialized_size bytes at least), headed by `magic`. */
void sblsim_serialize(const sblsim_model* m, uint64_t magic, const sblsim_saved* saved, void* bytes);

/* Reads a serialized state and checks it before it is taken: `size` bytes, the magic, value count and
   purposes of model m, a state number below n_states (at most 32), times finite and ordered, every value
   finite (naming the variable), the inputs within their declared ranges and, when its state number is one of
   `past_init_states` (a bit set over the shell's state numbers), the parameters (sblsim_check_parameters)
   and t0 not before the start time. In such a state an output may be NaN exactly where the model's output
   function, at the state's own x, p, d and t, gives NaN (an undefined output: a receiver's estimate before its
   first fix); a NaN output where it gives a value is refused. 0 if it is taken, copied into `into` (which may be freshly allocated
   by the caller); else -1 with a message (the shell prefixes its function name), `into` left as it was.
   `message` takes SBLSIM_STATE_MESSAGE bytes for the whole message. */
int sblsim_deserialize(const sblsim_model* m, uint64_t magic, int n_states, unsigned past_init_states,
                       const void* bytes, size_t size, sblsim_saved* into, char* message, size_t message_size);

/* The declared range of a variable as text, e.g. "[0, 1e+07] m". */
void sblsim_describe_range(const sblsim_variable* v, char* text, size_t size);

/* Whether `value` lies in the declared range of `v` (a variable without one takes any value). */
int sblsim_in_range(const sblsim_variable* v, double value);

#endif

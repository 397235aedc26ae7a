/* What the FMI glue (fmi2Functions.c) needs from a model, and nothing of FMI beyond value references.
 *
 * The glue owns the FMI side: instances, callbacks and logging, the order of calls (instantiated,
 * initialization mode, stepping, terminated), argument checks, and FMU state objects (their header,
 * identity check and serialization). The model owns its variables and its physics: it reads and writes
 * values by value reference, applies parameters at the end of initialization, steps, and saves and
 * restores its state as plain bytes. linknet_model.c is the only model; the glue never names it.
 *
 * Every function that can fail returns an fmu_result and, when it is not FMU_OK, writes one line saying
 * why (naming the variable and the rule) into msg, a buffer of FMU_MESSAGE bytes.
 */
#ifndef LINKNET_FMU_MODEL_H
#define LINKNET_FMU_MODEL_H

#include <stddef.h>
#include <stdint.h>

#include "fmu_resource.h"

#define FMU_MESSAGE 2048

enum fmu_result {
    FMU_OK = 0,
    FMU_WARNING = 1,    /* done, with something worth saying in msg */
    FMU_DISCARD = 2,    /* the step could not be completed; nothing changed */
    FMU_ERROR = 3,      /* refused (bad argument or value); nothing changed */
    FMU_NOTE = 4,       /* done, as asked (the call returns fmi2OK), with information in msg that the host must see
                           although nothing went wrong: logged with fmi2Warning status in the category
                           LINKNET_NOTE_CATEGORY (fmi2_api.h),
                           logging on or not (the model's error estimate exceeded the run's goal) */
    FMU_DISCARD_FINAL = 5 /* as FMU_DISCARD, and no retry of this step from this state with these inputs can
                           succeed, however short the step is made; msg says why. The glue answers fmi2Discard and
                           reports fmi2Terminated (the master should stop) */
};

typedef struct fmu_model fmu_model;

typedef struct fmu_model_info {
    const char *model_identifier;
    const char *guid;
    uint64_t fingerprint;       /* identity of the model's build: a state carries it and is refused by others */
    unsigned n_real;            /* Real variables have value references 0 .. n_real - 1 */
    unsigned n_string;          /* String variables follow: n_real .. n_real + n_string - 1 */
    unsigned n_boolean;         /* then Boolean variables: n_real + n_string .. */
    int events;                 /* the model has events to log (a scene with ropes): fmu_model_event */
} fmu_model_info;

/* The model's identity and sizes (read from its resource). */
const fmu_model_info *fmu_model_info_get(const fmu_model *m);

/* A new model of the scene in the resource r (fmu_resource.h), at its start values, or NULL with the reason in msg.
   The model points into r, which must outlive it. */
fmu_model *fmu_model_new(const fmu_resource *r, char *msg);
void fmu_model_free(fmu_model *m);
/* Back to the start values and the initial state (fmi2Reset). */
int fmu_model_reset(fmu_model *m, char *msg);
/* The time the initial state is given at (fmi2SetupExperiment). */
int fmu_model_set_start_time(fmu_model *m, double start_time, char *msg);

/* `initialized`: initialization has ended (parameters are fixed from then on). */
int fmu_model_get_real(fmu_model *m, const unsigned *vr, size_t n, double *value, int initialized, char *msg);
int fmu_model_set_real(fmu_model *m, const unsigned *vr, size_t n, const double *value, int initialized, char *msg);
/* fmi2SetRealInputDerivatives: derivative of order order[i] of input vr[i]. Inputs the model holds constant over
   a step take them with FMU_WARNING (ignored, said in msg); a refused one (an order the model does not take, not
   an input, a non-finite value) is FMU_ERROR and nothing is set. */
int fmu_model_set_real_input_derivatives(fmu_model *m, const unsigned *vr, size_t n, const int *order,
                                         const double *value, int initialized, char *msg);
/* fmi2GetDirectionalDerivative at the current state with the inputs as set (after initialization): the derivatives
   of the outputs unknown[0..n_unknown) along the seed seed[i] on the inputs known[i], into derivative. A reference
   that is not an output (unknown) or an input (known), or a seed that is not finite, is FMU_ERROR naming it, and
   nothing is written. */
int fmu_model_directional_derivative(fmu_model *m, const unsigned *unknown, size_t n_unknown, const unsigned *known,
                                     size_t n_known, const double *seed, double *derivative, char *msg);
int fmu_model_get_string(fmu_model *m, const unsigned *vr, size_t n, const char **value, char *msg);
int fmu_model_set_string(fmu_model *m, const unsigned *vr, size_t n, const char *const *value, int initialized,
                         char *msg);
/* Booleans as 0 / 1 (fmi2Boolean is an int; any non-zero value set is true). */
int fmu_model_get_boolean(fmu_model *m, const unsigned *vr, size_t n, int *value, char *msg);
int fmu_model_set_boolean(fmu_model *m, const unsigned *vr, size_t n, const int *value, int initialized, char *msg);

/* End of initialization: the parameters set so far take effect. */
int fmu_model_initialize(fmu_model *m, char *msg);
/* One communication step from t to t + h with the inputs held. All or nothing (FMU_NOTE: done, with a note;
   FMU_DISCARD: not done, a shorter step may succeed; FMU_DISCARD_FINAL: not done, and no shorter one can). */
int fmu_model_do_step(fmu_model *m, double t, double h, char *msg);
double fmu_model_time(const fmu_model *m);
/* The events of the last successful step (a rope going slack or coming taut), each one line of text for the log,
   and the events beyond what the model keeps per step: i from 0 while it returns 1 (the line in out, n bytes); 0 past
   the last line. Empty before the first step and after a failed step, a reset or a restored state. */
int fmu_model_event(const fmu_model *m, size_t i, char *out, size_t n);

/* The model's whole state as bytes (size fixed per model), and back. restore checks what it reads. */
size_t fmu_model_state_size(const fmu_model *m);
void fmu_model_state_save(const fmu_model *m, unsigned char *buffer);
int fmu_model_state_restore(fmu_model *m, const unsigned char *buffer, size_t size, char *msg);

#endif

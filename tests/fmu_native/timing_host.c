/* The native FMU's cost per communication step over the core's own ln_advance, from C.
 *
 * Compiled together with one FMU's sources/ (the SourceFiles list, same flags as the FMU's binary), so that
 * fmi2DoStep and ln_advance are the same code as in the FMU. One process, two instances of the same model at
 * the same state: an FMI instance (fmi2Instantiate ... fmi2DoStep) and a bare model (fmu_model_new) whose
 * ln_model, ln_method and ln_data are driven with ln_advance directly. Runs of N calls alternate, each from the
 * same saved state; the best of R runs is kept. After each pair of runs the two final states must be equal bit
 * for bit (the same work was timed).
 *
 *   timing_host RESOURCES N H REPEATS STEP INPUT_VR [INPUT_VR ...]
 *
 * RESOURCES: the unzipped FMU's resources folder (an absolute path), where both instances read the scene.
 * H: communication step; STEP: the "step" parameter (H/STEP RATTLE steps per call); the first INPUT_VR gets a
 * new value every call ("one input"), all of them in the "all inputs" runs. Prints one line per figure, in
 * nanoseconds per call.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2_api.h"
#include "fmu_model.h"
#include "linknet.h"
#include "lnfmu_scene.h"

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env, (void)category;
    fprintf(stderr, "[%s] %d %s\n", name, (int)status, message);
}

#define CHECK(x)                                                   \
    do {                                                           \
        if ((x) != 0) {                                            \
            fprintf(stderr, "%s failed at line %d\n", #x, __LINE__); \
            exit(4);                                               \
        }                                                          \
    } while (0)

int main(int argc, char **argv)
{
    if (argc < 7) {
        fprintf(stderr, "usage: %s RESOURCES N H REPEATS STEP INPUT_VR [INPUT_VR ...]\n", argv[0]);
        return 2;
    }
    const char *folder = argv[1];
    const long N = atol(argv[2]);
    const double h = atof(argv[3]);
    const int R = atoi(argv[4]);
    const double step = atof(argv[5]);
    const int n_in = argc - 6;
    fmi2ValueReference *in = malloc((size_t)n_in * sizeof *in);
    for (int j = 0; j < n_in; j++) in[j] = (fmi2ValueReference)atoi(argv[6 + j]);
    char msg[FMU_MESSAGE], location[4200];
    fmu_resource *resource = fmu_resource_load(folder, msg, sizeof msg);
    const lnfmu_scene *s = resource ? lnfmu_scene_load(resource, msg) : NULL;
    if (!s) {
        fprintf(stderr, "%s\n", msg);
        return 4;
    }
    snprintf(location, sizeof location, "file://%s", folder);
    fmi2ValueReference step_vr = 0;
    for (ln_int vr = 0; vr < s->n_real; vr++)
        if (s->variables[vr].kind == LNFMU_STEP) step_vr = (fmi2ValueReference)vr;

    /* the FMI instance */
    const fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("timed", fmi2CoSimulation, s->guid, location, &cb, fmi2False, fmi2False);
    if (!c) return 4;
    CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    CHECK(fmi2EnterInitializationMode(c));
    CHECK(fmi2SetReal(c, &step_vr, 1, &step));
    CHECK(fmi2ExitInitializationMode(c));
    fmi2FMUstate start = NULL;
    CHECK(fmi2GetFMUstate(c, &start));

    /* the bare model, driven with ln_advance */
    fmu_model *m = fmu_model_new(resource, msg);
    if (!m) return 4;
    CHECK(fmu_model_set_real(m, &step_vr, 1, &step, 0, msg));
    CHECK(fmu_model_initialize(m, msg));
    const ln_model *model;
    const ln_method *method;
    ln_data *d;
    lnfmu_core(m, &model, &method, &d);
    unsigned char *saved = malloc(fmu_model_state_size(m));
    fmu_model_state_save(m, saved);
    ln_int *index = malloc((size_t)n_in * sizeof *index);
    for (int j = 0; j < n_in; j++) index[j] = s->variables[in[j]].index;
    const size_t n3 = (size_t)(3 * s->K);
    double *X_fmu = malloc(n3 * sizeof(double)), *X_core = malloc(n3 * sizeof(double));
    double *values = malloc((size_t)(N * (n_in > 0 ? n_in : 1)) * sizeof(double));
    for (long i = 0; i < N; i++)
        for (int j = 0; j < n_in; j++) values[i * n_in + j] = 0.1 * sin(0.37 * (double)i + (double)j);

    enum { CORE_ONE, FMU_ONE, CORE_STEP, FMU_STEP, FMU_SET_ONE, CORE_ALL, FMU_ALL, FMU_SET_ALL, KINDS };
    const char *names[KINDS] = {"core_advance_one_input", "fmu_setreal_dostep_one_input", "core_advance",
                                "fmu_dostep", "fmu_setreal_one", "core_advance_all_inputs",
                                "fmu_setreal_dostep_all_inputs", "fmu_setreal_all"};
    double best[KINDS];
    for (int k = 0; k < KINDS; k++) best[k] = 1e300;
    int identical = 1;
    for (int r = 0; r < R; r++) {
        for (int kind = 0; kind < KINDS; kind++) {
            const int all = kind >= CORE_ALL;
            const int n_set = all ? n_in : (n_in > 0 ? 1 : 0);
            const int core = kind == CORE_ONE || kind == CORE_STEP || kind == CORE_ALL;
            const int set_only = kind == FMU_SET_ONE || kind == FMU_SET_ALL;
            const int no_set = kind == CORE_STEP || kind == FMU_STEP;
            if (core) {
                CHECK(fmu_model_state_restore(m, saved, fmu_model_state_size(m), msg));
            } else {
                CHECK(fmi2SetFMUstate(c, start));
            }
            if (no_set) {  /* inputs set once, before the timed span */
                for (int j = 0; j < n_set; j++) {
                    if (core) d->F_input[index[j]] = values[j];
                    else CHECK(fmi2SetReal(c, &in[j], 1, &values[j]));
                }
            }
            double t = 0.0;
            const double t0 = now();
            if (core) {
                for (long i = 0; i < N; i++) {
                    if (!no_set)
                        for (int j = 0; j < n_set; j++) d->F_input[index[j]] = values[i * n_in + j];
                    if (ln_advance(model, method, d, t + h, s->max_steps) != LN_OK) return 4;
                    t += h;
                }
            } else if (set_only) {
                for (long i = 0; i < N; i++) fmi2SetReal(c, in, (size_t)n_set, &values[i * n_in]);
            } else {
                for (long i = 0; i < N; i++) {
                    if (!no_set) fmi2SetReal(c, in, (size_t)n_set, &values[i * n_in]);
                    if (fmi2DoStep(c, t, h, fmi2True) != fmi2OK) return 4;
                    t += h;
                }
            }
            const double per_call = (now() - t0) / (double)N;
            if (per_call < best[kind]) best[kind] = per_call;
            if (core) memcpy(X_core, d->X, n3 * sizeof(double));
            else if (!set_only) {
                /* the FMU's positions after the run: read through the instance's own outputs is not needed,
                   the FMU state holds them; compare via a second model state */
                fmi2FMUstate end = NULL;
                CHECK(fmi2GetFMUstate(c, &end));
                size_t size = 0;
                CHECK(fmi2SerializedFMUstateSize(c, end, &size));
                fmi2Byte *bytes = malloc(size);
                CHECK(fmi2SerializeFMUstate(c, end, bytes, size));
                /* X follows the header and the model's leading fields: locate it by saving the bare model */
                const size_t model_size = fmu_model_state_size(m);
                const size_t offset = size - model_size;
                const size_t x_at = offset + sizeof(double) * (size_t)(1 + 3 + 2 * s->n_real + 2 + 4);
                memcpy(X_fmu, bytes + x_at, n3 * sizeof(double));
                free(bytes);
                CHECK(fmi2FreeFMUstate(c, &end));
                if (memcmp(X_fmu, X_core, n3 * sizeof(double)) != 0) identical = 0;
            }
        }
    }
    for (int k = 0; k < KINDS; k++) printf("%s %.1f\n", names[k], 1e9 * best[k]);
    printf("identical %d\n", identical);
    CHECK(fmi2FreeFMUstate(c, &start));
    fmi2FreeInstance(c);
    fmu_model_free(m);
    return 0;
}

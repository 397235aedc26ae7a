/* The cost of one fmi2GetDirectionalDerivative against one fmi2DoStep, from a plain C host (no Python in the host,
 * no ctypes): what a C master (OMSimulator's strong coupling, say) pays per Jacobian column.
 *
 *   directional_timing_host FMU_DIR MODEL_ID GUID H N ROUNDS KNOWN_VR UNKNOWN_VR [UNKNOWN_VR ...]
 *
 * Instantiates, initialises with the start values (inputs 0, anchors at rest) and saves the state at t = 0. Each
 * round restarts from that state (untimed) and times
 *   dostep       N consecutive fmi2DoStep(t, H), per call;
 *   first        N times: an untimed fmi2DoStep, then one fmi2GetDirectionalDerivative (seed 1 on KNOWN_VR, the
 *                derivatives of every UNKNOWN_VR), timed alone: the first call at a new state, which prepares the
 *                linearization (the outputs' evaluation and the factorisation of A) before its solve;
 *   next         right after each `first`, the same call again, timed alone: a further column at the same state
 *                (the kept factorisation, one solve);
 * each per call. The minimum over the rounds is reported (other processes only ever add time), as one JSON line in
 * seconds, with the last derivatives (they must be finite: the timed calls did the work).
 *
 * Exit codes: 0 ok, 2 usage, 3 load error, 4 an FMI call failed. Compiled and run by
 * benchmarks/bench_fmu_directional.py (cc -O2 ... -ldl).
 */
#define _POSIX_C_SOURCE 199309L
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef struct {
    void (*logger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef fmi2Component (*Instantiate_t)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                       const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef fmi2Status (*SetupExperiment_t)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
typedef fmi2Status (*Simple_t)(fmi2Component);
typedef fmi2Status (*DoStep_t)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
typedef fmi2Status (*GetFMUstate_t)(fmi2Component, fmi2FMUstate *);
typedef fmi2Status (*SetFMUstate_t)(fmi2Component, fmi2FMUstate);
typedef fmi2Status (*Directional_t)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2ValueReference[],
                                    size_t, const fmi2Real[], fmi2Real[]);

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env, (void)category;
    if (status > fmi2OK) fprintf(stderr, "[%s] %d %s\n", name, (int)status, message);
}

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void *sym(void *lib, const char *name)
{
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "missing symbol %s\n", name);
        exit(3);
    }
    return f;
}

#define CHECK(call)                                                                  \
    do {                                                                             \
        fmi2Status s_ = (call);                                                      \
        if (s_ > fmi2Warning) {                                                      \
            fprintf(stderr, "%s failed with status %d\n", #call, (int)s_);           \
            return 4;                                                                \
        }                                                                            \
    } while (0)

int main(int argc, char **argv)
{
    if (argc < 9) {
        fprintf(stderr, "usage: %s FMU_DIR MODEL_ID GUID H N ROUNDS KNOWN_VR UNKNOWN_VR [UNKNOWN_VR ...]\n", argv[0]);
        return 2;
    }
    const char *dir = argv[1], *id = argv[2], *guid = argv[3];
    const double h = atof(argv[4]);
    const long N = atol(argv[5]), rounds = atol(argv[6]);
    const fmi2ValueReference known = (fmi2ValueReference)strtoul(argv[7], NULL, 10);
    const size_t n_unknown = (size_t)(argc - 8);
    fmi2ValueReference *unknown = malloc(n_unknown * sizeof *unknown);
    fmi2Real *derivative = malloc(n_unknown * sizeof *derivative);
    if (!unknown || !derivative || N < 1 || rounds < 1) return 2;
    for (size_t j = 0; j < n_unknown; j++) unknown[j] = (fmi2ValueReference)strtoul(argv[8 + j], NULL, 10);
    const fmi2Real seed = 1.0;

    char path[4096], uri[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    snprintf(uri, sizeof uri, "file://%s/resources", dir);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen failed: %s\n", dlerror());
        return 3;
    }
    Instantiate_t instantiate = (Instantiate_t)sym(lib, "fmi2Instantiate");
    SetupExperiment_t setup = (SetupExperiment_t)sym(lib, "fmi2SetupExperiment");
    Simple_t enter = (Simple_t)sym(lib, "fmi2EnterInitializationMode");
    Simple_t exit_init = (Simple_t)sym(lib, "fmi2ExitInitializationMode");
    DoStep_t do_step = (DoStep_t)sym(lib, "fmi2DoStep");
    GetFMUstate_t get_state = (GetFMUstate_t)sym(lib, "fmi2GetFMUstate");
    SetFMUstate_t set_state = (SetFMUstate_t)sym(lib, "fmi2SetFMUstate");
    Directional_t directional = (Directional_t)sym(lib, "fmi2GetDirectionalDerivative");

    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("directional_timing_host", fmi2CoSimulation, guid, uri, &cb, 0, 0);
    if (!c) {
        fprintf(stderr, "fmi2Instantiate failed\n");
        return 4;
    }
    CHECK(setup(c, 0, 0.0, 0.0, 0, 0.0));
    CHECK(enter(c));
    CHECK(exit_init(c));
    fmi2FMUstate initial = NULL;
    CHECK(get_state(c, &initial));

    double best[3] = {INFINITY, INFINITY, INFINITY};
    for (long r = 0; r <= rounds; r++) {  /* round 0 untimed: the first calls load and warm up */
        CHECK(set_state(c, initial));
        double t = 0.0;
        const double t0 = now();
        for (long i = 0; i < N; i++, t += h) CHECK(do_step(c, t, h, 1));
        const double dostep = (now() - t0) / (double)N;
        CHECK(set_state(c, initial));
        t = 0.0;
        double first = 0.0, next = 0.0;
        for (long i = 0; i < N; i++, t += h) {
            CHECK(do_step(c, t, h, 1));
            const double a = now();
            CHECK(directional(c, unknown, n_unknown, &known, 1, &seed, derivative));
            const double b = now();
            CHECK(directional(c, unknown, n_unknown, &known, 1, &seed, derivative));
            next += now() - b;
            first += b - a;
        }
        if (r == 0) continue;
        const double per[3] = {dostep, first / (double)N, next / (double)N};
        for (int k = 0; k < 3; k++)
            if (per[k] < best[k]) best[k] = per[k];
    }
    for (size_t j = 0; j < n_unknown; j++)
        if (!isfinite(derivative[j])) {
            fprintf(stderr, "derivative %zu is not finite\n", j);
            return 4;
        }
    printf("{\"dostep_s\": %.6e, \"directional_first_s\": %.6e, \"directional_next_s\": %.6e, \"n_unknown\": %zu, "
           "\"last_derivative_0\": %.17g}\n", best[0], best[1], best[2], n_unknown, derivative[0]);
    fflush(stdout);
    return 0;
}

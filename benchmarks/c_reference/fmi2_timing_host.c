/* FMI 2.0 Co-Simulation timing host in plain C: no Python in the host, no ctypes, no fmpy.
 *
 * Measures what an FMU costs per communication step when a C master drives it (as every FMI
 * toolchain does), so the FMU's own overhead can be told apart from a Python host's marshalling.
 * Loading follows tests/c_host/fmi2_host.c (that file belongs to the tests and is left alone).
 *
 *   fmi2_timing_host FMU_DIR MODEL_ID GUID H N_STEPS REPEATS in:VR=VALUE [in:VR=VALUE ...] [out:VR ...]
 *
 * Instantiates, initialises, saves the FMU state at t = 0 (fmi2GetFMUstate), then for REPEATS rounds
 * times three variants, each over N_STEPS calls, each restarted with fmi2SetFMUstate(initial) outside
 * the timed span:
 *   setreal_dostep  fmi2SetReal(inputs) then fmi2DoStep(t, H), N_STEPS times (what a master does)
 *   dostep          fmi2DoStep(t, H) only, N_STEPS times (inputs set once, untimed, before the span)
 *   setreal         fmi2SetReal(inputs) only, N_STEPS times at t = 0 (no doStep in between)
 * The variants take turns within a round and the round's first variant rotates, so load from other
 * processes hits them alike. One untimed round first (the first doStep imports and loads the kernels).
 * Time is CLOCK_MONOTONIC around the N_STEPS calls. The minimum over the rounds is reported: other
 * processes only ever add time.
 *
 * and, as a diagnostic, the same three with a Python thread state kept for the calling thread
 * (setreal_dostep_tstate_kept, ...; see `py` below: what pythonfmu's per-call thread-state churn costs).
 *
 * Prints one JSON line: best per-step seconds of each variant (`<variant>_s`), every round's per-step
 * seconds (`<variant>_samples_s`), and the out: variables read after the last span of each stepping
 * variant (`outputs_after_<variant>`: they must agree with each other and with the library run over the
 * same span, i.e. the timed calls did the real work).
 *
 * Exit codes: 0 ok, 2 usage, 3 load error, 4 an FMI call failed (status printed).
 * Compiled and run by benchmarks/bench_fmu.py (cc -O2 ... -ldl).
 */
#define _POSIX_C_SOURCE 199309L
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

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
typedef void (*FreeInstance_t)(fmi2Component);
typedef fmi2Status (*GetReal_t)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
typedef fmi2Status (*SetReal_t)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2Real *);
typedef fmi2Status (*DoStep_t)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
typedef fmi2Status (*GetFMUstate_t)(fmi2Component, fmi2FMUstate *);
typedef fmi2Status (*SetFMUstate_t)(fmi2Component, fmi2FMUstate);
typedef fmi2Status (*FreeFMUstate_t)(fmi2Component, fmi2FMUstate *);

#define MAX_VARS 4096
#define MAX_REPEATS 1000
/* The _kept variants repeat the first three with a Python thread state kept for this thread (below). */
enum { SETREAL_DOSTEP, DOSTEP, SETREAL, SETREAL_DOSTEP_KEPT, DOSTEP_KEPT, SETREAL_KEPT, N_VARIANTS };
static const char *variant_name[N_VARIANTS] = {"setreal_dostep", "dostep", "setreal",
                                               "setreal_dostep_tstate_kept", "dostep_tstate_kept",
                                               "setreal_tstate_kept"};

/* Diagnostic only. pythonfmu 0.7.0 initialises Python on a thread of its own and wraps every FMI call in
 * PyGILState_Ensure/Release. On a host thread that has no Python thread state (any C master), each call
 * then creates one and deletes it again. The _kept variants hold one for the calling thread
 * (PyGILState_Ensure + PyEval_SaveThread before the span, undone after it, both untimed), so each call
 * only takes and drops the GIL, as it does under a Python host. linknet FMUs keep that thread state
 * themselves (fmu_src/linknet_fmu/thread_state.py): then the _kept variants equal the plain ones, and a
 * difference says the FMU's keeping fails somewhere. The functions come from the libpython
 * the FMU binary links (dlsym on the FMU's handle searches its dependencies); the plain variants never
 * touch them. */
typedef int (*GILStateEnsure_t)(void);
typedef void (*GILStateRelease_t)(int);
typedef void *(*SaveThread_t)(void);
typedef void (*RestoreThread_t)(void *);
static struct {
    GILStateEnsure_t ensure;
    GILStateRelease_t release;
    SaveThread_t save;
    RestoreThread_t restore;
    int gil_state;
    void *thread_state;
} py;

static struct {
    fmi2Component c;
    SetReal_t set_real;
    GetReal_t get_real;
    DoStep_t do_step;
    SetFMUstate_t set_state;
    fmi2FMUstate initial;
    fmi2ValueReference in_vr[MAX_VARS];
    fmi2Real in_val[MAX_VARS];
    size_t n_in;
    double h;
    long n_steps;
} host;

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env;
    fprintf(stderr, "[%s] status %d %s: %s\n", instance, (int)status, category ? category : "", message);
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) { fprintf(stderr, "missing symbol %s\n", name); exit(3); }
    return f;
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#define CHECK(call) do { fmi2Status s_ = (call); if (s_ > fmi2Warning) { \
    fprintf(stderr, "%s failed with status %d\n", #call, (int)s_); return -1.0; } } while (0)

static double timed_span(int variant) {
    CHECK(host.set_state(host.c, host.initial));  /* back to t = 0, outside the timed span */
    if (variant == DOSTEP) CHECK(host.set_real(host.c, host.in_vr, host.n_in, host.in_val));
    double t = 0.0, t0 = now();
    switch (variant) {
    case SETREAL_DOSTEP:
        for (long n = 0; n < host.n_steps; n++) {
            CHECK(host.set_real(host.c, host.in_vr, host.n_in, host.in_val));
            CHECK(host.do_step(host.c, t, host.h, 1));
            t += host.h;  /* accumulated like a Python master's t += h: the same time points as bench_fmu's */
        }
        break;
    case DOSTEP:
        for (long n = 0; n < host.n_steps; n++) {
            CHECK(host.do_step(host.c, t, host.h, 1));
            t += host.h;
        }
        break;
    case SETREAL:
        for (long n = 0; n < host.n_steps; n++) CHECK(host.set_real(host.c, host.in_vr, host.n_in, host.in_val));
        break;
    }
    return (now() - t0) / (double)host.n_steps;
}

/* One timed span of a variant, from the initial state; returns seconds per call (< 0: an FMI call failed). */
static double run_variant(int variant) {
    if (variant < SETREAL_DOSTEP_KEPT) return timed_span(variant);
    if (!py.ensure) return 0.0;  /* not measured (reported as null) */
    py.gil_state = py.ensure();
    py.thread_state = py.save();
    double s = timed_span(variant - SETREAL_DOSTEP_KEPT);
    py.restore(py.thread_state);
    py.release(py.gil_state);  /* the thread state goes again */
    return s;
}

static void print_reals(const char *key, const fmi2Real *v, size_t n) {
    printf("\"%s\": [", key);
    for (size_t j = 0; j < n; j++) printf("%s%.17g", j ? ", " : "", v[j]);
    printf("]");
}

int main(int argc, char **argv) {
    if (argc < 8) {
        fprintf(stderr, "usage: %s FMU_DIR MODEL_ID GUID H N_STEPS REPEATS in:VR=VALUE [in:VR=VALUE ...] [out:VR ...]\n",
                argv[0]);
        return 2;
    }
    const char *dir = argv[1], *id = argv[2], *guid = argv[3];
    host.h = atof(argv[4]);
    host.n_steps = atol(argv[5]);
    long repeats = atol(argv[6]);
    if (!(host.h > 0) || host.n_steps < 1 || repeats < 1 || repeats > MAX_REPEATS) {
        fprintf(stderr, "H must be > 0, N_STEPS >= 1, 1 <= REPEATS <= %d\n", MAX_REPEATS);
        return 2;
    }
    static fmi2ValueReference out_vr[MAX_VARS];
    static fmi2Real out_after[N_VARIANTS][MAX_VARS];
    size_t n_out = 0;
    for (int i = 7; i < argc; i++) {
        if (strncmp(argv[i], "in:", 3) == 0 && host.n_in < MAX_VARS) {
            char *eq = strchr(argv[i], '=');
            if (!eq) return 2;
            host.in_vr[host.n_in] = (fmi2ValueReference)strtoul(argv[i] + 3, NULL, 10);
            host.in_val[host.n_in++] = atof(eq + 1);
        } else if (strncmp(argv[i], "out:", 4) == 0 && n_out < MAX_VARS) {
            out_vr[n_out++] = (fmi2ValueReference)strtoul(argv[i] + 4, NULL, 10);
        } else {
            fprintf(stderr, "bad argument %s (or more than %d inputs/outputs)\n", argv[i], MAX_VARS);
            return 2;
        }
    }
    if (host.n_in == 0) { fprintf(stderr, "at least one in:VR=VALUE is needed\n"); return 2; }

    char path[4096], uri[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    snprintf(uri, sizeof uri, "file://%s/resources", dir);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen failed: %s\n", dlerror()); return 3; }

    Instantiate_t instantiate = (Instantiate_t)sym(lib, "fmi2Instantiate");
    SetupExperiment_t setup = (SetupExperiment_t)sym(lib, "fmi2SetupExperiment");
    Simple_t enter = (Simple_t)sym(lib, "fmi2EnterInitializationMode");
    Simple_t exit_init = (Simple_t)sym(lib, "fmi2ExitInitializationMode");
    Simple_t terminate = (Simple_t)sym(lib, "fmi2Terminate");
    FreeInstance_t free_instance = (FreeInstance_t)sym(lib, "fmi2FreeInstance");
    GetFMUstate_t get_state = (GetFMUstate_t)sym(lib, "fmi2GetFMUstate");
    FreeFMUstate_t free_state = (FreeFMUstate_t)sym(lib, "fmi2FreeFMUstate");
    host.get_real = (GetReal_t)sym(lib, "fmi2GetReal");
    host.set_real = (SetReal_t)sym(lib, "fmi2SetReal");
    host.do_step = (DoStep_t)sym(lib, "fmi2DoStep");
    host.set_state = (SetFMUstate_t)sym(lib, "fmi2SetFMUstate");

    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    host.c = instantiate("c_timing_host", fmi2CoSimulation, guid, uri, &cb, 0, 1);
    if (!host.c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 4; }
    /* libpython comes with pythonfmu's binary, which the FMU's front layer (<id>.so) loads at fmi2Instantiate as
       <id>_pythonfmu.so beside it: its symbols are reached through that binary, else through the FMU's own */
    char inner_path[4200];
    snprintf(inner_path, sizeof inner_path, "%s/binaries/linux64/%s_pythonfmu.so", dir, id);
    void *python_lib = dlopen(inner_path, RTLD_NOW | RTLD_NOLOAD);
    if (!python_lib) python_lib = lib;
    py.ensure = (GILStateEnsure_t)dlsym(python_lib, "PyGILState_Ensure");
    py.release = (GILStateRelease_t)dlsym(python_lib, "PyGILState_Release");
    py.save = (SaveThread_t)dlsym(python_lib, "PyEval_SaveThread");
    py.restore = (RestoreThread_t)dlsym(python_lib, "PyEval_RestoreThread");
    if (!(py.ensure && py.release && py.save && py.restore)) {
        fprintf(stderr, "note: no libpython behind the FMU binary; the _tstate_kept variants are not measured\n");
        py.ensure = NULL;
    }
#undef CHECK
#define CHECK(call) do { fmi2Status s_ = (call); if (s_ > fmi2Warning) { \
    fprintf(stderr, "%s failed with status %d\n", #call, (int)s_); return 4; } } while (0)
    CHECK(setup(host.c, 0, 0.0, 0.0, 0, 0.0));
    CHECK(enter(host.c));
    CHECK(exit_init(host.c));
    CHECK(get_state(host.c, &host.initial));  /* t = 0, inputs at their start values */

    int n_measured = py.ensure ? N_VARIANTS : SETREAL_DOSTEP_KEPT;
    static double samples[N_VARIANTS][MAX_REPEATS];
    double best[N_VARIANTS];
    for (int v = 0; v < n_measured; v++)  /* warm-up round, untimed */
        if (run_variant(v) < 0) return 4;
    for (long r = 0; r < repeats; r++) {
        for (int k = 0; k < n_measured; k++) {
            int v = (int)((r + k) % n_measured);
            double s = run_variant(v);
            if (s < 0) return 4;
            samples[v][r] = s;
            if (r == 0 || s < best[v]) best[v] = s;
            if (v % SETREAL_DOSTEP_KEPT != SETREAL && n_out)  /* the state at the span's end (read outside it) */
                CHECK(host.get_real(host.c, out_vr, n_out, out_after[v]));
        }
    }

    printf("{\"n_steps\": %ld, \"repeats\": %ld, \"h\": %.17g, \"n_inputs\": %zu", host.n_steps, repeats, host.h,
           host.n_in);
    for (int v = 0; v < N_VARIANTS; v++) {
        if (v >= n_measured) printf(", \"%s_s\": null", variant_name[v]);
        else printf(", \"%s_s\": %.9g", variant_name[v], best[v]);
    }
    for (int v = 0; v < n_measured; v++) {
        printf(", \"%s_samples_s\": [", variant_name[v]);
        for (long r = 0; r < repeats; r++) printf("%s%.9g", r ? ", " : "", samples[v][r]);
        printf("]");
    }
    for (int v = 0; v < n_measured && n_out; v++) {
        if (v % SETREAL_DOSTEP_KEPT == SETREAL) continue;
        char key[128];
        snprintf(key, sizeof key, "outputs_after_%s", variant_name[v]);
        printf(", ");
        print_reals(key, out_after[v], n_out);
    }
    printf("}\n");
    fflush(stdout);
    CHECK(free_state(host.c, &host.initial));
    CHECK(terminate(host.c));
    free_instance(host.c);
    /* pythonfmu 0.7.0 may corrupt the heap while finalizing Python at exit (docs/fmu.md):
       every result is flushed above, so leave without running library destructors. */
    _exit(0);
}

/* FMI 2.0 Co-Simulation timing host in plain C: no Python in the host, no ctypes, no fmpy.
 *
 * Measures what an FMU costs per communication step when a C master drives it (as every FMI
 * toolchain does), so the FMU's own overhead can be told apart from a Python host's marshalling.
 * Loading, callbacks and the status check are tests/c_host/fmi2_host_api.h's, as every C host's.
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
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../../tests/c_host/fmi2_host_api.h"

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

static fmi2_host fmu;
static struct {
    fmi2Component c;
    fmi2FMUstate initial;
    fmi2ValueReference in_vr[MAX_VARS];
    fmi2Real in_val[MAX_VARS];
    size_t n_in;
    double h;
    long n_steps;
} host;

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#define CHECK(call) FMI2_HOST_CHECK(call, -1.0)

static double timed_span(int variant) {
    CHECK(fmu.SetFMUstate(host.c, host.initial));  /* back to t = 0, outside the timed span */
    if (variant == DOSTEP) CHECK(fmu.SetReal(host.c, host.in_vr, host.n_in, host.in_val));
    double t = 0.0, t0 = now();
    switch (variant) {
    case SETREAL_DOSTEP:
        for (long n = 0; n < host.n_steps; n++) {
            CHECK(fmu.SetReal(host.c, host.in_vr, host.n_in, host.in_val));
            CHECK(fmu.DoStep(host.c, t, host.h, 1));
            t += host.h;  /* accumulated like a Python master's t += h: the same time points as bench_fmu's */
        }
        break;
    case DOSTEP:
        for (long n = 0; n < host.n_steps; n++) {
            CHECK(fmu.DoStep(host.c, t, host.h, 1));
            t += host.h;
        }
        break;
    case SETREAL:
        for (long n = 0; n < host.n_steps; n++) CHECK(fmu.SetReal(host.c, host.in_vr, host.n_in, host.in_val));
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

    fmi2_host_open(&fmu, dir, id);
    host.c = fmi2_host_instantiate(&fmu, "c_timing_host", guid, fmi2True);
    if (!host.c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 4; }
    /* libpython comes with pythonfmu's binary, which the FMU's front layer (<id>.so) loads at fmi2Instantiate as
       <id>_pythonfmu.so beside it: its symbols are reached through that binary, else through the FMU's own */
    char inner_path[4200];
    snprintf(inner_path, sizeof inner_path, "%s/binaries/linux64/%s_pythonfmu.so", dir, id);
    void *python_lib = dlopen(inner_path, RTLD_NOW | RTLD_NOLOAD);
    if (!python_lib) python_lib = fmu.library;
    py.ensure = (GILStateEnsure_t)dlsym(python_lib, "PyGILState_Ensure");
    py.release = (GILStateRelease_t)dlsym(python_lib, "PyGILState_Release");
    py.save = (SaveThread_t)dlsym(python_lib, "PyEval_SaveThread");
    py.restore = (RestoreThread_t)dlsym(python_lib, "PyEval_RestoreThread");
    if (!(py.ensure && py.release && py.save && py.restore)) {
        fprintf(stderr, "note: no libpython behind the FMU binary; the _tstate_kept variants are not measured\n");
        py.ensure = NULL;
    }
#undef CHECK
#define CHECK(call) FMI2_HOST_CHECK(call, 4)
    CHECK(fmu.SetupExperiment(host.c, 0, 0.0, 0.0, 0, 0.0));
    CHECK(fmu.EnterInitializationMode(host.c));
    CHECK(fmu.ExitInitializationMode(host.c));
    CHECK(fmu.GetFMUstate(host.c, &host.initial));  /* t = 0, inputs at their start values */

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
                CHECK(fmu.GetReal(host.c, out_vr, n_out, out_after[v]));
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
    CHECK(fmu.FreeFMUstate(host.c, &host.initial));
    CHECK(fmu.Terminate(host.c));
    fmu.FreeInstance(host.c);
    /* pythonfmu 0.7.0 may corrupt the heap while finalizing Python at exit (docs/fmu.md):
       every result is flushed above, so leave without running library destructors. */
    _exit(0);
}

/* A plain C FMI 2.0 Co-Simulation host for the native linknet FMU: no Python in the process (the tests run it
 * under env -i with a PATH that has no Python). It loads binaries/linux64/<id>.so from an extracted FMU with
 * dlopen and runs one of:
 *
 *   run       DIR ID GUID T0 N H [options]   N communication steps of H from T0, one CSV line per point:
 *                                            t, then the outputs asked for (-o), read after the inputs of the
 *                                            step that starts there are set (T feels them directly)
 *   replay    DIR ID GUID N H [options]      FMU state: get after N steps, run N more, set and replay, serialize
 *                                            and replay in a fresh instance; prints whether all are bit-identical
 *   twins     DIR ID GUID N H [options]      two instances interleaved, and on two threads, against each alone
 *   contract  DIR ID GUID FOREIGN_STATE F X T M R TOL STEP
 *                                            bad inputs, misuse and foreign states; one line per case:
 *                                            CASE <name> <status> <message logged last>
 *   savestate DIR ID GUID FILE               a serialized state after one step, for another FMU's contract run
 *   coldstart DIR ID GUID H                  seconds for dlopen, and from fmi2Instantiate to the end of the
 *                                            first doStep (this process is fresh)
 *   cycles    DIR ID GUID N                  N instantiate/initialize/step/get state/free cycles; resident
 *                                            memory (KiB) after the first tenth and after all of them
 *   stepbench DIR ID GUID N H REPEATS STEP_VR STEP INPUT_VR
 *                                            nanoseconds per setReal (one input) + doStep, and per doStep alone,
 *                                            best of REPEATS runs of N calls, each from the same FMU state
 *
 * NATIVE_HOST_FAST_EXIT=1 leaves with _exit (for FMUs that hang in a normal exit, such as pythonfmu's).
 *
 * options: -m VR=METHOD (the String parameter integrator), -p VR=VALUE (a Real parameter, set in initialization mode),
 *          -i VR=A[,W] (an input, A cos(W t) at every communication point; W absent: constant), -o VR (an output)
 *
 * Exit codes: 0 ok, 2 usage, 3 load error, 4 an FMI call failed where it should not have. The process ends with
 * a normal exit() after freeing its instances: an FMU that hangs or crashes at exit fails the test.
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
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
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Byte;
typedef const char *fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;
typedef struct {
    void (*logger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef struct {
    fmi2Component (*instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions *,
                                 fmi2Boolean, fmi2Boolean);
    void (*free_instance)(fmi2Component);
    fmi2Status (*setup)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
    fmi2Status (*enter_init)(fmi2Component);
    fmi2Status (*exit_init)(fmi2Component);
    fmi2Status (*terminate)(fmi2Component);
    fmi2Status (*reset)(fmi2Component);
    fmi2Status (*get_real)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
    fmi2Status (*set_real)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2Real *);
    fmi2Status (*get_integer)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Integer *);
    fmi2Status (*get_boolean)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Boolean *);
    fmi2Status (*set_boolean)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2Boolean *);
    fmi2Status (*get_string)(fmi2Component, const fmi2ValueReference *, size_t, fmi2String *);
    fmi2Status (*set_string)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2String *);
    fmi2Status (*set_integer)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2Integer *);
    fmi2Status (*do_step)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
    fmi2Status (*get_state)(fmi2Component, fmi2FMUstate *);
    fmi2Status (*set_state)(fmi2Component, fmi2FMUstate);
    fmi2Status (*free_state)(fmi2Component, fmi2FMUstate *);
    fmi2Status (*state_size)(fmi2Component, fmi2FMUstate, size_t *);
    fmi2Status (*serialize)(fmi2Component, fmi2FMUstate, fmi2Byte *, size_t);
    fmi2Status (*deserialize)(fmi2Component, const fmi2Byte *, size_t, fmi2FMUstate *);
    fmi2Status (*get_real_status)(fmi2Component, fmi2StatusKind, fmi2Real *);
    fmi2Status (*set_debug_logging)(fmi2Component, fmi2Boolean, size_t, const fmi2String *);
} api;

static api F;
static const char *GUID;
static char resources[4200];  /* fmuResourceLocation: file://DIR/resources */

/* the last message the FMU logged, per thread of the log (instances log from the thread that calls them) */
static char last_log[4096];
static int fatal_seen = 0;

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    if (status == fmi2Fatal) fatal_seen = 1;
    va_list args;
    va_start(args, message);
    vsnprintf(last_log, sizeof last_log, message, args);  /* the FMU doubles '%': expand as the standard says */
    va_end(args);
    if (getenv("NATIVE_HOST_VERBOSE")) fprintf(stderr, "[%s] %d %s %s\n", instance, (int)status, category, last_log);
}

static void quiet_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                         fmi2String message, ...)
{
    (void)env, (void)instance, (void)category, (void)message;
    if (status == fmi2Fatal) fatal_seen = 1;
}

static fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
static double now(void);
static fmi2CallbackFunctions quiet_callbacks = {quiet_logger, calloc, free, NULL, NULL};

static void *sym(void *lib, const char *name)
{
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "missing symbol %s\n", name);
        exit(3);
    }
    return f;
}

static void *load(const char *dir, const char *id)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    snprintf(resources, sizeof resources, "file://%s/resources", dir);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen failed: %s\n", dlerror());
        exit(3);
    }
#define BIND(field, name) *(void **)(&F.field) = sym(lib, name)
    BIND(instantiate, "fmi2Instantiate");
    BIND(free_instance, "fmi2FreeInstance");
    BIND(setup, "fmi2SetupExperiment");
    BIND(enter_init, "fmi2EnterInitializationMode");
    BIND(exit_init, "fmi2ExitInitializationMode");
    BIND(terminate, "fmi2Terminate");
    BIND(reset, "fmi2Reset");
    BIND(get_real, "fmi2GetReal");
    BIND(set_real, "fmi2SetReal");
    BIND(get_integer, "fmi2GetInteger");
    BIND(get_boolean, "fmi2GetBoolean");
    BIND(set_boolean, "fmi2SetBoolean");
    BIND(get_string, "fmi2GetString");
    BIND(set_string, "fmi2SetString");
    BIND(set_integer, "fmi2SetInteger");
    BIND(do_step, "fmi2DoStep");
    BIND(get_state, "fmi2GetFMUstate");
    BIND(set_state, "fmi2SetFMUstate");
    BIND(free_state, "fmi2FreeFMUstate");
    BIND(state_size, "fmi2SerializedFMUstateSize");
    BIND(serialize, "fmi2SerializeFMUstate");
    BIND(deserialize, "fmi2DeSerializeFMUstate");
    BIND(get_real_status, "fmi2GetRealStatus");
    BIND(set_debug_logging, "fmi2SetDebugLogging");
#undef BIND
    return lib;
}

#define MUST(call)                                                                     \
    do {                                                                               \
        fmi2Status s_ = (call);                                                        \
        if (s_ != fmi2OK) {                                                            \
            fprintf(stderr, "%s returned %d: %s\n", #call, (int)s_, last_log);         \
            exit(4);                                                                   \
        }                                                                              \
    } while (0)

/* ---- a run described by the options ------------------------------------------------------------- */

#define MAX_VARS 8192
typedef struct {
    const char *method;
    size_t n_par, n_in, n_out, n_bool, n_detour;
    fmi2ValueReference par_vr[MAX_VARS], in_vr[MAX_VARS], out_vr[MAX_VARS], bool_vr[16], detour_vr[16];
    double par[MAX_VARS], amp[MAX_VARS], omega[MAX_VARS], detour[16];
    fmi2Boolean bool_value[16];
} plan;

static plan P;
static fmi2ValueReference integrator_vr = 0;

static void parse_options(int argc, char **argv, int first)
{
    for (int i = first; i < argc; i++) {
        const char *a = argv[i];
        if (i + 1 >= argc) exit(2);
        const char *v = argv[++i];
        if (strcmp(a, "-m") == 0) {
            integrator_vr = (fmi2ValueReference)strtoul(v, NULL, 10);
            P.method = strchr(v, '=') + 1;
        } else if (strcmp(a, "-p") == 0 && P.n_par < MAX_VARS) {
            P.par_vr[P.n_par] = (fmi2ValueReference)strtoul(v, NULL, 10);
            P.par[P.n_par++] = strtod(strchr(v, '=') + 1, NULL);
        } else if (strcmp(a, "-i") == 0 && P.n_in < MAX_VARS) {
            char *end;
            P.in_vr[P.n_in] = (fmi2ValueReference)strtoul(v, NULL, 10);
            P.amp[P.n_in] = strtod(strchr(v, '=') + 1, &end);
            P.omega[P.n_in++] = *end == ',' ? strtod(end + 1, NULL) : 0.0;
        } else if (strcmp(a, "-b") == 0 && P.n_bool < 16) {  /* a Boolean parameter: vr=0|1 */
            P.bool_vr[P.n_bool] = (fmi2ValueReference)strtoul(v, NULL, 10);
            P.bool_value[P.n_bool++] = atoi(strchr(v, '=') + 1) != 0;
        } else if (strcmp(a, "-q") == 0 && P.n_detour < 16) {  /* a parameter set (and applied) before the -p ones */
            P.detour_vr[P.n_detour] = (fmi2ValueReference)strtoul(v, NULL, 10);
            P.detour[P.n_detour++] = strtod(strchr(v, '=') + 1, NULL);
        } else if (strcmp(a, "-o") == 0 && P.n_out < MAX_VARS) {
            P.out_vr[P.n_out++] = (fmi2ValueReference)strtoul(v, NULL, 10);
        } else {
            fprintf(stderr, "unknown option %s\n", a);
            exit(2);
        }
    }
}


/* Initialization of an instantiated (or reset) instance as the plan says. With detour, the -q parameters are set
   first and applied (an output read in initialization mode applies the parameters set so far), then the plan's. */
static void initialize(fmi2Component c, double t0, int detour)
{
    MUST(F.setup(c, 0, 0.0, t0, 0, 0.0));
    MUST(F.enter_init(c));
    if (detour && P.n_detour) {
        double ignored[MAX_VARS];
        MUST(F.set_real(c, P.detour_vr, P.n_detour, P.detour));
        if (P.n_out) MUST(F.get_real(c, P.out_vr, P.n_out, ignored));
    }
    if (P.method) {
        fmi2String m = P.method;
        MUST(F.set_string(c, &integrator_vr, 1, &m));
    }
    if (P.n_bool) MUST(F.set_boolean(c, P.bool_vr, P.n_bool, P.bool_value));
    if (P.n_par) MUST(F.set_real(c, P.par_vr, P.n_par, P.par));
    MUST(F.exit_init(c));
}

static fmi2Component start(const char *name, double t0, fmi2CallbackFunctions *cb)
{
    fmi2Component c = F.instantiate(name, fmi2CoSimulation, GUID, resources, cb, 0, 0);
    if (!c) {
        fprintf(stderr, "fmi2Instantiate failed: %s\n", last_log);
        exit(4);
    }
    if (P.n_bool || P.n_detour) {
        initialize(c, t0, 0);
        return c;
    }
    MUST(F.setup(c, 0, 0.0, t0, 0, 0.0));
    MUST(F.enter_init(c));
    if (P.method) {
        fmi2String m = P.method;
        MUST(F.set_string(c, &integrator_vr, 1, &m));
    }
    if (P.n_par) MUST(F.set_real(c, P.par_vr, P.n_par, P.par));
    MUST(F.exit_init(c));
    return c;
}

static void set_inputs(fmi2Component c, double t)
{
    double value[MAX_VARS];
    for (size_t j = 0; j < P.n_in; j++) value[j] = P.omega[j] == 0.0 ? P.amp[j] : P.amp[j] * cos(P.omega[j] * t);
    if (P.n_in) MUST(F.set_real(c, P.in_vr, P.n_in, value));
}

/* N steps of h from t0, the outputs at every point into rows (N+1 rows of n_out) if given */
static void steps(fmi2Component c, double t0, long N, double h, long first, double *rows)
{
    for (long n = first; n <= N; n++) {
        const double t = t0 + (double)n * h;
        set_inputs(c, t);
        if (rows && P.n_out) MUST(F.get_real(c, P.out_vr, P.n_out, rows + (size_t)(n - first) * P.n_out));
        if (n < N) MUST(F.do_step(c, t, h, 1));
    }
}

static int cmd_run(int argc, char **argv)
{
    if (argc < 8) return 2;
    const double t0 = atof(argv[5]), h = atof(argv[7]);
    const long N = atol(argv[6]);
    parse_options(argc, argv, 8);
    fmi2Component c = start("run", t0, &callbacks);
    double *rows = calloc((size_t)(N + 1) * (P.n_out ? P.n_out : 1), sizeof(double));
    steps(c, t0, N, h, 0, rows);
    for (long n = 0; n <= N; n++) {
        printf("%.17g", t0 + (double)n * h);
        for (size_t j = 0; j < P.n_out; j++) printf(",%.17g", rows[(size_t)n * P.n_out + j]);
        printf("\n");
    }
    free(rows);
    MUST(F.terminate(c));
    F.free_instance(c);
    return 0;
}

static int same(const double *a, const double *b, size_t n) { return memcmp(a, b, n * sizeof(double)) == 0; }

static int cmd_replay(int argc, char **argv)
{
    if (argc < 7) return 2;
    const long N = atol(argv[5]);
    const double h = atof(argv[6]);
    parse_options(argc, argv, 7);
    const size_t per = P.n_out ? P.n_out : 1, n_rows = (size_t)(N + 1) * per;
    double *first = calloc(n_rows, sizeof(double)), *again = calloc(n_rows, sizeof(double)),
           *fresh = calloc(n_rows, sizeof(double));
    fmi2Component c = start("replay", 0.0, &callbacks);
    steps(c, 0.0, N, h, 0, NULL);
    fmi2FMUstate s = NULL;
    MUST(F.get_state(c, &s));
    steps(c, 0.0, 2 * N, h, N, first);
    MUST(F.set_state(c, s));
    steps(c, 0.0, 2 * N, h, N, again);
    size_t size = 0;
    MUST(F.state_size(c, s, &size));
    fmi2Byte *bytes = malloc(size);
    MUST(F.serialize(c, s, bytes, size));
    fmi2Component d = start("fresh", 0.0, &callbacks);
    fmi2FMUstate s2 = NULL;
    MUST(F.deserialize(d, bytes, size, &s2));
    MUST(F.set_state(d, s2));
    steps(d, 0.0, 2 * N, h, N, fresh);
    printf("replay_identical %d\nfresh_identical %d\nstate_bytes %zu\n", same(first, again, n_rows),
           same(first, fresh, n_rows), size);
    MUST(F.free_state(c, &s));
    MUST(F.free_state(d, &s2));
    F.free_instance(c);
    F.free_instance(d);
    free(bytes), free(first), free(again), free(fresh);
    return 0;
}

/* The same run three ways, bit for bit: a fresh instance; the same instance after fmi2Reset (initialized again as
   the plan says); a new instance whose parameters were first set to the -q values and applied (the model and the
   error estimate's companion rebuilt there) and then to the plan's. Prints reset_identical and detour_identical. */
static int cmd_rerun(int argc, char **argv)
{
    if (argc < 7) return 2;
    const long N = atol(argv[5]);
    const double h = atof(argv[6]);
    parse_options(argc, argv, 7);
    const size_t per = P.n_out ? P.n_out : 1, n_rows = (size_t)(N + 1) * per;
    double *fresh = calloc(n_rows, sizeof(double)), *reset = calloc(n_rows, sizeof(double)),
           *detour = calloc(n_rows, sizeof(double));
    fmi2Component c = F.instantiate("rerun", fmi2CoSimulation, GUID, resources, &callbacks, 0, 0);
    if (!c) return 4;
    initialize(c, 0.0, 0);
    steps(c, 0.0, N, h, 0, fresh);
    MUST(F.reset(c));
    initialize(c, 0.0, 0);
    steps(c, 0.0, N, h, 0, reset);
    fmi2Component d = F.instantiate("detour", fmi2CoSimulation, GUID, resources, &callbacks, 0, 0);
    if (!d) return 4;
    initialize(d, 0.0, 1);
    steps(d, 0.0, N, h, 0, detour);
    printf("reset_identical %d\ndetour_identical %d\n", same(fresh, reset, n_rows), same(fresh, detour, n_rows));
    for (long n = 0; n <= N; n++) {
        printf("%.17g", (double)n * h);
        for (size_t j = 0; j < P.n_out; j++) printf(",%.17g", fresh[(size_t)n * P.n_out + j]);
        printf("\n");
    }
    F.free_instance(c);
    F.free_instance(d);
    free(fresh), free(reset), free(detour);
    return 0;
}

typedef struct {
    long N;
    double h;
    double *rows;
    const char *name;
} job;

static void *run_job(void *arg)
{
    job *j = arg;
    fmi2Component c = start(j->name, 0.0, &quiet_callbacks);
    steps(c, 0.0, j->N, j->h, 0, j->rows);
    F.free_instance(c);
    return NULL;
}

static int cmd_twins(int argc, char **argv)
{
    if (argc < 7) return 2;
    const long N = atol(argv[5]);
    const double h = atof(argv[6]);
    parse_options(argc, argv, 7);
    const size_t per = P.n_out ? P.n_out : 1, n_rows = (size_t)(N + 1) * per;
    double *alone = calloc(n_rows, sizeof(double)), *a = calloc(n_rows, sizeof(double)),
           *b = calloc(n_rows, sizeof(double)), *ta = calloc(n_rows, sizeof(double)),
           *tb = calloc(n_rows, sizeof(double));
    fmi2Component c = start("alone", 0.0, &callbacks);
    steps(c, 0.0, N, h, 0, alone);
    F.free_instance(c);
    /* interleaved: A's step, B's step, ...; B's inputs doubled between its points and put back: a state
       shared between instances would show up in A */
    fmi2Component ca = start("A", 0.0, &callbacks), cb = start("B", 0.0, &callbacks);
    double other[MAX_VARS];
    for (long n = 0; n <= N; n++) {
        const double t = (double)n * h;
        set_inputs(ca, t);
        for (size_t j = 0; j < P.n_in; j++) other[j] = 2.0 * P.amp[j] + 1.0;
        if (P.n_in) MUST(F.set_real(cb, P.in_vr, P.n_in, other));
        if (P.n_out) MUST(F.get_real(ca, P.out_vr, P.n_out, a + (size_t)n * per));
        if (P.n_out) MUST(F.get_real(cb, P.out_vr, P.n_out, b + (size_t)n * per));
        if (n < N) {
            MUST(F.do_step(cb, t, h, 1));
            MUST(F.do_step(ca, t, h, 1));
        }
    }
    F.free_instance(ca);
    F.free_instance(cb);
    /* two threads at once, each with its own instance */
    pthread_t t1, t2;
    job j1 = {N, h, ta, "T1"}, j2 = {N, h, tb, "T2"};
    pthread_create(&t1, NULL, run_job, &j1);
    pthread_create(&t2, NULL, run_job, &j2);
    pthread_join(t1, NULL);
    pthread_join(t2, NULL);
    printf("interleaved_identical %d\nother_differs %d\nthreads_identical %d\n", same(alone, a, n_rows),
           !same(alone, b, n_rows), same(alone, ta, n_rows) && same(alone, tb, n_rows));
    free(alone), free(a), free(b), free(ta), free(tb);
    return 0;
}

static int cmd_savestate(int argc, char **argv)
{
    if (argc < 6) return 2;
    fmi2Component c = start("save", 0.0, &callbacks);
    MUST(F.do_step(c, 0.0, 0.01, 1));
    fmi2FMUstate s = NULL;
    MUST(F.get_state(c, &s));
    size_t size;
    MUST(F.state_size(c, s, &size));
    fmi2Byte *bytes = malloc(size);
    MUST(F.serialize(c, s, bytes, size));
    FILE *f = fopen(argv[5], "wb");
    if (!f || fwrite(bytes, 1, size, f) != size) return 4;
    fclose(f);
    free(bytes);
    MUST(F.free_state(c, &s));
    F.free_instance(c);
    return 0;
}

/* ---- the contract ------------------------------------------------------------------------------- */

static int cmd_stepbench(int argc, char **argv)
{
    if (argc < 11) return 2;
    const long N = atol(argv[5]);
    const double h = atof(argv[6]);
    const int R = atoi(argv[7]);
    fmi2ValueReference step_vr = (fmi2ValueReference)atoi(argv[8]), in = (fmi2ValueReference)atoi(argv[10]);
    P.n_par = 1;
    P.par_vr[0] = step_vr;
    P.par[0] = atof(argv[9]);
    fmi2Component c = start("bench", 0.0, &callbacks);
    fmi2FMUstate s = NULL;
    MUST(F.get_state(c, &s));
    double best_set = 1e300, best_step = 1e300;
    for (int r = 0; r < R; r++) {
        for (int with_set = 0; with_set < 2; with_set++) {
            MUST(F.set_state(c, s));
            double t = 0.0, value = 0.0;
            MUST(F.set_real(c, &in, 1, &value));
            const double t0 = now();
            for (long i = 0; i < N; i++) {
                if (with_set) {
                    value = 0.1 * sin(0.37 * (double)i);
                    F.set_real(c, &in, 1, &value);
                }
                if (F.do_step(c, t, h, 1) != fmi2OK) exit(4);
                t += h;
            }
            const double per = (now() - t0) / (double)N;
            if (with_set && per < best_set) best_set = per;
            if (!with_set && per < best_step) best_step = per;
        }
    }
    printf("setreal_dostep %.1f\ndostep %.1f\n", 1e9 * best_set, 1e9 * best_step);
    MUST(F.free_state(c, &s));
    F.free_instance(c);
    return 0;
}

static int n_cases = 0;

static void report(const char *name, fmi2Status status)
{
    if (status == fmi2Fatal) fatal_seen = 1;
    printf("CASE %s %d %s\n", name, (int)status, last_log);
    last_log[0] = '\0';
    n_cases++;
}

static int cmd_contract(int argc, char **argv)
{
    if (argc < 13) return 2;
    const char *foreign = argv[5];
    fmi2ValueReference vF = (fmi2ValueReference)atoi(argv[6]), vX = (fmi2ValueReference)atoi(argv[7]),
                       vT = (fmi2ValueReference)atoi(argv[8]), vM = (fmi2ValueReference)atoi(argv[9]),
                       vR = (fmi2ValueReference)atoi(argv[10]), vTol = (fmi2ValueReference)atoi(argv[11]),
                       vStep = (fmi2ValueReference)atoi(argv[12]);
    const fmi2ValueReference bad_vr = 999999;
    double x = 0.0, v;
    fmi2Status s;

    /* instantiation */
    fmi2Component c = F.instantiate("wrong_guid", fmi2CoSimulation, "{00000000-0000-0000-0000-000000000000}",
                                    resources, &callbacks, 0, 0);
    report("instantiate_wrong_guid", c == NULL ? fmi2Error : fmi2OK);
    c = F.instantiate("me", fmi2ModelExchange, GUID, resources, &callbacks, 0, 0);
    report("instantiate_model_exchange", c == NULL ? fmi2Error : fmi2OK);
    c = F.instantiate("null_guid", fmi2CoSimulation, NULL, resources, &callbacks, 0, 0);
    report("instantiate_null_guid", c == NULL ? fmi2Error : fmi2OK);

    c = F.instantiate("contract", fmi2CoSimulation, GUID, resources, &callbacks, 0, 0);
    if (!c) return 4;
    report("step_before_initialization", F.do_step(c, 0.0, 0.01, 1));
    report("set_start_time", F.setup(c, 0, 0.0, 1.5, 0, 0.0));
    report("setup_nan_start", F.setup(c, 0, 0.0, NAN, 0, 0.0));
    report("enter_initialization", F.enter_init(c));
    report("step_in_initialization", F.do_step(c, 1.5, 0.01, 1));
    report("setup_in_initialization", F.setup(c, 0, 0.0, 0.0, 0, 0.0));
    x = -1.0;
    report("set_mass_negative", F.set_real(c, &vM, 1, &x));
    x = NAN;
    report("set_mass_nan", F.set_real(c, &vM, 1, &x));
    x = 5.0;
    report("set_tolerance_5", F.set_real(c, &vTol, 1, &x));
    x = 1e-20;
    report("set_tolerance_tiny", F.set_real(c, &vTol, 1, &x));
    x = 0.0;
    report("set_step_zero", F.set_real(c, &vStep, 1, &x));
    F.get_real(c, &vR, 1, &v);
    x = 1.5 * v;
    report("set_length_misfit", F.set_real(c, &vR, 1, &x));
    {
        fmi2ValueReference vrs[2] = {vF, vX};
        double xs[2] = {1.0, 2.0};
        report("set_output_in_batch", F.set_real(c, vrs, 2, xs));
        F.get_real(c, &vF, 1, &v);
        printf("VALUE input_after_refused_batch %.17g\n", v);
    }
    report("set_unknown_vr", F.set_real(c, &bad_vr, 1, &x));
    report("get_unknown_vr", F.get_real(c, &bad_vr, 1, &v));
    report("get_null_vr", F.get_real(c, NULL, 1, &v));
    {
        fmi2Integer iv;
        fmi2Boolean bv;
        fmi2String sv;
        report("get_integer", F.get_integer(c, &vF, 1, &iv));
        report("set_integer", F.set_integer(c, &vF, 1, &iv));
        report("get_boolean", F.get_boolean(c, &vF, 1, &bv));
        report("get_string_of_real", F.get_string(c, &vF, 1, &sv));
        fmi2String name = "rk99";
        fmi2ValueReference vs = vStep + 1;  /* the String parameter follows the Reals */
        report("set_integrator_unknown", F.set_string(c, &vs, 1, &name));
        fmi2String good = "dop853";
        report("set_integrator_dop853", F.set_string(c, &vs, 1, &good));
        report("get_integrator", F.get_string(c, &vs, 1, &sv));
        printf("VALUE integrator %s\n", sv);
    }
    report("exit_initialization", F.exit_init(c));
    F.get_real(c, &vX, 1, &v);
    report("get_time_start", F.get_real_status(c, fmi2LastSuccessfulTime, &x));
    printf("VALUE time_after_init %.17g\n", x);
    x = NAN;
    report("set_input_nan", F.set_real(c, &vF, 1, &x));
    x = INFINITY;
    report("set_input_inf", F.set_real(c, &vF, 1, &x));
    report("set_output", F.set_real(c, &vX, 1, &x));
    F.get_real(c, &vM, 1, &v);
    report("set_parameter_same_after_init", F.set_real(c, &vM, 1, &v));
    x = 2.0 * v;
    report("set_parameter_after_init", F.set_real(c, &vM, 1, &x));
    report("step_negative_h", F.do_step(c, 1.5, -0.01, 1));
    report("step_zero_h", F.do_step(c, 1.5, 0.0, 1));
    report("step_nan_h", F.do_step(c, 1.5, NAN, 1));
    report("step_wrong_t", F.do_step(c, 0.0, 0.01, 1));
    report("step_ok", F.do_step(c, 1.5, 0.01, 1));
    report("step_sub_ulp", F.do_step(c, 1.51, 1e-300, 1));
    x = 1e300;
    report("set_input_beyond_limit", F.set_real(c, &vF, 1, &x));
    x = 1e90;
    report("set_input_huge", F.set_real(c, &vF, 1, &x));
    s = F.do_step(c, 1.51, 0.01, 1);
    report("step_with_huge_input", s);
    F.get_real_status(c, fmi2LastSuccessfulTime, &x);
    printf("VALUE time_after_discard %.17g\n", x);
    x = 0.0;
    report("set_input_zero", F.set_real(c, &vF, 1, &x));
    report("step_after_discard", F.do_step(c, 1.51, 0.01, 1));
    report("get_tension", F.get_real(c, &vT, 1, &v));
    printf("VALUE tension_finite %d\n", isfinite(v) ? 1 : 0);

    /* FMU states */
    fmi2FMUstate st = NULL;
    report("get_state", F.get_state(c, &st));
    report("get_state_null", F.get_state(c, NULL));
    {
        double garbage_words[64];
        for (int i = 0; i < 64; i++) garbage_words[i] = (double)i * 1.25;
        report("set_state_garbage", F.set_state(c, (fmi2FMUstate)garbage_words));
        report("set_state_null", F.set_state(c, NULL));
        fmi2FMUstate g = NULL;
        report("deserialize_garbage", F.deserialize(c, (const fmi2Byte *)garbage_words, sizeof garbage_words, &g));
        size_t size = 0;
        F.state_size(c, st, &size);
        fmi2Byte *bytes = malloc(size);
        F.serialize(c, st, bytes, size);
        report("deserialize_truncated", F.deserialize(c, bytes, size / 2, &g));
        bytes[size - 9] ^= 0x7f;  /* a bit flipped in the payload: the header is intact */
        fmi2FMUstate flipped = NULL;
        report("deserialize_flipped_payload", F.deserialize(c, bytes, size, &flipped));
        if (flipped) F.free_state(c, &flipped);
        bytes[size - 9] ^= 0x7f;
        bytes[12] ^= 0x01;  /* the byte order mark */
        report("deserialize_other_byte_order", F.deserialize(c, bytes, size, &g));
        free(bytes);
    }
    {
        FILE *f = foreign[0] ? fopen(foreign, "rb") : NULL;
        if (f) {
            static fmi2Byte buffer[1 << 22];
            const size_t n = fread(buffer, 1, sizeof buffer, f);
            fclose(f);
            fmi2FMUstate g = NULL;
            report("deserialize_foreign", F.deserialize(c, buffer, n, &g));
        }
    }
    report("set_state_own", F.set_state(c, st));
    report("free_state", F.free_state(c, &st));
    report("free_state_again", F.free_state(c, &st));  /* NULL after the first: a no-op */

    /* usable after all of it, and again after a reset */
    F.get_real_status(c, fmi2LastSuccessfulTime, &x);
    report("step_at_end", F.do_step(c, x, 0.01, 1));
    report("terminate", F.terminate(c));
    report("step_after_terminate", F.do_step(c, x + 0.01, 0.01, 1));
    report("reset", F.reset(c));
    F.get_real(c, &vM, 1, &v);
    printf("VALUE mass_after_reset %.17g\n", v);
    report("setup_after_reset", F.setup(c, 0, 0.0, 0.0, 0, 0.0));
    report("enter_after_reset", F.enter_init(c));
    report("exit_after_reset", F.exit_init(c));
    report("step_after_reset", F.do_step(c, 0.0, 0.01, 1));
    report("debug_logging_unknown_category", F.set_debug_logging(c, 1, 1, (const fmi2String[]){"logNothing"}));
    report("null_component_step", F.do_step(NULL, 0.0, 0.01, 1));
    F.free_instance(NULL);
    F.free_instance(c);
    printf("FATAL_SEEN %d\nCASES %d\n", fatal_seen, n_cases);
    return 0;
}

/* ---- cold start and memory ---------------------------------------------------------------------- */

static long resident_kib(void)
{
    long pages = 0, resident = 0;
    FILE *f = fopen("/proc/self/statm", "r");
    if (!f) return -1;
    if (fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = -1;
    fclose(f);
    return resident * 4;
}

static int cmd_cycles(int argc, char **argv)
{
    if (argc < 6) return 2;
    const long N = atol(argv[5]);
    long early = 0;
    for (long i = 0; i < N; i++) {
        fmi2Component c = start("cycle", 0.0, &quiet_callbacks);
        MUST(F.do_step(c, 0.0, 0.01, 1));
        fmi2FMUstate s = NULL;
        MUST(F.get_state(c, &s));
        MUST(F.free_state(c, &s));
        F.free_instance(c);
        if (i == N / 10) early = resident_kib();
    }
    printf("resident_after_tenth %ld\nresident_after_all %ld\n", early, resident_kib());
    return 0;
}

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv)
{
    if (argc < 5) {
        fprintf(stderr, "usage: %s run|replay|rerun|twins|contract|savestate|coldstart|cycles DIR ID GUID ...\n", argv[0]);
        return 2;
    }
    const char *what = argv[1];
    GUID = argv[4];
    const double t_load = now();
    load(argv[2], argv[3]);
    const double t_loaded = now();
    int rc;
    if (strcmp(what, "run") == 0) rc = cmd_run(argc, argv);
    else if (strcmp(what, "replay") == 0) rc = cmd_replay(argc, argv);
    else if (strcmp(what, "rerun") == 0) rc = cmd_rerun(argc, argv);
    else if (strcmp(what, "twins") == 0) rc = cmd_twins(argc, argv);
    else if (strcmp(what, "contract") == 0) rc = cmd_contract(argc, argv);
    else if (strcmp(what, "savestate") == 0) rc = cmd_savestate(argc, argv);
    else if (strcmp(what, "cycles") == 0) rc = cmd_cycles(argc, argv);
    else if (strcmp(what, "stepbench") == 0) rc = cmd_stepbench(argc, argv);
    else if (strcmp(what, "coldstart") == 0) {
        const double h = argc > 5 ? atof(argv[5]) : 0.01;
        const double t0 = now();
        fmi2Component c = start("cold", 0.0, &callbacks);
        MUST(F.do_step(c, 0.0, h, 1));
        const double t1 = now();
        printf("dlopen %.9f\ninstantiate_to_first_step %.9f\n", t_loaded - t_load, t1 - t0);
        F.free_instance(c);
        rc = 0;
    } else {
        rc = 2;
    }
    fflush(stdout);
    if (getenv("NATIVE_HOST_FAST_EXIT")) _exit(rc);
    exit(rc);  /* a normal exit, library destructors included */
}

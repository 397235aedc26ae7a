/* A plain C FMI 2.0 Co-Simulation host for the native linknet FMU: no Python in the process (the tests run it
 * under env -i with a PATH that has no Python). It loads binaries/linux64/<id>.so from an extracted FMU with
 * dlopen (tests/c_host/fmi2_host_api.h: the binary of the platform it is built for, with LoadLibraryA on Windows; the
 * FMI types are fmu_src/native/fmi2_api.h's) and runs one of:
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
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../c_host/fmi2_host_api.h"

static fmi2_host F;  /* the binary's functions, loaded by fmi2_host_open */
static const char *GUID;

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
    MUST(F.SetupExperiment(c, 0, 0.0, t0, 0, 0.0));
    MUST(F.EnterInitializationMode(c));
    if (detour && P.n_detour) {
        double ignored[MAX_VARS];
        MUST(F.SetReal(c, P.detour_vr, P.n_detour, P.detour));
        if (P.n_out) MUST(F.GetReal(c, P.out_vr, P.n_out, ignored));
    }
    if (P.method) {
        fmi2String m = P.method;
        MUST(F.SetString(c, &integrator_vr, 1, &m));
    }
    if (P.n_bool) MUST(F.SetBoolean(c, P.bool_vr, P.n_bool, P.bool_value));
    if (P.n_par) MUST(F.SetReal(c, P.par_vr, P.n_par, P.par));
    MUST(F.ExitInitializationMode(c));
}

static fmi2Component start(const char *name, double t0, fmi2CallbackFunctions *cb)
{
    fmi2Component c = F.Instantiate(name, fmi2CoSimulation, GUID, F.resources, cb, 0, 0);
    if (!c) {
        fprintf(stderr, "fmi2Instantiate failed: %s\n", last_log);
        exit(4);
    }
    if (P.n_bool || P.n_detour) {
        initialize(c, t0, 0);
        return c;
    }
    MUST(F.SetupExperiment(c, 0, 0.0, t0, 0, 0.0));
    MUST(F.EnterInitializationMode(c));
    if (P.method) {
        fmi2String m = P.method;
        MUST(F.SetString(c, &integrator_vr, 1, &m));
    }
    if (P.n_par) MUST(F.SetReal(c, P.par_vr, P.n_par, P.par));
    MUST(F.ExitInitializationMode(c));
    return c;
}

static void set_inputs(fmi2Component c, double t)
{
    double value[MAX_VARS];
    for (size_t j = 0; j < P.n_in; j++) value[j] = P.omega[j] == 0.0 ? P.amp[j] : P.amp[j] * cos(P.omega[j] * t);
    if (P.n_in) MUST(F.SetReal(c, P.in_vr, P.n_in, value));
}

/* N steps of h from t0, the outputs at every point into rows (N+1 rows of n_out) if given */
static void steps(fmi2Component c, double t0, long N, double h, long first, double *rows)
{
    for (long n = first; n <= N; n++) {
        const double t = t0 + (double)n * h;
        set_inputs(c, t);
        if (rows && P.n_out) MUST(F.GetReal(c, P.out_vr, P.n_out, rows + (size_t)(n - first) * P.n_out));
        if (n < N) MUST(F.DoStep(c, t, h, 1));
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
    MUST(F.Terminate(c));
    F.FreeInstance(c);
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
    MUST(F.GetFMUstate(c, &s));
    steps(c, 0.0, 2 * N, h, N, first);
    MUST(F.SetFMUstate(c, s));
    steps(c, 0.0, 2 * N, h, N, again);
    size_t size = 0;
    MUST(F.SerializedFMUstateSize(c, s, &size));
    fmi2Byte *bytes = malloc(size);
    MUST(F.SerializeFMUstate(c, s, bytes, size));
    fmi2Component d = start("fresh", 0.0, &callbacks);
    fmi2FMUstate s2 = NULL;
    MUST(F.DeSerializeFMUstate(d, bytes, size, &s2));
    MUST(F.SetFMUstate(d, s2));
    steps(d, 0.0, 2 * N, h, N, fresh);
    printf("replay_identical %d\nfresh_identical %d\nstate_bytes %zu\n", same(first, again, n_rows),
           same(first, fresh, n_rows), size);
    MUST(F.FreeFMUstate(c, &s));
    MUST(F.FreeFMUstate(d, &s2));
    F.FreeInstance(c);
    F.FreeInstance(d);
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
    fmi2Component c = F.Instantiate("rerun", fmi2CoSimulation, GUID, F.resources, &callbacks, 0, 0);
    if (!c) return 4;
    initialize(c, 0.0, 0);
    steps(c, 0.0, N, h, 0, fresh);
    MUST(F.Reset(c));
    initialize(c, 0.0, 0);
    steps(c, 0.0, N, h, 0, reset);
    fmi2Component d = F.Instantiate("detour", fmi2CoSimulation, GUID, F.resources, &callbacks, 0, 0);
    if (!d) return 4;
    initialize(d, 0.0, 1);
    steps(d, 0.0, N, h, 0, detour);
    printf("reset_identical %d\ndetour_identical %d\n", same(fresh, reset, n_rows), same(fresh, detour, n_rows));
    for (long n = 0; n <= N; n++) {
        printf("%.17g", (double)n * h);
        for (size_t j = 0; j < P.n_out; j++) printf(",%.17g", fresh[(size_t)n * P.n_out + j]);
        printf("\n");
    }
    F.FreeInstance(c);
    F.FreeInstance(d);
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
    F.FreeInstance(c);
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
    F.FreeInstance(c);
    /* interleaved: A's step, B's step, ...; B's inputs doubled between its points and put back: a state
       shared between instances would show up in A */
    fmi2Component ca = start("A", 0.0, &callbacks), cb = start("B", 0.0, &callbacks);
    double other[MAX_VARS];
    for (long n = 0; n <= N; n++) {
        const double t = (double)n * h;
        set_inputs(ca, t);
        for (size_t j = 0; j < P.n_in; j++) other[j] = 2.0 * P.amp[j] + 1.0;
        if (P.n_in) MUST(F.SetReal(cb, P.in_vr, P.n_in, other));
        if (P.n_out) MUST(F.GetReal(ca, P.out_vr, P.n_out, a + (size_t)n * per));
        if (P.n_out) MUST(F.GetReal(cb, P.out_vr, P.n_out, b + (size_t)n * per));
        if (n < N) {
            MUST(F.DoStep(cb, t, h, 1));
            MUST(F.DoStep(ca, t, h, 1));
        }
    }
    F.FreeInstance(ca);
    F.FreeInstance(cb);
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
    MUST(F.DoStep(c, 0.0, 0.01, 1));
    fmi2FMUstate s = NULL;
    MUST(F.GetFMUstate(c, &s));
    size_t size;
    MUST(F.SerializedFMUstateSize(c, s, &size));
    fmi2Byte *bytes = malloc(size);
    MUST(F.SerializeFMUstate(c, s, bytes, size));
    FILE *f = fopen(argv[5], "wb");
    if (!f || fwrite(bytes, 1, size, f) != size) return 4;
    fclose(f);
    free(bytes);
    MUST(F.FreeFMUstate(c, &s));
    F.FreeInstance(c);
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
    MUST(F.GetFMUstate(c, &s));
    double best_set = 1e300, best_step = 1e300;
    for (int r = 0; r < R; r++) {
        for (int with_set = 0; with_set < 2; with_set++) {
            MUST(F.SetFMUstate(c, s));
            double t = 0.0, value = 0.0;
            MUST(F.SetReal(c, &in, 1, &value));
            const double t0 = now();
            for (long i = 0; i < N; i++) {
                if (with_set) {
                    value = 0.1 * sin(0.37 * (double)i);
                    F.SetReal(c, &in, 1, &value);
                }
                if (F.DoStep(c, t, h, 1) != fmi2OK) exit(4);
                t += h;
            }
            const double per = (now() - t0) / (double)N;
            if (with_set && per < best_set) best_set = per;
            if (!with_set && per < best_step) best_step = per;
        }
    }
    printf("setreal_dostep %.1f\ndostep %.1f\n", 1e9 * best_set, 1e9 * best_step);
    MUST(F.FreeFMUstate(c, &s));
    F.FreeInstance(c);
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
    fmi2Component c = F.Instantiate("wrong_guid", fmi2CoSimulation, "{00000000-0000-0000-0000-000000000000}",
                                    F.resources, &callbacks, 0, 0);
    report("instantiate_wrong_guid", c == NULL ? fmi2Error : fmi2OK);
    c = F.Instantiate("me", fmi2ModelExchange, GUID, F.resources, &callbacks, 0, 0);
    report("instantiate_model_exchange", c == NULL ? fmi2Error : fmi2OK);
    c = F.Instantiate("null_guid", fmi2CoSimulation, NULL, F.resources, &callbacks, 0, 0);
    report("instantiate_null_guid", c == NULL ? fmi2Error : fmi2OK);

    c = F.Instantiate("contract", fmi2CoSimulation, GUID, F.resources, &callbacks, 0, 0);
    if (!c) return 4;
    report("step_before_initialization", F.DoStep(c, 0.0, 0.01, 1));
    report("set_start_time", F.SetupExperiment(c, 0, 0.0, 1.5, 0, 0.0));
    report("setup_nan_start", F.SetupExperiment(c, 0, 0.0, NAN, 0, 0.0));
    report("enter_initialization", F.EnterInitializationMode(c));
    report("step_in_initialization", F.DoStep(c, 1.5, 0.01, 1));
    report("setup_in_initialization", F.SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0));
    x = -1.0;
    report("set_mass_negative", F.SetReal(c, &vM, 1, &x));
    x = NAN;
    report("set_mass_nan", F.SetReal(c, &vM, 1, &x));
    x = 5.0;
    report("set_tolerance_5", F.SetReal(c, &vTol, 1, &x));
    x = 1e-20;
    report("set_tolerance_tiny", F.SetReal(c, &vTol, 1, &x));
    x = 0.0;
    report("set_step_zero", F.SetReal(c, &vStep, 1, &x));
    F.GetReal(c, &vR, 1, &v);
    x = 1.5 * v;
    report("set_length_misfit", F.SetReal(c, &vR, 1, &x));
    {
        fmi2ValueReference vrs[2] = {vF, vX};
        double xs[2] = {1.0, 2.0};
        report("set_output_in_batch", F.SetReal(c, vrs, 2, xs));
        F.GetReal(c, &vF, 1, &v);
        printf("VALUE input_after_refused_batch %.17g\n", v);
    }
    report("set_unknown_vr", F.SetReal(c, &bad_vr, 1, &x));
    report("get_unknown_vr", F.GetReal(c, &bad_vr, 1, &v));
    report("get_null_vr", F.GetReal(c, NULL, 1, &v));
    {
        fmi2Integer iv;
        fmi2Boolean bv;
        fmi2String sv;
        report("get_integer", F.GetInteger(c, &vF, 1, &iv));
        report("set_integer", F.SetInteger(c, &vF, 1, &iv));
        report("get_boolean", F.GetBoolean(c, &vF, 1, &bv));
        report("get_string_of_real", F.GetString(c, &vF, 1, &sv));
        fmi2String name = "rk99";
        fmi2ValueReference vs = vStep + 1;  /* the String parameter follows the Reals */
        report("set_integrator_unknown", F.SetString(c, &vs, 1, &name));
        fmi2String good = "dop853";
        report("set_integrator_dop853", F.SetString(c, &vs, 1, &good));
        report("get_integrator", F.GetString(c, &vs, 1, &sv));
        printf("VALUE integrator %s\n", sv);
    }
    report("exit_initialization", F.ExitInitializationMode(c));
    F.GetReal(c, &vX, 1, &v);
    report("get_time_start", F.GetRealStatus(c, fmi2LastSuccessfulTime, &x));
    printf("VALUE time_after_init %.17g\n", x);
    x = NAN;
    report("set_input_nan", F.SetReal(c, &vF, 1, &x));
    x = INFINITY;
    report("set_input_inf", F.SetReal(c, &vF, 1, &x));
    report("set_output", F.SetReal(c, &vX, 1, &x));
    F.GetReal(c, &vM, 1, &v);
    report("set_parameter_same_after_init", F.SetReal(c, &vM, 1, &v));
    x = 2.0 * v;
    report("set_parameter_after_init", F.SetReal(c, &vM, 1, &x));
    report("step_negative_h", F.DoStep(c, 1.5, -0.01, 1));
    report("step_zero_h", F.DoStep(c, 1.5, 0.0, 1));
    report("step_nan_h", F.DoStep(c, 1.5, NAN, 1));
    report("step_wrong_t", F.DoStep(c, 0.0, 0.01, 1));
    report("step_ok", F.DoStep(c, 1.5, 0.01, 1));
    report("step_sub_ulp", F.DoStep(c, 1.51, 1e-300, 1));
    x = 1e300;
    report("set_input_beyond_limit", F.SetReal(c, &vF, 1, &x));
    x = 1e90;
    report("set_input_huge", F.SetReal(c, &vF, 1, &x));
    s = F.DoStep(c, 1.51, 0.01, 1);
    report("step_with_huge_input", s);
    F.GetRealStatus(c, fmi2LastSuccessfulTime, &x);
    printf("VALUE time_after_discard %.17g\n", x);
    x = 0.0;
    report("set_input_zero", F.SetReal(c, &vF, 1, &x));
    report("step_after_discard", F.DoStep(c, 1.51, 0.01, 1));
    report("get_tension", F.GetReal(c, &vT, 1, &v));
    printf("VALUE tension_finite %d\n", isfinite(v) ? 1 : 0);

    /* FMU states */
    fmi2FMUstate st = NULL;
    report("get_state", F.GetFMUstate(c, &st));
    report("get_state_null", F.GetFMUstate(c, NULL));
    {
        double garbage_words[64];
        for (int i = 0; i < 64; i++) garbage_words[i] = (double)i * 1.25;
        report("set_state_garbage", F.SetFMUstate(c, (fmi2FMUstate)garbage_words));
        report("set_state_null", F.SetFMUstate(c, NULL));
        fmi2FMUstate g = NULL;
        report("deserialize_garbage",
               F.DeSerializeFMUstate(c, (const fmi2Byte *)garbage_words, sizeof garbage_words, &g));
        size_t size = 0;
        F.SerializedFMUstateSize(c, st, &size);
        fmi2Byte *bytes = malloc(size);
        F.SerializeFMUstate(c, st, bytes, size);
        report("deserialize_truncated", F.DeSerializeFMUstate(c, bytes, size / 2, &g));
        bytes[size - 9] ^= 0x7f;  /* a bit flipped in the payload: the header is intact */
        fmi2FMUstate flipped = NULL;
        report("deserialize_flipped_payload", F.DeSerializeFMUstate(c, bytes, size, &flipped));
        if (flipped) F.FreeFMUstate(c, &flipped);
        bytes[size - 9] ^= 0x7f;
        bytes[12] ^= 0x01;  /* the byte order mark */
        report("deserialize_other_byte_order", F.DeSerializeFMUstate(c, bytes, size, &g));
        free(bytes);
    }
    {
        FILE *f = foreign[0] ? fopen(foreign, "rb") : NULL;
        if (f) {
            static fmi2Byte buffer[1 << 22];
            const size_t n = fread(buffer, 1, sizeof buffer, f);
            fclose(f);
            fmi2FMUstate g = NULL;
            report("deserialize_foreign", F.DeSerializeFMUstate(c, buffer, n, &g));
        }
    }
    report("set_state_own", F.SetFMUstate(c, st));
    report("free_state", F.FreeFMUstate(c, &st));
    report("free_state_again", F.FreeFMUstate(c, &st));  /* NULL after the first: a no-op */

    /* usable after all of it, and again after a reset */
    F.GetRealStatus(c, fmi2LastSuccessfulTime, &x);
    report("step_at_end", F.DoStep(c, x, 0.01, 1));
    report("terminate", F.Terminate(c));
    report("step_after_terminate", F.DoStep(c, x + 0.01, 0.01, 1));
    report("reset", F.Reset(c));
    F.GetReal(c, &vM, 1, &v);
    printf("VALUE mass_after_reset %.17g\n", v);
    report("setup_after_reset", F.SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0));
    report("enter_after_reset", F.EnterInitializationMode(c));
    report("exit_after_reset", F.ExitInitializationMode(c));
    report("step_after_reset", F.DoStep(c, 0.0, 0.01, 1));
    report("debug_logging_unknown_category", F.SetDebugLogging(c, 1, 1, (const fmi2String[]){"logNothing"}));
    report("null_component_step", F.DoStep(NULL, 0.0, 0.01, 1));
    F.FreeInstance(NULL);
    F.FreeInstance(c);
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
        MUST(F.DoStep(c, 0.0, 0.01, 1));
        fmi2FMUstate s = NULL;
        MUST(F.GetFMUstate(c, &s));
        MUST(F.FreeFMUstate(c, &s));
        F.FreeInstance(c);
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
    fmi2_host_open(&F, argv[2], argv[3]);
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
        MUST(F.DoStep(c, 0.0, h, 1));
        const double t1 = now();
        printf("dlopen %.9f\ninstantiate_to_first_step %.9f\n", t_loaded - t_load, t1 - t0);
        F.FreeInstance(c);
        rc = 0;
    } else {
        rc = 2;
    }
    fflush(stdout);
    if (getenv("NATIVE_HOST_FAST_EXIT")) _exit(rc);
    exit(rc);  /* a normal exit, library destructors included */
}

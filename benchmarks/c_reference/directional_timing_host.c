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
 * benchmarks/bench_fmu_directional.py (cc -O2 ... -ldl). Loading, callbacks and the status check are
 * tests/c_host/fmi2_host_api.h's, as every C host's.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../tests/c_host/fmi2_host_api.h"

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#define CHECK(call) FMI2_HOST_CHECK(call, 4)

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

    fmi2_host fmu;
    fmi2_host_open(&fmu, dir, id);
    fmi2Component c = fmi2_host_instantiate(&fmu, "directional_timing_host", guid, fmi2False);
    if (!c) {
        fprintf(stderr, "fmi2Instantiate failed\n");
        return 4;
    }
    CHECK(fmu.SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0));
    CHECK(fmu.EnterInitializationMode(c));
    CHECK(fmu.ExitInitializationMode(c));
    fmi2FMUstate initial = NULL;
    CHECK(fmu.GetFMUstate(c, &initial));

    double best[3] = {INFINITY, INFINITY, INFINITY};
    for (long r = 0; r <= rounds; r++) {  /* round 0 untimed: the first calls load and warm up */
        CHECK(fmu.SetFMUstate(c, initial));
        double t = 0.0;
        const double t0 = now();
        for (long i = 0; i < N; i++, t += h) CHECK(fmu.DoStep(c, t, h, 1));
        const double dostep = (now() - t0) / (double)N;
        CHECK(fmu.SetFMUstate(c, initial));
        t = 0.0;
        double first = 0.0, next = 0.0;
        for (long i = 0; i < N; i++, t += h) {
            CHECK(fmu.DoStep(c, t, h, 1));
            const double a = now();
            CHECK(fmu.GetDirectionalDerivative(c, unknown, n_unknown, &known, 1, &seed, derivative));
            const double b = now();
            CHECK(fmu.GetDirectionalDerivative(c, unknown, n_unknown, &known, 1, &seed, derivative));
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

/* Minimal FMI 2.0 Co-Simulation host in plain C: no Python in the process.
 *
 * Loads <fmu_dir>/binaries/linux64/<id>.so from an extracted FMU with dlopen, runs
 * fixed communication steps and prints one CSV line per communication point.
 *
 *   fmi2_host FMU_DIR MODEL_ID GUID T_END H [in:VR=VALUE ...] [out:VR ...]
 *
 * Exit codes: 0 ok, 2 usage, 3 load error, 4 an FMI call failed (status printed).
 * Used by tests/fmu/test_fmu_c_host.py, which compiles it with the system C compiler. The loading, callbacks and
 * status check are fmi2_host_api.h's, shared with the benchmarks' C hosts.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2_host_api.h"

#define CHECK(call) FMI2_HOST_CHECK(call, 4)

int main(int argc, char **argv) {
    if (argc < 6) {
        fprintf(stderr, "usage: %s FMU_DIR MODEL_ID GUID T_END H [in:VR=VALUE ...] [out:VR ...]\n", argv[0]);
        return 2;
    }
    const char *dir = argv[1], *id = argv[2], *guid = argv[3];
    double t_end = atof(argv[4]), h = atof(argv[5]);
    fmi2ValueReference in_vr[4096], out_vr[4096];
    fmi2Real in_val[4096], out_val[4096];
    size_t n_in = 0, n_out = 0;
    for (int i = 6; i < argc; i++) {
        if (strncmp(argv[i], "in:", 3) == 0 && n_in < 4096) {
            char *eq = strchr(argv[i], '=');
            if (!eq) return 2;
            in_vr[n_in] = (fmi2ValueReference)strtoul(argv[i] + 3, NULL, 10);
            in_val[n_in++] = atof(eq + 1);
        } else if (strncmp(argv[i], "out:", 4) == 0 && n_out < 4096) {
            out_vr[n_out++] = (fmi2ValueReference)strtoul(argv[i] + 4, NULL, 10);
        } else {
            return 2;
        }
    }
    fmi2_host fmu;
    fmi2_host_open(&fmu, dir, id);
    fmi2Component c = fmi2_host_instantiate(&fmu, "c_host", guid, fmi2True);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 4; }
    CHECK(fmu.SetupExperiment(c, 0, 0.0, 0.0, 1, t_end));
    CHECK(fmu.EnterInitializationMode(c));
    if (n_in) CHECK(fmu.SetReal(c, in_vr, n_in, in_val));
    CHECK(fmu.ExitInitializationMode(c));

    long n_steps = (long)(t_end / h + 0.5);
    for (long n = 0; n <= n_steps; n++) {
        double t = n * h;
        if (n_out) CHECK(fmu.GetReal(c, out_vr, n_out, out_val));
        printf("%.17g", t);
        for (size_t j = 0; j < n_out; j++) printf(",%.17g", out_val[j]);
        printf("\n");
        if (n < n_steps) CHECK(fmu.DoStep(c, t, h, 1));
    }
    fflush(stdout);
    CHECK(fmu.Terminate(c));
    fmu.FreeInstance(c);
    /* pythonfmu 0.7.0 may corrupt the heap while finalizing Python at exit (docs/fmu.md):
       every result is flushed above, so leave without running library destructors. */
    _exit(0);
}

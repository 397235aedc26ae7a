/* The plainest FMI 2.0 Co-Simulation host: linked with libc and libdl only (no libm in the process, as a C host that
 * does no floating-point math of its own), so an FMU binary that needs libm must say so itself (a DT_NEEDED entry).
 *
 *   bare_host LIBRARY ID GUID N H VR [RESOURCES]
 *       dlopen(LIBRARY), N doSteps of H from 0, print VR's value after each (%a). RESOURCES: the fmuResourceLocation
 *       (a file: URI of the unzipped FMU's resources folder, where the FMU reads its scene); without it, the
 *       resources folder of the FMU LIBRARY lies in (LIBRARY is <FMU>/binaries/<platform>/<ID>.so)
 *
 * Exit codes: 0 ok, 2 usage, 3 load error (dlerror on stderr), 4 an FMI call failed. The binary and its functions are
 * loaded by tests/c_host/fmi2_host_api.h (fmi2_host_load), the FMI types are fmu_src/native/fmi2_api.h's.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../c_host/fmi2_host_api.h"

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env, (void)instance, (void)category;
    fprintf(stderr, "log %d: %s\n", (int)status, message);
}

int main(int argc, char **argv)
{
    if (argc != 7 && argc != 8) {
        fprintf(stderr, "usage: %s LIBRARY ID GUID N H VR [RESOURCES]\n", argv[0]);
        return 2;
    }
    char resources[4200];
    if (argc == 8) {
        snprintf(resources, sizeof resources, "%s", argv[7]);
    } else {
        snprintf(resources, sizeof resources, "file://%s", argv[1]);
        char *binaries = strstr(resources, "/binaries/");
        if (binaries) strcpy(binaries, "/resources");
    }
    fmi2_host F;
    fmi2_host_load(&F, argv[1], resources);
    const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = F.Instantiate(argv[2], fmi2CoSimulation, argv[3], F.resources, &callbacks, fmi2False, fmi2False);
    const int n = atoi(argv[4]);
    const double h = strtod(argv[5], NULL);
    const fmi2ValueReference vr = (fmi2ValueReference)strtoul(argv[6], NULL, 10);
    if (!c || F.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK
        || F.EnterInitializationMode(c) != fmi2OK || F.ExitInitializationMode(c) != fmi2OK)
        return 4;
    for (int i = 0; i < n; i++) {
        fmi2Real value;
        if (F.DoStep(c, i * h, h, fmi2True) != fmi2OK || F.GetReal(c, &vr, 1, &value) != fmi2OK) return 4;
        printf("%a\n", value);
    }
    F.FreeInstance(c);
    return 0;
}

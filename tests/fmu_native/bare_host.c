/* The plainest FMI 2.0 Co-Simulation host: linked with libc and libdl only (no libm in the process, as a C host that
 * does no floating-point math of its own), so an FMU binary that needs libm must say so itself (a DT_NEEDED entry).
 *
 *   bare_host LIBRARY ID GUID N H VR [RESOURCES]
 *       dlopen(LIBRARY), N doSteps of H from 0, print VR's value after each (%a). RESOURCES: the fmuResourceLocation
 *       (a file: URI of the unzipped FMU's resources folder, where the FMU reads its scene); without it, the
 *       resources folder of the FMU LIBRARY lies in (LIBRARY is <FMU>/binaries/<platform>/<ID>.so)
 *
 * Exit codes: 0 ok, 2 usage, 3 load error (dlerror on stderr), 4 an FMI call failed.
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void *(*instantiate_t)(const char *, int, const char *, const char *, const void *, int, int);
typedef int (*component_t)(void *);
typedef int (*setup_t)(void *, int, double, double, int, double);
typedef int (*do_step_t)(void *, double, double, int);
typedef int (*get_real_t)(void *, const unsigned *, size_t, double *);
typedef void (*free_t)(void *);

static void logger(void *env, const char *instance, int status, const char *category, const char *message, ...)
{
    (void)env, (void)instance, (void)category;
    fprintf(stderr, "log %d: %s\n", status, message);
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
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen failed: %s\n", dlerror());
        return 3;
    }
    instantiate_t instantiate;
    component_t enter, leave;
    setup_t setup;
    do_step_t do_step;
    get_real_t get_real;
    free_t free_instance;
    *(void **)&instantiate = dlsym(lib, "fmi2Instantiate");
    *(void **)&setup = dlsym(lib, "fmi2SetupExperiment");
    *(void **)&enter = dlsym(lib, "fmi2EnterInitializationMode");
    *(void **)&leave = dlsym(lib, "fmi2ExitInitializationMode");
    *(void **)&do_step = dlsym(lib, "fmi2DoStep");
    *(void **)&get_real = dlsym(lib, "fmi2GetReal");
    *(void **)&free_instance = dlsym(lib, "fmi2FreeInstance");
    if (!instantiate || !setup || !enter || !leave || !do_step || !get_real || !free_instance) {
        fprintf(stderr, "missing an fmi2 function\n");
        return 3;
    }
    struct { void *logger, *allocate, *free, *step_finished, *env; } callbacks = {(void *)logger, (void *)calloc,
                                                                               (void *)free, NULL, NULL};
    void *c = instantiate(argv[2], 1, argv[3], resources, &callbacks, 0, 0);
    const int n = atoi(argv[4]);
    const double h = strtod(argv[5], NULL);
    const unsigned vr = (unsigned)strtoul(argv[6], NULL, 10);
    if (!c || setup(c, 0, 0.0, 0.0, 0, 0.0) || enter(c) || leave(c)) return 4;
    for (int i = 0; i < n; i++) {
        double value;
        if (do_step(c, i * h, h, 1) || get_real(c, &vr, 1, &value)) return 4;
        printf("%a\n", value);
    }
    free_instance(c);
    return 0;
}

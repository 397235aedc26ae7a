/* A plain C host of the native FMI 3.0 FMU (tests/fmu_native/test_fmi3.py): no Python in its process. It loads the
 * binary with dlopen, runs a few communication steps with force inputs, saves, serializes and restores a state,
 * makes bad calls, and instantiates and frees the FMU again and again; it prints the positions after each step as
 * hexadecimal floats (exact) and the number of messages logged with fmi3Error status.
 *
 *   fmi3_host BINARY TOKEN VR_F N_F VR_X N_X STEPS CYCLES
 *
 * BINARY lies in the unzipped FMU (<FMU>/binaries/<platform>/<id>.so): its resourcePath is <FMU>/resources/, where
 * the FMU reads its scene.
 */
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

static int errors_logged;

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    if (status == fmi3Error) errors_logged++;
    fprintf(stderr, "[%d %s] %s\n", (int)status, category, message);
}

/* the forces of test_fmi3.py's forces(n, t), in the same operations */
static void forces(double *F, size_t n, double t)
{
    for (size_t j = 0; j < n; j++) F[j] = 0.4 * sin(1.3 * (double)(j + 1) + 7.0 * t) + 0.1;
}

#define LOAD(name)                                                                                                 \
    name##TYPE *name = (name##TYPE *)dlsym(lib, #name);                                                            \
    if (name == NULL) {                                                                                            \
        fprintf(stderr, "missing %s\n", #name);                                                                    \
        return 2;                                                                                                  \
    }

#define CHECK(call, expected)                                                                                      \
    do {                                                                                                           \
        fmi3Status s_ = (call);                                                                                    \
        if (s_ != (expected)) {                                                                                    \
            fprintf(stderr, "%s:%d: %s returned %d, expected %d\n", __FILE__, __LINE__, #call, (int)s_,             \
                    (int)(expected));                                                                              \
            return 3;                                                                                              \
        }                                                                                                          \
    } while (0)

int main(int argc, char **argv)
{
    if (argc != 9) {
        fprintf(stderr, "usage: fmi3_host BINARY TOKEN VR_F N_F VR_X N_X STEPS CYCLES\n");
        return 1;
    }
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
        return 2;
    }
    LOAD(fmi3InstantiateCoSimulation)
    LOAD(fmi3FreeInstance)
    LOAD(fmi3EnterInitializationMode)
    LOAD(fmi3ExitInitializationMode)
    LOAD(fmi3SetFloat64)
    LOAD(fmi3GetFloat64)
    LOAD(fmi3DoStep)
    LOAD(fmi3GetFMUState)
    LOAD(fmi3SetFMUState)
    LOAD(fmi3FreeFMUState)
    LOAD(fmi3SerializedFMUStateSize)
    LOAD(fmi3SerializeFMUState)
    LOAD(fmi3DeserializeFMUState)
    char resources[4200];
    snprintf(resources, sizeof resources, "%s", argv[1]);
    char *binaries = strstr(resources, "/binaries/");
    if (binaries == NULL) {
        fprintf(stderr, "%s is not in an unzipped FMU's binaries/\n", argv[1]);
        return 1;
    }
    strcpy(binaries, "/resources/");
    const char *token = argv[2];
    const fmi3ValueReference vr_F = (fmi3ValueReference)atoi(argv[3]), vr_X = (fmi3ValueReference)atoi(argv[5]);
    const size_t n_F = (size_t)atoi(argv[4]), n_X = (size_t)atoi(argv[6]);
    const int steps = atoi(argv[7]), cycles = atoi(argv[8]);
    const double h = 0.01;
    double *F = calloc(n_F, sizeof *F), *X = calloc(n_X, sizeof *X), *X_again = calloc(n_X, sizeof *X_again);
    fmi3Boolean event, terminate, early;
    fmi3Float64 last;

    for (int cycle = 0; cycle < cycles; cycle++) {
        fmi3Instance c = fmi3InstantiateCoSimulation("host", token, resources, fmi3False, fmi3False, fmi3False, fmi3False,
                                                     NULL, 0, NULL, logger, NULL);
        if (c == NULL) return 4;
        CHECK(fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0), fmi3OK);
        CHECK(fmi3ExitInitializationMode(c), fmi3OK);
        fmi3FMUState state = NULL;
        for (int n = 0; n < steps; n++) {
            forces(F, n_F, n * h);
            CHECK(fmi3SetFloat64(c, &vr_F, 1, F, n_F), fmi3OK);
            if (n == 1) CHECK(fmi3GetFMUState(c, &state), fmi3OK);
            CHECK(fmi3DoStep(c, n * h, h, fmi3True, &event, &terminate, &early, &last), fmi3OK);
            CHECK(fmi3GetFloat64(c, &vr_X, 1, X, n_X), fmi3OK);
            if (cycle == 0)
                for (size_t j = 0; j < n_X; j++) printf("%a%c", X[j], j + 1 < n_X ? ',' : '\n');
        }
        /* the state of step 1, serialized and restored into the same instance, replays the last steps */
        size_t size = 0;
        CHECK(fmi3SerializedFMUStateSize(c, state, &size), fmi3OK);
        fmi3Byte *bytes = malloc(size);
        CHECK(fmi3SerializeFMUState(c, state, bytes, size), fmi3OK);
        CHECK(fmi3FreeFMUState(c, &state), fmi3OK);
        fmi3FMUState restored = NULL;
        CHECK(fmi3DeserializeFMUState(c, bytes, size, &restored), fmi3OK);
        CHECK(fmi3SetFMUState(c, restored), fmi3OK);
        for (int n = 1; n < steps; n++) {
            forces(F, n_F, n * h);
            CHECK(fmi3SetFloat64(c, &vr_F, 1, F, n_F), fmi3OK);
            CHECK(fmi3DoStep(c, n * h, h, fmi3True, &event, &terminate, &early, &last), fmi3OK);
        }
        CHECK(fmi3GetFloat64(c, &vr_X, 1, X_again, n_X), fmi3OK);
        if (memcmp(X, X_again, n_X * sizeof *X) != 0) {
            fprintf(stderr, "the restored state does not replay the run\n");
            return 5;
        }
        /* bad calls: refused, logged, nothing changed; the restored state is left for fmi3FreeInstance */
        CHECK(fmi3SetFloat64(c, &vr_F, 1, F, n_F + 1), fmi3Error);
        CHECK(fmi3DoStep(c, 0.5, h, fmi3True, &event, &terminate, &early, &last), fmi3Error);
        CHECK(fmi3DoStep(c, steps * h, h, fmi3True, NULL, &terminate, &early, &last), fmi3Error);
        CHECK(fmi3SetFMUState(c, bytes), fmi3Error);
        CHECK(fmi3FreeFMUState(c, (fmi3FMUState *)restored), fmi3Error);
        bytes[size - 1] ^= 1;
        fmi3FMUState damaged = NULL;
        CHECK(fmi3DeserializeFMUState(c, bytes, size, &damaged), fmi3Error);
        CHECK(fmi3DeserializeFMUState(c, bytes, 3, &damaged), fmi3Error);
        free(bytes);
        fmi3FreeInstance(c);
    }
    printf("errors logged %d\n", errors_logged);
    free(F);
    free(X);
    free(X_again);
    dlclose(lib);
    return 0;
}

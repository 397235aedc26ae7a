/* What every plain-C FMI 2.0 Co-Simulation host of the tests and benchmarks shares: loading an extracted FMU's
 * binary and its function table, the callbacks, the logger and the check of a call's status. The hosts include this
 * file and nothing else of the FMI; tests/c_host/fmi2_host.c, tests/fmu_native/state_handle_host.c,
 * benchmarks/c_reference/fmi2_timing_host.c and
 * benchmarks/c_reference/directional_timing_host.c.
 *
 * The FMI 2.0 types and the functions' argument lists are those of fmu_src/native/fmi2_api.h, the header both FMU
 * kinds are compiled with: the table's pointer types are taken from its declarations (__typeof__, which GCC and
 * Clang provide in every C mode), so that no type or argument list is written a second time here. Its relative
 * include keeps the hosts' compile commands as they are (cc -O2 -Wall host.c -ldl).
 */
#ifndef LINKNET_FMI2_HOST_API_H
#define LINKNET_FMI2_HOST_API_H

#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../fmu_src/native/fmi2_api.h"

/* Every function of the FMI 2.0 Co-Simulation interface (a conforming binary exports all of them, supported or
   not), by its name without the "fmi2" prefix. */
#define FMI2_HOST_FUNCTIONS(X)                                                                                    \
    X(GetTypesPlatform) X(GetVersion) X(SetDebugLogging) X(Instantiate) X(FreeInstance) X(SetupExperiment)        \
    X(EnterInitializationMode) X(ExitInitializationMode) X(Terminate) X(Reset) X(GetReal) X(GetInteger)           \
    X(GetBoolean) X(GetString) X(SetReal) X(SetInteger) X(SetBoolean) X(SetString) X(GetFMUstate) X(SetFMUstate)  \
    X(FreeFMUstate) X(SerializedFMUstateSize) X(SerializeFMUstate) X(DeSerializeFMUstate)                        \
    X(GetDirectionalDerivative) X(SetRealInputDerivatives) X(GetRealOutputDerivatives) X(DoStep) X(CancelStep)   \
    X(GetStatus) X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus) X(GetStringStatus)

/* One loaded FMU binary: host.DoStep(c, t, h, fmi2True), ... */
typedef struct {
    void *library;           /* dlopen's handle, for anything else a host looks up in the binary */
    char resources[4096];    /* the resource location fmi2Instantiate takes: file://FMU_DIR/resources */
#define FMI2_HOST_POINTER(name) __typeof__(&fmi2##name) name;
    FMI2_HOST_FUNCTIONS(FMI2_HOST_POINTER)
#undef FMI2_HOST_POINTER
} fmi2_host;

/* Every message on stderr, with its instance, status and category (the FMU filters by its loggingOn). */
static inline void fmi2_host_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                                    fmi2String category, fmi2String message, ...)
{
    (void)env;
    fprintf(stderr, "[%s] status %d %s: %s\n", instance, (int)status, category ? category : "", message);
}

/* unused in a host with a logger of its own (a -Werror build warns of an unused static otherwise) */
static const fmi2CallbackFunctions fmi2_host_callbacks __attribute__((unused)) = {fmi2_host_logger, calloc, free,
                                                                                 NULL, NULL};

/* <fmu_dir>/binaries/linux64/<model_id>.so of an extracted FMU, every function looked up. Exits with status 3 (the
   hosts' load error) where the binary does not load or lacks a function, naming it. */
static inline void fmi2_host_open(fmi2_host *host, const char *fmu_dir, const char *model_id)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", fmu_dir, model_id);
    snprintf(host->resources, sizeof host->resources, "file://%s/resources", fmu_dir);
    host->library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!host->library) {
        fprintf(stderr, "dlopen failed: %s\n", dlerror());
        exit(3);
    }
    /* POSIX's way to a function pointer from dlsym's void *, which ISO C does not convert by a cast */
#define FMI2_HOST_LOOKUP(name)                                                  \
    {                                                                           \
        void *function = dlsym(host->library, "fmi2" #name);                   \
        if (!function) {                                                        \
            fprintf(stderr, "missing symbol %s\n", "fmi2" #name);              \
            exit(3);                                                            \
        }                                                                       \
        memcpy(&host->name, &function, sizeof function);                        \
    }
    FMI2_HOST_FUNCTIONS(FMI2_HOST_LOOKUP)
#undef FMI2_HOST_LOOKUP
}

/* fmi2Instantiate of a co-simulation instance with the shared callbacks (not visible). */
static inline fmi2Component fmi2_host_instantiate(const fmi2_host *host, const char *instance, const char *guid,
                                                  fmi2Boolean logging_on)
{
    return host->Instantiate(instance, fmi2CoSimulation, guid, host->resources, &fmi2_host_callbacks, fmi2False,
                             logging_on);
}

/* Whether a call failed (a status beyond fmi2Warning), said on stderr with the call's text. */
static inline int fmi2_host_failed(fmi2Status status, const char *call)
{
    if (status <= fmi2Warning) return 0;
    fprintf(stderr, "%s failed with status %d\n", call, (int)status);
    return 1;
}

/* Return `result` from the calling function where `call` failed. */
#define FMI2_HOST_CHECK(call, result)                       \
    do {                                                    \
        if (fmi2_host_failed((call), #call)) return result; \
    } while (0)

#endif

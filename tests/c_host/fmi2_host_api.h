/* What every plain-C FMI 2.0 Co-Simulation host of the tests and benchmarks shares: loading an FMU's binary and its
 * function table, the callbacks, the logger and the check of a call's status. The hosts include this file and
 * nothing else of the FMI: tests/c_host/fmi2_host.c, tests/fmu_native/state_handle_host.c, native_host.c (also
 * cross-built for Windows and aarch64-linux), bare_host.c, benchmarks/c_reference/fmi2_timing_host.c and
 * benchmarks/c_reference/directional_timing_host.c.
 *
 * The FMI 2.0 types and the functions' argument lists are those of fmu_src/native/fmi2_api.h, the header both FMU
 * kinds are compiled with: the table's pointer types are taken from its declarations (__typeof__, which GCC and
 * Clang provide in every C mode), so that no type or argument list is written a second time here. Its relative
 * include keeps the hosts' compile commands as they are (cc -O2 -Wall host.c -ldl).
 *
 * The binary is opened with dlopen, or on Windows with LoadLibraryA. An extracted FMU's is
 * binaries/FMU_PLATFORM_FOLDER/<model id>FMU_LIBRARY_SUFFIX: linux64 and .so, win64 and .dll on Windows, unless the
 * host's build defines both (a host cross-built for aarch64-linux: -DFMU_PLATFORM_FOLDER='"aarch64-linux"'
 * -DFMU_LIBRARY_SUFFIX='".so"').
 */
#ifndef LINKNET_FMI2_HOST_API_H
#define LINKNET_FMI2_HOST_API_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef FMI2_Export
#define FMI2_Export /* the functions are the FMU's; a host imports them by name and declares nothing exported */
#endif
#include "../../fmu_src/native/fmi2_api.h"

#if !defined(FMU_PLATFORM_FOLDER) || !defined(FMU_LIBRARY_SUFFIX)
#ifdef _WIN32
#define FMU_PLATFORM_FOLDER "win64"
#define FMU_LIBRARY_SUFFIX ".dll"
#else
#define FMU_PLATFORM_FOLDER "linux64"
#define FMU_LIBRARY_SUFFIX ".so"
#endif
#endif

/* Opening a library, looking up a name in it and the last failure, in words: dlopen's, or on Windows LoadLibraryA's,
   declared here rather than through <windows.h>, whose GUID type would clash with the hosts' variables of that
   name. */
#ifdef _WIN32
__declspec(dllimport) void *__stdcall LoadLibraryA(const char *name);
__declspec(dllimport) void *__stdcall GetProcAddress(void *module, const char *name);
__declspec(dllimport) unsigned long __stdcall GetLastError(void);
static char fmi2_host_load_failure[4400];
static inline void *fmi2_host_dlopen(const char *path)
{
    char native[4096];  /* with the backslashes LoadLibraryA wants */
    snprintf(native, sizeof native, "%s", path);
    for (char *c = native; *c; c++)
        if (*c == '/') *c = '\\';
    void *module = LoadLibraryA(native);
    if (!module)
        snprintf(fmi2_host_load_failure, sizeof fmi2_host_load_failure, "LoadLibraryA(%s) failed: error %lu", native,
                 GetLastError());
    return module;
}
static inline void *fmi2_host_dlsym(void *module, const char *name) { return GetProcAddress(module, name); }
static inline const char *fmi2_host_dlerror(void) { return fmi2_host_load_failure; }
#else
#include <dlfcn.h>
static inline void *fmi2_host_dlopen(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static inline void *fmi2_host_dlsym(void *library, const char *name) { return dlsym(library, name); }
static inline const char *fmi2_host_dlerror(void) { return dlerror(); }
#endif

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
    void *library;           /* the library's handle (fmi2_host_dlsym looks up anything else in it) */
    char resources[4200];    /* the resource location fmi2Instantiate takes: file://FMU_DIR/resources */
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

/* The FMU binary at `path` (any library: an extracted FMU's, or one built elsewhere), every function looked up, with
   `resources` as the resource location fmi2Instantiate is given. Exits with status 3 (the hosts' load error) where
   the binary does not load or lacks a function, naming it. */
static inline void fmi2_host_load(fmi2_host *host, const char *path, const char *resources)
{
    snprintf(host->resources, sizeof host->resources, "%s", resources);
    host->library = fmi2_host_dlopen(path);
    if (!host->library) {
        fprintf(stderr, "dlopen failed: %s\n", fmi2_host_dlerror());
        exit(3);
    }
    /* POSIX's way to a function pointer from dlsym's void *, which ISO C does not convert by a cast */
#define FMI2_HOST_LOOKUP(name)                                                  \
    {                                                                           \
        void *function = fmi2_host_dlsym(host->library, "fmi2" #name);         \
        if (!function) {                                                        \
            fprintf(stderr, "missing symbol %s\n", "fmi2" #name);              \
            exit(3);                                                            \
        }                                                                       \
        memcpy(&host->name, &function, sizeof function);                        \
    }
    FMI2_HOST_FUNCTIONS(FMI2_HOST_LOOKUP)
#undef FMI2_HOST_LOOKUP
}

/* The binary of the extracted FMU in fmu_dir (binaries/FMU_PLATFORM_FOLDER/<model_id>FMU_LIBRARY_SUFFIX), with its
   resources folder as the resource location (file://fmu_dir/resources), as fmi2_host_load. */
static inline void fmi2_host_open(fmi2_host *host, const char *fmu_dir, const char *model_id)
{
    char path[4096], resources[4200];
    snprintf(path, sizeof path, "%s/binaries/%s/%s%s", fmu_dir, FMU_PLATFORM_FOLDER, model_id, FMU_LIBRARY_SUFFIX);
    snprintf(resources, sizeof resources, "file://%s/resources", fmu_dir);
    fmi2_host_load(host, path, resources);
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

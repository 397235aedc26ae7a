/* Minimal FMI 2.0 Co-Simulation host in plain C: no Python in the process.
 *
 * Loads <fmu_dir>/binaries/linux64/<id>.so from an extracted FMU with dlopen, runs
 * fixed communication steps and prints one CSV line per communication point.
 *
 *   fmi2_host FMU_DIR MODEL_ID GUID T_END H [in:VR=VALUE ...] [out:VR ...]
 *
 * Exit codes: 0 ok, 2 usage, 3 load error, 4 an FMI call failed (status printed).
 * Used by tests/test_fmu_c_host.py, which compiles it with the system C compiler.
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef struct {
    void (*logger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef fmi2Component (*Instantiate_t)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                       const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef fmi2Status (*SetupExperiment_t)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
typedef fmi2Status (*Simple_t)(fmi2Component);
typedef void (*FreeInstance_t)(fmi2Component);
typedef fmi2Status (*GetSetReal_t)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
typedef fmi2Status (*DoStep_t)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env;
    fprintf(stderr, "[%s] status %d %s: %s\n", instance, (int)status, category ? category : "", message);
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) { fprintf(stderr, "missing symbol %s\n", name); exit(3); }
    return f;
}

#define CHECK(call) do { fmi2Status s_ = (call); if (s_ > fmi2Warning) { \
    fprintf(stderr, "%s failed with status %d\n", #call, (int)s_); return 4; } } while (0)

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
    char path[4096], uri[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    snprintf(uri, sizeof uri, "file://%s/resources", dir);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen failed: %s\n", dlerror()); return 3; }

    Instantiate_t instantiate = (Instantiate_t)sym(lib, "fmi2Instantiate");
    SetupExperiment_t setup = (SetupExperiment_t)sym(lib, "fmi2SetupExperiment");
    Simple_t enter = (Simple_t)sym(lib, "fmi2EnterInitializationMode");
    Simple_t exit_init = (Simple_t)sym(lib, "fmi2ExitInitializationMode");
    Simple_t terminate = (Simple_t)sym(lib, "fmi2Terminate");
    FreeInstance_t free_instance = (FreeInstance_t)sym(lib, "fmi2FreeInstance");
    GetSetReal_t get_real = (GetSetReal_t)sym(lib, "fmi2GetReal");
    GetSetReal_t set_real = (GetSetReal_t)sym(lib, "fmi2SetReal");
    DoStep_t do_step = (DoStep_t)sym(lib, "fmi2DoStep");

    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("c_host", fmi2CoSimulation, guid, uri, &cb, 0, 1);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 4; }
    CHECK(setup(c, 0, 0.0, 0.0, 1, t_end));
    CHECK(enter(c));
    if (n_in) CHECK(set_real(c, in_vr, n_in, in_val));
    CHECK(exit_init(c));

    long n_steps = (long)(t_end / h + 0.5);
    for (long n = 0; n <= n_steps; n++) {
        double t = n * h;
        if (n_out) CHECK(get_real(c, out_vr, n_out, out_val));
        printf("%.17g", t);
        for (size_t j = 0; j < n_out; j++) printf(",%.17g", out_val[j]);
        printf("\n");
        if (n < n_steps) CHECK(do_step(c, t, h, 1));
    }
    fflush(stdout);
    CHECK(terminate(c));
    free_instance(c);
    /* pythonfmu 0.7.0 may corrupt the heap while finalizing Python at exit (docs/fmu.md):
       every result is flushed above, so leave without running library destructors. */
    _exit(0);
}

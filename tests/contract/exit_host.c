/* A plain C FMI 2.0 host that ends the way most tools do: with exit() (not _exit), so every exit handler and
 * library destructor runs, pythonfmu's Python finalization included. It instantiates the FMU, optionally runs
 * it (one good step, then a refused one), frees it and calls exit(EXIT_CODE): a test checks the process ends,
 * in time, with that code.
 *
 *   exit_host FMU_DIR MODEL_ID GUID MODE EXIT_CODE      MODE: free (instantiate/free only) | step | cycles:N
 *                                                        | atexit | span:H
 *
 * cycles:N instantiates, initializes, steps and frees N times and prints the resident memory (KiB) after the
 * first tenth and after all: "rss_tenth A rss_end B".
 * atexit is a host that tears down in its own exit handler (as a C++ host does in the destructor of a static
 * object): registered before the FMU is loaded, it runs after the FMU's own exit handlers, steps the instance main
 * left live and frees it, printing "late step S" and "late freed".
 * span:H follows the good step with one of h = H (a span of more steps than can be taken) and another of
 * 0.01, printing "span step S" and "after span step S".
 */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void *fmi2Component;
typedef struct {
    void (*logger)(void *, const char *, int, const char *, const char *, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(void *, int);
    void *componentEnvironment;
} fmi2CallbackFunctions;

static void logger(void *env, const char *instance, int status, const char *category, const char *message, ...) {
    (void)env; (void)category;
    fprintf(stderr, "LOG %s %d %s\n", instance, status, message);
}

static fmi2Component late_instance;
static int (*late_step)(fmi2Component, double, double, int);
static void (*late_free)(fmi2Component);

static void host_teardown(void) {
    printf("late step %d\n", late_step(late_instance, 0.01, 0.01, 1));
    late_free(late_instance);
    printf("late freed\n");
    fflush(stdout);
}

static long resident_kib(void) {
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    long kib = -1;
    while (f && fgets(line, sizeof line, f))
        if (strncmp(line, "VmRSS:", 6) == 0) kib = atol(line + 6);
    if (f) fclose(f);
    return kib;
}

int main(int argc, char **argv) {
    if (argc < 6) { fprintf(stderr, "usage: %s FMU_DIR MODEL_ID GUID MODE EXIT_CODE\n", argv[0]); return 2; }
    char path[4096], uri[4096];
    const int late = strcmp(argv[4], "atexit") == 0;
    if (late) atexit(host_teardown);
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen failed: %s\n", dlerror()); return 3; }
    fmi2Component (*instantiate)(const char *, int, const char *, const char *, const fmi2CallbackFunctions *, int,
                                 int) = (fmi2Component (*)(const char *, int, const char *, const char *,
                                        const fmi2CallbackFunctions *, int, int))dlsym(lib, "fmi2Instantiate");
    int (*setup)(fmi2Component, int, double, double, int, double) =
        (int (*)(fmi2Component, int, double, double, int, double))dlsym(lib, "fmi2SetupExperiment");
    int (*enter)(fmi2Component) = (int (*)(fmi2Component))dlsym(lib, "fmi2EnterInitializationMode");
    int (*exit_init)(fmi2Component) = (int (*)(fmi2Component))dlsym(lib, "fmi2ExitInitializationMode");
    int (*do_step)(fmi2Component, double, double, int) =
        (int (*)(fmi2Component, double, double, int))dlsym(lib, "fmi2DoStep");
    void (*free_instance)(fmi2Component) = (void (*)(fmi2Component))dlsym(lib, "fmi2FreeInstance");
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    int cycles = strncmp(argv[4], "cycles:", 7) == 0 ? atoi(argv[4] + 7) : 1;
    long tenth = -1;
    for (int i = 0; i < cycles; i++) {
        fmi2Component c = instantiate("exit_host", 1, argv[3], uri, &cb, 0, 0);
        if (!c) { fprintf(stderr, "fmi2Instantiate returned NULL\n"); return 4; }
        if (strcmp(argv[4], "free") != 0) {
            setup(c, 0, 0.0, 0, 0, 0.0);
            enter(c);
            exit_init(c);
            printf("step %d\n", do_step(c, 0.0, 0.01, 1));
            if (strncmp(argv[4], "span:", 5) == 0) {
                printf("span step %d\n", do_step(c, 0.01, atof(argv[4] + 5), 1));
                printf("after span step %d\n", do_step(c, 0.01, 0.01, 1));
            } else if (cycles == 1) {
                printf("refused step %d\n", do_step(c, 5.0, 0.01, 1)); /* t is not the FMU's time */
            }
        }
        if (late) {
            late_instance = c;
            late_step = do_step;
            late_free = free_instance;
        } else {
            free_instance(c);
        }
        if (i == cycles / 10) tenth = resident_kib();
    }
    if (cycles > 1) printf("rss_tenth %ld rss_end %ld\n", tenth, resident_kib());
    printf("freed\n");
    fflush(stdout);
    exit(atoi(argv[5]));
}

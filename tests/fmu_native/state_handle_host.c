/* A plain C FMI 2.0 host that misuses FMU state handles the ways real hosts have, each call once, and checks the
 * instance still works afterwards (tests/fmu_native/test_native_fmu_state_handles.py).
 *
 *   state_handle_host DIR ID GUID handles VR...   the cases below on one instance, one line per call:
 *                                                 CASE <name> <status> <message logged during the call>
 *                                                 then the outputs VR... after one step from a state restored
 *                                                 after all the misuse, and the same from a fresh instance that saw
 *                                                 none: VALUES after|clean <C99 hex floats>
 *   state_handle_host DIR ID GUID leave N K       N cycles of instantiate, initialize, step, K states taken and
 *                                                 never freed, free the instance; resident memory (KiB) after the
 *                                                 first tenth of the cycles and after all: rss_tenth A rss_end B,
 *                                                 and the serialized size of one state: state_bytes S
 *
 * A made-up handle points to a page that cannot be read (PROT_NONE): an FMU that reads through a handle before it
 * knows the handle is its own crashes there. A crash or abort fails the test by the exit status; the process ends
 * with exit() after freeing its instances.
 */
#define _DEFAULT_SOURCE
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "../c_host/fmi2_host_api.h"

static fmi2_host F;  /* the binary's functions, loaded by fmi2_host_open */

static char logged[8192];  /* what the FMU logged during the current call */
static int fatal_seen;

static void logger(void *env, const char *instance, fmi2Status status, const char *category, const char *message,
                   ...)
{
    (void)env, (void)instance, (void)category;
    if (status == fmi2Fatal) fatal_seen = 1;
    char text[4096];
    va_list args;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);  /* the FMU doubles '%' and '#': expand as the standard says */
    va_end(args);
    const size_t used = strlen(logged);
    snprintf(logged + used, sizeof logged - used, "%s%s", used ? " | " : "", text);
}

static fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
static const char *GUID;

#define MUST(call)                                                                                  \
    do {                                                                                            \
        logged[0] = '\0';                                                                           \
        fmi2Status must_status = (call);                                                            \
        if (must_status != fmi2OK) {                                                                \
            fprintf(stderr, "%s:%d: %s returned %d: %s\n", __FILE__, __LINE__, #call, must_status, logged); \
            exit(4);                                                                                \
        }                                                                                           \
    } while (0)

static void report(const char *name, fmi2Status status)
{
    printf("CASE %s %d %s\n", name, (int)status, logged);
    fflush(stdout);
}

#define CASE(name, call)            \
    do {                            \
        logged[0] = '\0';           \
        report(name, (call));       \
    } while (0)

static fmi2Component started(const char *name)
{
    fmi2Component c = F.Instantiate(name, fmi2CoSimulation, GUID, F.resources, &callbacks, fmi2False, fmi2False);
    if (!c) {
        fprintf(stderr, "fmi2Instantiate failed: %s\n", logged);
        exit(4);
    }
    MUST(F.SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0));
    MUST(F.EnterInitializationMode(c));
    MUST(F.ExitInitializationMode(c));
    return c;
}

#define H 0.01

static void print_values(const char *label, fmi2Component c, const fmi2ValueReference *vr, size_t n)
{
    double v[64];
    MUST(F.GetReal(c, vr, n, v));
    printf("VALUES %s", label);
    for (size_t i = 0; i < n; i++) printf(" %a", v[i]);
    printf("\n");
}

static int cmd_handles(int argc, char **argv)
{
    size_t n = 0;
    fmi2ValueReference vr[64];
    for (int i = 0; i < argc && n < 64; i++) vr[n++] = (fmi2ValueReference)strtoul(argv[i], NULL, 10);
    /* a page no one may read: a made-up handle, or a made-up address of a state variable, points there */
    void *unreadable = mmap(NULL, 4096, PROT_NONE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (unreadable == MAP_FAILED) return 5;

    fmi2Component c = started("misused");
    MUST(F.DoStep(c, 0.0, H, 1));
    fmi2FMUstate saved = NULL;
    MUST(F.GetFMUstate(c, &saved));  /* the state at t = H: restored at the end, then one more step */

    /* NULL */
    CASE("set_null", F.SetFMUstate(c, NULL));
    CASE("free_null_address", F.FreeFMUstate(c, NULL));
    CASE("get_null_address", F.GetFMUstate(c, NULL));
    CASE("size_null", F.SerializedFMUstateSize(c, NULL, &(size_t){0}));

    /* a handle never handed out: its memory is the bytes of a real state, or cannot be read at all */
    size_t size = 0;
    MUST(F.SerializedFMUstateSize(c, saved, &size));
    char *bytes = malloc(size);
    MUST(F.SerializeFMUstate(c, saved, bytes, size));
    fmi2FMUstate look_alike = bytes, made_up = unreadable;
    CASE("set_look_alike", F.SetFMUstate(c, look_alike));
    CASE("set_made_up", F.SetFMUstate(c, made_up));
    CASE("size_made_up", F.SerializedFMUstateSize(c, made_up, &size));
    CASE("serialize_made_up", F.SerializeFMUstate(c, made_up, bytes, size));
    CASE("free_made_up", F.FreeFMUstate(c, &made_up));
    CASE("get_overwriting_made_up", F.GetFMUstate(c, &made_up));

    /* freed: set, sized, serialized and freed again through a copy of the handle */
    fmi2FMUstate taken = NULL;
    MUST(F.GetFMUstate(c, &taken));
    fmi2FMUstate copy = taken;
    CASE("free_taken", F.FreeFMUstate(c, &taken));
    printf("VALUE variable_after_free %s\n", taken == NULL ? "NULL" : "set");
    CASE("free_again_variable_null", F.FreeFMUstate(c, &taken));  /* FMI: freeing NULL does nothing */
    CASE("set_freed", F.SetFMUstate(c, copy));
    CASE("size_freed", F.SerializedFMUstateSize(c, copy, &size));
    CASE("serialize_freed", F.SerializeFMUstate(c, copy, bytes, size));
    CASE("double_free", F.FreeFMUstate(c, &copy));

    /* the handle where the address of the host's variable belongs (fmusim 0.0.39's fmi2FreeFMUstate) */
    fmi2FMUstate held = NULL;
    MUST(F.GetFMUstate(c, &held));
    CASE("free_handle_for_address", F.FreeFMUstate(c, (fmi2FMUstate *)held));
    CASE("get_into_handle_for_address", F.GetFMUstate(c, (fmi2FMUstate *)held));
    CASE("deserialize_into_handle_for_address", F.DeSerializeFMUstate(c, bytes, size, (fmi2FMUstate *)held));
    CASE("free_handle_for_address_again", F.FreeFMUstate(c, (fmi2FMUstate *)held));
    CASE("set_held_after", F.SetFMUstate(c, held));  /* still live: the misuse neither freed nor wrote it */
    CASE("free_held", F.FreeFMUstate(c, &held));

    /* a state of another instance of the same FMU */
    fmi2Component other = started("other");
    fmi2FMUstate others = NULL;
    MUST(F.GetFMUstate(other, &others));
    CASE("set_other_instances", F.SetFMUstate(c, others));
    CASE("free_other_instances", F.FreeFMUstate(c, &others));
    MUST(F.FreeFMUstate(other, &others));
    F.FreeInstance(other);

    /* still working: the saved state restored, one step, the outputs; against a fresh instance without misuse */
    CASE("set_saved", F.SetFMUstate(c, saved));
    CASE("step_after", F.DoStep(c, H, H, 1));
    print_values("after", c, vr, n);
    CASE("free_saved", F.FreeFMUstate(c, &saved));
    fmi2FMUstate left = NULL;
    MUST(F.GetFMUstate(c, &left));  /* left for fmi2FreeInstance to free */
    F.FreeInstance(c);

    fmi2Component clean = started("clean");
    MUST(F.DoStep(clean, 0.0, H, 1));
    MUST(F.DoStep(clean, H, H, 1));
    print_values("clean", clean, vr, n);
    F.FreeInstance(clean);
    free(bytes);
    printf("FATAL_SEEN %d\n", fatal_seen);
    return 0;
}

static long resident_kib(void)
{
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    long kib = -1;
    while (f && fgets(line, sizeof line, f))
        if (strncmp(line, "VmRSS:", 6) == 0) kib = atol(line + 6);
    if (f) fclose(f);
    return kib;
}

static int cmd_leave(int n_cycles, int k_states)
{
    long tenth = -1;
    size_t size = 0;
    for (int cycle = 0; cycle < n_cycles; cycle++) {
        fmi2Component c = started("leaver");
        MUST(F.DoStep(c, 0.0, H, 1));
        for (int k = 0; k < k_states; k++) {
            fmi2FMUstate s = NULL;
            MUST(F.GetFMUstate(c, &s));
            if (cycle == 0 && k == 0) MUST(F.SerializedFMUstateSize(c, s, &size));
        }
        F.FreeInstance(c);
        if (cycle + 1 == n_cycles / 10) tenth = resident_kib();
    }
    printf("rss_tenth %ld\nrss_end %ld\nstate_bytes %zu\n", tenth, resident_kib(), size);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 5) {
        fprintf(stderr, "usage: %s DIR ID GUID handles VR... | leave N K\n", argv[0]);
        return 2;
    }
    GUID = argv[3];
    fmi2_host_open(&F, argv[1], argv[2]);
    int rc = 2;
    if (strcmp(argv[4], "handles") == 0)
        rc = cmd_handles(argc - 5, argv + 5);
    else if (strcmp(argv[4], "leave") == 0 && argc == 7)
        rc = cmd_leave(atoi(argv[5]), atoi(argv[6]));
    fflush(stdout);
    exit(rc);
}

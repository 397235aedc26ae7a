/* The front layer of the pythonfmu FMU: the binary a host loads (binaries/linux64/<model>.so). It exports the
 * FMI 2.0 functions and forwards each call to pythonfmu's own binary, shipped beside it (FRONT_INNER_LIBRARY,
 * loaded with dlopen at the first fmi2Instantiate), adding what pythonfmu 0.7.0 cannot give a Python slave:
 *
 * - the status of a call is the worst of pythonfmu's answer and the statuses the slave logged during the call in
 *   the status categories (messages of the slave's own categories are information: counts_towards_status)
 *   (pythonfmu ignores what the slave's methods return, but each message the slave logs reaches pythonfmu's
 *   logger callback before the call returns, and that callback is this layer's `relay`). So a refused
 *   setReal/getReal/get or set String, Integer, Boolean returns the fmi2Error the slave logged;
 * - arguments pythonfmu would dereference unchecked are checked first: a component handle that is not a live
 *   instance of this FMU, NULL arrays, a serialization buffer smaller than the state, and every fmi2FMUstate
 *   handle (pythonfmu takes any pointer for a Python object): an instance accepts only the states it handed out
 *   and has not freed (its registry), so NULL, made-up, freed or foreign handles, a double free and a state handle
 *   passed where the address of the host's variable belongs are refused, as in the native FMU (the same rules and
 *   words as fmu_src/native/fmi2Functions.c). Refused with fmi2Error and a logged message;
 * - fmi2GetBooleanStatus(fmi2Terminated) (pythonfmu 0.7.0 answers true after any discarded step, so that a master
 *   stops even where setting a good input or a shorter step would go on): true when the master asks for the very
 *   step that was discarded again with nothing set or restored in between, which fails the same way (answered
 *   without calling the slave), as the native FMU does; false otherwise;
 * - messages: errors, discards and warnings always reach the host's logger, other messages only with logging
 *   on, as in the native FMU (fmu_src/native/fmi2Functions.c). pythonfmu itself runs with logging always on,
 *   so that every status the slave logs is seen here;
 * - fmi2FreeInstance parks the instance and the next fmi2Instantiate with the same resources and GUID takes it
 *   back through pythonfmu's fmi2Reset, which builds a new slave object from the class it already has. A real
 *   pythonfmu instantiate executes the slave's module again and never frees what that creates (~75 KiB per
 *   instantiate/free cycle); a reset does not (docs/fmu.md, tests/contract). A parked instance is reset when it
 *   is parked, so it holds a fresh slave rather than a finished run.
 * - at exit(), pythonfmu's interpreter is released once, not twice (see load_inner).
 * - the order of calls (pythonfmu checks none): the native FMU's modes and rules (instantiated, initialization mode,
 *   step mode, terminated), so that a doStep after fmi2Terminate, or input derivatives before initialization, are
 *   refused with fmi2Error and the native FMU's words; setupExperiment's stopTime checked against its startTime;
 *   the host's GUID checked against the guid of the FMU's modelDescription.xml at fmi2Instantiate;
 * - a serialized FMU state is pythonfmu's bytes behind a header (format, byte order, size, the instance's mode and
 *   a checksum), checked at fmi2DeSerializeFMUstate before pythonfmu unpickles anything: garbage, truncated or
 *   damaged bytes are refused there, as the native FMU refuses them.
 *
 * - fmi2SetRealInputDerivatives reaches a slave that takes input derivatives (FRONT_DERIVATIVE_VR_BASE defined)
 *   as an fmi2SetReal of encoded value references (see the function).
 *
 * This file knows nothing of linknet: it is pythonfmu glue, compiled by build_fmu.py for every pythonfmu FMU
 * (scenes and components) with FRONT_INNER_LIBRARY defined. It is linked -z nodelete (parked instances outlive a
 * host's dlclose), so an FMU rebuilt and extracted again at the same path in the same process is served by the
 * front loaded first: its code must not depend on the FMU (no GUID is compiled in; instances are parked by
 * resource location and GUID).
 */
#define _GNU_SOURCE
#include <ctype.h>
#include <dlfcn.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_api.h"

#ifndef FRONT_INNER_LIBRARY
#error "define FRONT_INNER_LIBRARY: the file name of pythonfmu's binary, in the folder of this one"
#endif

/* ---- pythonfmu's functions --------------------------------------------------------------------------- */

#define INNER_FUNCTIONS(X)                                                                                      \
    X(fmi2Instantiate) X(fmi2FreeInstance) X(fmi2SetupExperiment) X(fmi2EnterInitializationMode)                \
    X(fmi2ExitInitializationMode) X(fmi2Terminate) X(fmi2Reset) X(fmi2GetReal) X(fmi2GetInteger)                \
    X(fmi2GetBoolean) X(fmi2GetString) X(fmi2SetReal) X(fmi2SetInteger) X(fmi2SetBoolean) X(fmi2SetString)     \
    X(fmi2GetFMUstate) X(fmi2SetFMUstate) X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize)                     \
    X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate) X(fmi2GetDirectionalDerivative)                         \
    X(fmi2SetRealInputDerivatives) X(fmi2GetRealOutputDerivatives) X(fmi2DoStep) X(fmi2CancelStep)             \
    X(fmi2GetStatus) X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) X(fmi2GetBooleanStatus)                      \
    X(fmi2GetStringStatus)

static struct {
#define DECLARE(name) __typeof__(name) *name;
    INNER_FUNCTIONS(DECLARE)
#undef DECLARE
    void *library;
    char problem[PATH_MAX + 512];  /* why it could not be loaded */
} inner;

static pthread_once_t inner_once = PTHREAD_ONCE_INIT;

static const char inner_anchor = 0;  /* an object of this library: dladdr names the library's file */

static void load_inner(void)
{
    Dl_info self_info;
    char path[PATH_MAX];
    if (!dladdr(&inner_anchor, &self_info) || self_info.dli_fname == NULL) {
        snprintf(inner.problem, sizeof inner.problem, "cannot find the folder of the FMU's binary (dladdr failed)");
        return;
    }
    const char *slash = strrchr(self_info.dli_fname, '/');
    const int folder = slash ? (int)(slash - self_info.dli_fname) : 1;
    snprintf(path, sizeof path, "%.*s/%s", folder, slash ? self_info.dli_fname : ".", FRONT_INNER_LIBRARY);
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (library == NULL) {
        snprintf(inner.problem, sizeof inner.problem, "cannot load pythonfmu's binary %s: %s", path, dlerror());
        return;
    }
#define RESOLVE(name)                                                                                           \
    if ((*(void **)&inner.name = dlsym(library, #name)) == NULL) {                                              \
        snprintf(inner.problem, sizeof inner.problem, "%s does not export " #name, path);                       \
        return;                                                                                                 \
    }
    INNER_FUNCTIONS(RESOLVE)
#undef RESOLVE
    /* pythonfmu 0.7.0 keeps its interpreter in a static std::shared_ptr<PyState> (PySlaveInstance.cpp) and releases
       it twice when the process calls exit(): exit() first runs the shared_ptr's destructor, registered with
       __cxa_atexit when the library was loaded (PyState's teardown, then its control block is freed); then _dl_fini
       runs the library's __attribute__((destructor)) onLibraryUnload, whose finalizePythonInterpreter assigns
       nullptr to the destroyed shared_ptr and so decrements the count inside the freed block (glibc aborts with
       "free(): corrupted unsorted chunks" when that block sits in an unsorted bin; elsewhere the heap is damaged
       silently). An exit handler registered now, after the library was loaded, runs before that destructor: it is
       finalizePythonInterpreter itself, which releases the interpreter once and leaves the shared_ptr empty for
       the two later releases. (A dlclose runs onLibraryUnload first: the safe order.) */
    void (*finalize_inner)(void);
    *(void **)&finalize_inner = dlsym(library, "finalizePythonInterpreter");
    if (finalize_inner == NULL || atexit(finalize_inner) != 0) {
        snprintf(inner.problem, sizeof inner.problem, "%s: pythonfmu's finalizePythonInterpreter is missing or cannot "
                 "be called at exit (the front layer is written for pythonfmu 0.7.0)", path);
        return;
    }
    inner.library = library;
}

/* ---- instances --------------------------------------------------------------------------------------- */

#define FRONT_MAGIC 0x6c6e5046u  /* a live instance; cleared when it is freed (parked) */

/* The order of calls, as the native FMU keeps it (fmu_src/native/fmi2Functions.c: the same modes and words). */
enum mode { MODE_INSTANTIATED = 0, MODE_INITIALIZATION = 1, MODE_STEPPING = 2, MODE_TERMINATED = 3 };
static const char *const mode_names[] = {"instantiated (before fmi2EnterInitializationMode)",
                                         "initialization mode", "step mode", "terminated"};
#define IN(mode) (1u << (mode))

/* A state this instance handed out and has not freed, and the instance's mode when it was taken (restored with it). */
typedef struct front_state {
    fmi2FMUstate handle;
    int mode;
} front_state;

typedef struct front {
    unsigned magic;
    fmi2Component inner;              /* pythonfmu's instance */
    char *name;
    char *resources;                  /* the fmuResourceLocation and GUID it was made with: a parked instance */
    char *guid;                       /* is reused for the same two only */
    fmi2CallbackLogger logger;        /* the host's */
    fmi2ComponentEnvironment environment;
    int logging_on;
    fmi2Status worst;                 /* the worst status logged during the current call */
    fmi2CallbackFunctions callbacks;  /* handed to pythonfmu (which keeps the pointer): its logger is relay() */
    struct front *next_parked;
    int mode;                         /* enum mode */
    int directional;                  /* the modelDescription declares providesDirectionalDerivative */
    int events;                       /* it declares the events' log category (LINKNET_EVENT_CATEGORY) */
    front_state *states;              /* the FMU states this instance handed out and has not freed */
    size_t n_states, states_capacity;
    /* the last discarded step, until something is set or restored: the same step asked again fails the same way */
    int discarded;
    double discarded_t, discarded_h;
    int terminated;                   /* fmi2Terminated */
    char last_discard[2048];          /* the last message the slave logged with fmi2Discard status */
    char discard_reason[2048];        /* the one it logged when that step was discarded */
    char line[4096];
} front;

static pthread_mutex_t registry_lock = PTHREAD_MUTEX_INITIALIZER;  /* the parked instances */
static front *parked;

static const char *category_of(fmi2Status status)
{
    switch (status) {
    case fmi2Warning: return "logStatusWarning";
    case fmi2Discard: return "logStatusDiscard";
    case fmi2Error: return "logStatusError";
    case fmi2Fatal: return "logStatusFatal";
    default: return "logAll";
    }
}

/* The logger's message is a printf format with FMI's #<type><vr># references: plain text has its '%' and '#'
   doubled, so that hosts which expand them print it as written. */
static void emit(front *self, fmi2Status status, const char *category, const char *text)
{
    if (status == fmi2OK && !self->logging_on) return;
    size_t j = 0;
    const size_t cap = sizeof self->line - 1;
    for (const char *p = text ? text : ""; *p && j + 2 < cap; p++) {
        if (*p == '%' || *p == '#') self->line[j++] = *p;
        self->line[j++] = *p;
    }
    self->line[j] = '\0';
    if (category == NULL || category[0] == '\0') category = category_of(status);
    if (self->logger)
        self->logger(self->environment, self->name, status, category, self->line);
    else
        fprintf(stderr, "[%s] %s: %s\n", self->name, category, text ? text : "");
}

/* Whether a message the slave logged sets the call's status: those of the status categories (logStatusWarning ...,
   and logAll, where pythonfmu files a status without a category of its own) do. A message of a category the slave
   declared for itself (a linknet scene FMU's logErrorEstimate: its error estimate exceeded the goal) is information
   about a result computed as asked: it reaches the host with its status, and the call's status stays as it was. */
static int counts_towards_status(const char *category)
{
    return category == NULL || category[0] == '\0' || strncmp(category, "logStatus", 9) == 0
           || strcmp(category, "logAll") == 0;
}

/* pythonfmu's logger callback: pythonfmu passes the slave's message as the format (with no arguments). */
static void relay(fmi2ComponentEnvironment environment, fmi2String instanceName, fmi2Status status,
                  fmi2String category, fmi2String message, ...)
{
    (void)instanceName;  /* a reused instance keeps the name it was made with: the front's is the host's */
    front *self = (front *)environment;
    if (self == NULL) return;
    if (status > self->worst && status <= fmi2Fatal && counts_towards_status(category)) self->worst = status;
    if (status == fmi2Discard) snprintf(self->last_discard, sizeof self->last_discard, "%s", message ? message : "");
    emit(self, status, category, message);
}

static fmi2Status refuse(front *self, const char *function, const char *format, ...)
{
    char text[1024];
    int n = snprintf(text, sizeof text, "%s: ", function);
    va_list args;
    va_start(args, format);
    vsnprintf(text + n, sizeof text - (size_t)n, format, args);
    va_end(args);
    if (fmi2Error > self->worst) self->worst = fmi2Error;
    emit(self, fmi2Error, NULL, text);
    return fmi2Error;
}

/* The answer of a forwarded call: pythonfmu's status or a worse one the slave logged meanwhile. */
static fmi2Status answer(const front *self, fmi2Status status)
{
    return self->worst > status ? self->worst : status;
}

/* A call that may change what a step computes (a value set, a state restored, a reset) succeeded: the discarded
   step, if any, is no longer known to fail, and the master is no longer asked to stop. */
static fmi2Status changed_by(front *self, fmi2Status status)
{
    if (status <= fmi2Warning) self->discarded = self->terminated = 0;
    return status;
}

static front *checked(fmi2Component c)
{
    front *self = (front *)c;
    if (self == NULL || self->magic != FRONT_MAGIC) return NULL;
    self->worst = fmi2OK;
    return self;
}

#define ENTER(function)                 \
    front *self = checked(c);           \
    if (self == NULL) return fmi2Error; \
    const char *const fn = function

/* Whether the call is allowed in the instance's mode; refused with the native FMU's words if not. */
static int mode_allows(front *self, const char *fn, unsigned allowed)
{
    if (allowed & IN(self->mode)) return 1;
    refuse(self, fn, "not allowed in %s", mode_names[self->mode]);
    return 0;
}

/* The mode a call moves to when pythonfmu and the slave accepted it. */
static fmi2Status moving_to(front *self, fmi2Status status, int mode)
{
    if (status <= fmi2Warning) self->mode = mode;
    return status;
}

static int arrays_given(front *self, const char *fn, size_t n, const void *vr, const void *value)
{
    if (n == 0 || (vr != NULL && value != NULL)) return 1;
    refuse(self, fn, "%s is NULL with nvr = %zu", vr == NULL ? "vr" : "value", n);
    return 0;
}

/* ---- FMU states: the handles this instance handed out and has not freed --------------------------------- */

/* A handle is live exactly when it is listed: whether one is, is decided by comparing pointers, never by reading
   through the handle, so a made-up, freed or foreign handle is refused without touching the memory it points to.
   The same registry and words as the native FMU's (fmu_src/native/fmi2Functions.c). */
static size_t state_index(const front *self, const void *handle)
{
    for (size_t i = 0; i < self->n_states; i++)
        if ((const void *)self->states[i].handle == handle) return i;
    return self->n_states;
}

static int is_live_state(const front *self, const void *handle)
{
    return handle != NULL && state_index(self, handle) < self->n_states;
}

static int remember_state(front *self, fmi2FMUstate state, int mode)
{
    if (self->n_states == self->states_capacity) {
        const size_t capacity = self->states_capacity ? 2 * self->states_capacity : 8;
        front_state *grown = realloc(self->states, capacity * sizeof *grown);
        if (grown == NULL) return 0;
        self->states = grown;
        self->states_capacity = capacity;
    }
    self->states[self->n_states].handle = state;
    self->states[self->n_states].mode = mode;
    self->n_states++;
    return 1;
}

static void forget_state(front *self, fmi2FMUstate state)
{
    const size_t i = state_index(self, state);
    if (i < self->n_states) self->states[i] = self->states[--self->n_states];
}

/* The states the host did not free, freed through pythonfmu (an instance parked or destroyed). */
static void free_all_states(front *self)
{
    for (size_t i = 0; i < self->n_states; i++) inner.fmi2FreeFMUstate(self->inner, &self->states[i].handle);
    free(self->states);
    self->states = NULL;
    self->n_states = self->states_capacity = 0;
}

#define NOT_A_LIVE_STATE                                                                                         \
    "FMUstate is not a live state of this FMU instance (one it made with fmi2GetFMUstate or "                  \
    "fmi2DeSerializeFMUstate and has not freed): a made-up handle, one already freed, or another FMU's or "    \
    "instance's; nothing was read or changed (a state moves to another instance serialized)"
#define HANDLE_FOR_ADDRESS                                                                                       \
    "FMUstate is a state handle itself where the address of the host's fmi2FMUstate variable belongs (call "  \
    "%s(c, &state), not %s(c, (fmi2FMUstate *)state)); nothing was freed or written: the state stays live, "   \
    "and fmi2FreeInstance frees it if the host does not"

/* A state handle given by the host by value: live in this instance, or refused with the reason logged. */
static int live_state(front *self, const char *fn, fmi2FMUstate state)
{
    if (state == NULL) {
        refuse(self, fn, "FMUstate is NULL");
        return 0;
    }
    if (!is_live_state(self, state)) {
        refuse(self, fn, NOT_A_LIVE_STATE);
        return 0;
    }
    return 1;
}

/* The address of the host's state variable: 1 when it may be read and written, else 0 after logging why. A live
   state's own handle passed as that address is recognised by the registry before anything is read through it,
   and refused (as fmu_src/native/fmi2Functions.c's state_variable explains). */
static int state_variable(front *self, const char *fn, const fmi2FMUstate *state)
{
    if (state == NULL) {
        refuse(self, fn, "FMUstate is NULL (the address of the host's fmi2FMUstate variable is expected)");
        return 0;
    }
    if (is_live_state(self, state)) {
        refuse(self, fn, HANDLE_FOR_ADDRESS, fn, fn);
        return 0;
    }
    return 1;
}

/* ---- common functions -------------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    ENTER("fmi2SetDebugLogging");
    if (nCategories > 0 && categories == NULL) return refuse(self, fn, "categories is NULL");
    const char *unknown = linknet_unknown_log_category(nCategories, categories, self->events);
    if (unknown)
        return refuse(self, fn, "unknown log category \"%s\" (known: %s)", unknown,
                      linknet_log_categories(self->events));
    self->logging_on = loggingOn != fmi2False;  /* pythonfmu keeps logging everything to relay() */
    return fmi2OK;
}

static char *copy_of(const char *text)
{
    char *copy = malloc(strlen(text) + 1);
    if (copy) strcpy(copy, text);
    return copy;
}

static front *take_parked(const char *resources, const char *guid)
{
    pthread_mutex_lock(&registry_lock);
    front **link = &parked;
    while (*link && (strcmp((*link)->resources, resources) != 0 || strcmp((*link)->guid, guid) != 0))
        link = &(*link)->next_parked;
    front *self = *link;
    if (self) *link = self->next_parked;
    pthread_mutex_unlock(&registry_lock);
    return self;
}

static void destroy(front *self)
{
    if (self->inner) free_all_states(self);
    if (self->inner) inner.fmi2FreeInstance(self->inner);
    free(self->resources);
    free(self->guid);
    free(self->name);
    free(self);
}

/* The path of the FMU's modelDescription.xml, from its resource location (a file URI, "file:///DIR/resources",
   "file://localhost/DIR/resources" or "file:/DIR/resources", percent-encoded; or a plain path): 1, or 0 for a location
   that is not a local folder. */
static int model_description_path(const char *resources, char *out, size_t n)
{
    const char *p = resources;
    if (strncmp(p, "file:", 5) == 0) {
        p += 5;
        if (strncmp(p, "//", 2) == 0) {
            p += 2;
            if (strncmp(p, "localhost", 9) == 0) p += 9;
            if (*p != '/') return 0;  /* another host */
        }
    }
    if (*p != '/') return 0;
    size_t j = 0;
    for (; *p && j + 1 < n; p++) {
        unsigned hex;
        if (p[0] == '%' && isxdigit((unsigned char)p[1]) && isxdigit((unsigned char)p[2])
            && sscanf(p + 1, "%2x", &hex) == 1) {
            out[j++] = (char)hex;
            p += 2;
        } else {
            out[j++] = *p;
        }
    }
    out[j] = '\0';
    while (j > 1 && out[j - 1] == '/') out[--j] = '\0';  /* the resources folder's own name goes */
    char *slash = strrchr(out, '/');
    if (slash == NULL) return 0;
    return snprintf(slash, n - (size_t)(slash - out), "/modelDescription.xml") < (int)(n - (size_t)(slash - out));
}

/* The guid attribute of the root element of a modelDescription.xml (text, NUL-terminated) into guid (n bytes): 1 if
   found. */
static int guid_of(const char *text, char *guid, size_t n)
{
    const char *root = strstr(text, "<fmiModelDescription");
    if (root == NULL) return 0;
    const char *end = strchr(root, '>');
    for (const char *p = root; p && (end == NULL || p < end); p = strstr(p + 1, "guid")) {
        if (p == root || !(p[-1] == ' ' || p[-1] == '\t' || p[-1] == '\n' || p[-1] == '\r')) continue;
        const char *q = p + 4;
        while (*q == ' ' || *q == '\t' || *q == '\n' || *q == '\r') q++;
        if (*q++ != '=') continue;
        while (*q == ' ' || *q == '\t' || *q == '\n' || *q == '\r') q++;
        const char quote = *q++;
        if (quote != '"' && quote != '\'') continue;
        const char *close = strchr(q, quote);
        if (close == NULL || (size_t)(close - q) >= n) return 0;
        memcpy(guid, q, (size_t)(close - q));
        guid[close - q] = '\0';
        return 1;
    }
    return 0;
}

/* Whether the CoSimulation element of a modelDescription.xml (text, NUL-terminated) declares
   providesDirectionalDerivative="true". */
static int declares_directional(const char *text)
{
    const char *element = strstr(text, "<CoSimulation");
    if (element == NULL) return 0;
    const char *end = strchr(element, '>');
    const char *p = strstr(element, "providesDirectionalDerivative");
    if (p == NULL || (end != NULL && p > end)) return 0;
    p += strlen("providesDirectionalDerivative");
    while (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r') p++;
    if (*p++ != '=') return 0;
    while (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r') p++;
    if (*p != '"' && *p != '\'') return 0;
    p++;
    return strncmp(p, "true", 4) == 0 || (p[0] == '1' && (p[1] == '"' || p[1] == '\''));
}

/* Whether the LogCategories of a modelDescription.xml (text, NUL-terminated) name LINKNET_EVENT_CATEGORY. */
static int declares_events(const char *text)
{
    const char *element = strstr(text, "<LogCategories");
    const char *end = element ? strstr(element, "</LogCategories>") : NULL;
    const char *p = element ? strstr(element, "\"" LINKNET_EVENT_CATEGORY "\"") : NULL;
    return p != NULL && (end == NULL || p < end);
}

/* The host's GUID against the guid of the modelDescription.xml beside the FMU's resources (pythonfmu checks none; no
   GUID is compiled into this layer, see the top of the file): 0 when they agree, 1 when they differ, -1 when the
   file cannot be read (why says which). *directional: whether the file declares providesDirectionalDerivative,
   *events the events' log category (0 where it cannot be read). */
static int guid_problem(const char *resources, const char *host_guid, char *why, size_t n, int *directional,
                        int *events)
{
    *directional = *events = 0;
    char path[PATH_MAX], guid[256];
    if (!model_description_path(resources, path, sizeof path)) {
        snprintf(why, n, "the resource location \"%s\" is not a local folder", resources);
        return -1;
    }
    FILE *file = fopen(path, "rb");
    if (file == NULL) {
        snprintf(why, n, "%s cannot be opened", path);
        return -1;
    }
    const size_t cap = (size_t)1 << 18;  /* the root element, with the guid, comes first */
    char *head = malloc(cap);
    if (head == NULL) {
        fclose(file);
        snprintf(why, n, "no memory to read %s", path);
        return -1;
    }
    const size_t got = fread(head, 1, cap - 1, file);
    fclose(file);
    head[got] = '\0';
    const int found = guid_of(head, guid, sizeof guid);
    *directional = declares_directional(head);
    *events = declares_events(head);
    free(head);
    if (!found) {
        snprintf(why, n, "%s has no guid in its fmiModelDescription element", path);
        return -1;
    }
    if (strcmp(guid, host_guid) == 0) return 0;
    snprintf(why, n, "GUID \"%s\" is not this FMU's (%s, in %s): the modelDescription.xml the host read and the FMU "
             "it loads come from different builds", host_guid, guid, path);
    return 1;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    const char *fn = "fmi2Instantiate";
    front probe;  /* for messages before an instance exists */
    memset(&probe, 0, sizeof probe);
    probe.name = (char *)(instanceName ? instanceName : "(unnamed instance)");
    probe.logger = functions ? functions->logger : NULL;
    probe.environment = functions ? functions->componentEnvironment : NULL;
    probe.logging_on = loggingOn != fmi2False;
    if (fmuType != fmi2CoSimulation) {
        refuse(&probe, fn, "this is a Co-Simulation FMU only (fmuType %d requested)", (int)fmuType);
        return NULL;
    }
    if (fmuGUID == NULL) {
        refuse(&probe, fn, "fmuGUID is NULL");
        return NULL;
    }
    if (fmuResourceLocation == NULL) {
        refuse(&probe, fn, "fmuResourceLocation is NULL (the slave's Python code is in the FMU's resources)");
        return NULL;
    }
    char why[2 * PATH_MAX + 512];
    int directional, events;
    const int guid_differs = guid_problem(fmuResourceLocation, fmuGUID, why, sizeof why, &directional, &events);
    if (guid_differs > 0) {
        refuse(&probe, fn, "%s", why);
        return NULL;
    }
    pthread_once(&inner_once, load_inner);
    if (inner.library == NULL) {
        refuse(&probe, fn, "%s", inner.problem);
        return NULL;
    }
    char *name = copy_of(probe.name);
    front *self = name ? take_parked(fmuResourceLocation, fmuGUID) : NULL;
    if (self == NULL && name) {
        self = calloc(1, sizeof *self);
        char *resources = self ? copy_of(fmuResourceLocation) : NULL;
        char *guid = resources ? copy_of(fmuGUID) : NULL;
        if (guid == NULL) {
            free(resources);
            free(self);
            self = NULL;
        } else {
            const fmi2CallbackFunctions callbacks = {relay, functions ? functions->allocateMemory : NULL,
                                                     functions ? functions->freeMemory : NULL, NULL, self};
            memcpy(&self->callbacks, &callbacks, sizeof callbacks);
            self->resources = resources;
            self->guid = guid;
        }
    }
    if (self == NULL) {
        free(name);
        refuse(&probe, fn, "out of memory");
        return NULL;
    }
    self->name = name;
    self->logger = probe.logger;
    self->environment = probe.environment;
    self->logging_on = probe.logging_on;
    self->worst = fmi2OK;
    self->discarded = self->terminated = 0;
    self->mode = MODE_INSTANTIATED;
    self->directional = directional;
    self->events = events;
    if (guid_differs < 0) {  /* said, and the instance made: pythonfmu finds the slave in the resources or says why */
        char text[sizeof why + 128];
        snprintf(text, sizeof text, "%s: the GUID \"%s\" cannot be checked: %s", fn, fmuGUID, why);
        emit(self, fmi2Warning, NULL, text);
    }
    if (self->inner == NULL) {
        /* pythonfmu logs through relay() with this instance: it must log everything, the front filters */
        self->inner = inner.fmi2Instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation, &self->callbacks,
                                            visible, fmi2True);
        if (self->inner == NULL) {
            if (self->worst < fmi2Error) refuse(self, fn, "pythonfmu could not instantiate the slave");
            destroy(self);
            return NULL;
        }
    }
    self->magic = FRONT_MAGIC;
    return self;
}

void fmi2FreeInstance(fmi2Component c)
{
    front *self = checked(c);
    if (self == NULL) return;
    self->magic = 0;
    free(self->name);
    self->name = copy_of("(parked)");
    self->logger = NULL;  /* messages of the reset below (there should be none) go to stderr */
    self->logging_on = 0;
    free_all_states(self);  /* the states the host did not free: they belong to the instance */
    /* a fresh slave (and pythonfmu's default experiment) for the next instance; one that cannot be reset is
       freed instead */
    fmi2Status status = inner.fmi2Reset(self->inner);
    if (status <= fmi2Warning) status = inner.fmi2SetupExperiment(self->inner, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    if (status > fmi2Warning || self->worst > fmi2Warning || self->name == NULL) {
        destroy(self);
        return;
    }
    pthread_mutex_lock(&registry_lock);
    self->next_parked = parked;
    parked = self;
    pthread_mutex_unlock(&registry_lock);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    ENTER("fmi2SetupExperiment");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED))) return fmi2Error;
    /* the native FMU's rules: a finite start, and a stop time, where given, at or after it */
    if (!isfinite(startTime)) return refuse(self, fn, "startTime = %g is not finite", startTime);
    if (stopTimeDefined && !(isfinite(stopTime) && stopTime >= startTime))
        return refuse(self, fn, "stopTime = %g must be finite and >= startTime = %g", stopTime, startTime);
    return changed_by(self, answer(self, inner.fmi2SetupExperiment(self->inner, toleranceDefined, tolerance,
                                                                   startTime, stopTimeDefined, stopTime)));
}

/* forwarded in the modes `allowed`; accepted (or whatever the answer, with `always`), the instance moves to mode
   `to` */
#define FORWARD_MODE_CHANGE(function, allowed, to, always)                                                  \
    fmi2Status function(fmi2Component c)                                                                    \
    {                                                                                                       \
        ENTER(#function);                                                                                   \
        if (!mode_allows(self, fn, allowed)) return fmi2Error;                                              \
        const fmi2Status status = changed_by(self, answer(self, inner.function(self->inner)));              \
        return always ? (self->mode = (to), status) : moving_to(self, status, to);                          \
    }

FORWARD_MODE_CHANGE(fmi2EnterInitializationMode, IN(MODE_INSTANTIATED), MODE_INITIALIZATION, 0)
/* a slave whose parameters do not define a valid scene still ends initialization (it says why at each doStep, until
   fmi2Reset): its parameters are fixed from then on, so staying in initialization mode would offer a retry that
   cannot succeed (where the native FMU keeps initialization mode, fix and retry) */
FORWARD_MODE_CHANGE(fmi2ExitInitializationMode, IN(MODE_INITIALIZATION), MODE_STEPPING, 1)
FORWARD_MODE_CHANGE(fmi2Terminate, IN(MODE_STEPPING), MODE_TERMINATED, 0)
FORWARD_MODE_CHANGE(fmi2Reset, IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEPPING)
                               | IN(MODE_TERMINATED), MODE_INSTANTIATED, 0)

fmi2Status fmi2CancelStep(fmi2Component c)
{
    ENTER("fmi2CancelStep");
    (void)fn;
    return changed_by(self, answer(self, inner.fmi2CancelStep(self->inner)));
}

/* ---- values ------------------------------------------------------------------------------------------ */

/* sets: a set that succeeded may change what the next step computes (changed_by); values are not set after
   fmi2Terminate (the native FMU's rule) */
#define FORWARD_VALUES(function, type, sets)                                                        \
    fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, type value[])   \
    {                                                                                               \
        ENTER(#function);                                                                           \
        if (sets && !mode_allows(self, fn, IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION)          \
                                           | IN(MODE_STEPPING)))                                    \
            return fmi2Error;                                                                       \
        if (!arrays_given(self, fn, nvr, vr, value)) return fmi2Error;                              \
        const fmi2Status status = answer(self, inner.function(self->inner, vr, nvr, value));        \
        return sets ? changed_by(self, status) : status;                                            \
    }

FORWARD_VALUES(fmi2GetReal, fmi2Real, 0)
FORWARD_VALUES(fmi2GetInteger, fmi2Integer, 0)
FORWARD_VALUES(fmi2GetBoolean, fmi2Boolean, 0)
FORWARD_VALUES(fmi2GetString, fmi2String, 0)
FORWARD_VALUES(fmi2SetReal, const fmi2Real, 1)
FORWARD_VALUES(fmi2SetInteger, const fmi2Integer, 1)
FORWARD_VALUES(fmi2SetBoolean, const fmi2Boolean, 1)
FORWARD_VALUES(fmi2SetString, const fmi2String, 1)

#ifdef FRONT_DERIVATIVE_VR_BASE
/* pythonfmu 0.7.0 has no path from fmi2GetDirectionalDerivative to the slave: a slave whose modelDescription declares
   providesDirectionalDerivative receives one directional derivative as two calls of encoded value references (the
   variables' own lie below FRONT_DERIVATIVE_VR_BASE, as for the input derivatives): one fmi2SetReal of the seed,
   DIRECTIONAL_SEED_START first (value: the number of knowns), then DIRECTIONAL_SEED + vKnown_ref[i] with dvKnown[i];
   then, where the slave took the seed, one fmi2GetReal of DIRECTIONAL_DERIVATIVE + vUnknown_ref[j] into dvUnknown.
   The slave answers (refuses a known that is not an input or an unknown that is not an output, naming it) itself.
   pythonfmu hands value references to Python as signed 32-bit ints: these arrive negative, apart from every
   variable's and every input derivative's (linknet_slave.py decodes them). */
#define DIRECTIONAL_SEED 0x80000000u
#define DIRECTIONAL_SEED_START (DIRECTIONAL_SEED + (unsigned long)(FRONT_DERIVATIVE_VR_BASE))
#define DIRECTIONAL_DERIVATIVE 0xC0000000u

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    ENTER("fmi2GetDirectionalDerivative");
    if (!self->directional) return refuse(self, fn, "not provided (providesDirectionalDerivative is false)");
    if (self->mode == MODE_INSTANTIATED || self->mode == MODE_INITIALIZATION)
        return refuse(self, fn, "called in %s: derivatives are given at the current state once "
                      "fmi2ExitInitializationMode has fixed the parameters", mode_names[self->mode]);
    if (nUnknown > 0 && (vUnknown_ref == NULL || dvUnknown == NULL))
        return refuse(self, fn, "%s is NULL with nUnknown = %zu", vUnknown_ref == NULL ? "vUnknown_ref" : "dvUnknown",
                      nUnknown);
    if (nKnown > 0 && (vKnown_ref == NULL || dvKnown == NULL))
        return refuse(self, fn, "%s is NULL with nKnown = %zu", vKnown_ref == NULL ? "vKnown_ref" : "dvKnown", nKnown);
    const unsigned long base = (unsigned long)(FRONT_DERIVATIVE_VR_BASE);
    for (size_t i = 0; i < nKnown; i++)
        if (vKnown_ref[i] >= base)
            return refuse(self, fn, "known value reference %u is not a Real variable of this FMU", vKnown_ref[i]);
    for (size_t j = 0; j < nUnknown; j++)
        if (vUnknown_ref[j] >= base)
            return refuse(self, fn, "unknown value reference %u is not a Real variable of this FMU", vUnknown_ref[j]);
    if (nUnknown == 0) return fmi2OK;
    fmi2ValueReference *seed_vr = malloc((nKnown + 1) * sizeof *seed_vr);
    fmi2Real *seed = malloc((nKnown + 1) * sizeof *seed);
    fmi2ValueReference *unknown_vr = malloc(nUnknown * sizeof *unknown_vr);
    fmi2Status status = fmi2Error;
    if (seed_vr == NULL || seed == NULL || unknown_vr == NULL) {
        refuse(self, fn, "out of memory for %zu value references", nKnown + nUnknown);
    } else {
        seed_vr[0] = (fmi2ValueReference)DIRECTIONAL_SEED_START;
        seed[0] = (fmi2Real)nKnown;
        for (size_t i = 0; i < nKnown; i++) {
            seed_vr[i + 1] = (fmi2ValueReference)(DIRECTIONAL_SEED + vKnown_ref[i]);
            seed[i + 1] = dvKnown[i];
        }
        for (size_t j = 0; j < nUnknown; j++)
            unknown_vr[j] = (fmi2ValueReference)(DIRECTIONAL_DERIVATIVE + vUnknown_ref[j]);
        status = answer(self, inner.fmi2SetReal(self->inner, seed_vr, nKnown + 1, seed));
        if (status <= fmi2Warning)
            status = answer(self, inner.fmi2GetReal(self->inner, unknown_vr, nUnknown, dvUnknown));
    }
    free(seed_vr);
    free(seed);
    free(unknown_vr);
    return status;
}
#else
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    ENTER("fmi2GetDirectionalDerivative");
    (void)fn;
    return answer(self, inner.fmi2GetDirectionalDerivative(self->inner, vUnknown_ref, nUnknown, vKnown_ref, nKnown,
                                                           dvKnown, dvUnknown));
}
#endif

#ifdef FRONT_DERIVATIVE_VR_BASE
/* pythonfmu 0.7.0 has no path from fmi2SetRealInputDerivatives to the slave: a slave that takes input derivatives
   receives them as one fmi2SetReal of the value references order * FRONT_DERIVATIVE_VR_BASE + vr, and answers
   (refuses orders or variables it does not take, naming them, and sets nothing when it refuses any) itself. An order
   that the encoding cannot carry (below 1, or beyond the slots) goes in the last slot, DERIVATIVE_ORDER_GIVEN, with
   the order itself as its value: the slave refuses it in its own words, so the host reads the same rule whatever the
   order (linknet_fmu.layout.DERIVATIVE_ORDER_GIVEN). pythonfmu hands value references to Python as signed 32-bit
   ints, so the slots end below 2^31. A value reference beyond the encoding's range is no variable of this FMU:
   refused here. */
#define DERIVATIVE_ORDER_GIVEN ((long)(((unsigned long)INT_MAX + 1) / (unsigned long)(FRONT_DERIVATIVE_VR_BASE)) - 1)

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    ENTER("fmi2SetRealInputDerivatives");
    if (!mode_allows(self, fn, IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi2Error;
    if (nvr > 0 && order == NULL) return refuse(self, fn, "order is NULL with nvr = %zu", nvr);
    if (!arrays_given(self, fn, nvr, vr, value)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    const unsigned long base = (unsigned long)(FRONT_DERIVATIVE_VR_BASE);
    for (size_t i = 0; i < nvr; i++)
        if (vr[i] >= base)
            return refuse(self, fn, "value reference %u is not a Real variable of this FMU; nothing set", vr[i]);
    fmi2ValueReference few_vr[64];
    fmi2Real few_value[64];
    fmi2ValueReference *encoded = nvr <= 64 ? few_vr : malloc(nvr * sizeof *encoded);
    fmi2Real *values = nvr <= 64 ? few_value : malloc(nvr * sizeof *values);
    if (encoded == NULL || values == NULL) {
        if (encoded != few_vr) free(encoded);
        if (values != few_value) free(values);
        return refuse(self, fn, "out of memory for %zu value references", nvr);
    }
    for (size_t i = 0; i < nvr; i++) {
        const int fits = order[i] >= 1 && order[i] < DERIVATIVE_ORDER_GIVEN;
        encoded[i] = (fmi2ValueReference)((unsigned long)(fits ? order[i] : DERIVATIVE_ORDER_GIVEN) * base + vr[i]);
        values[i] = fits ? value[i] : (fmi2Real)order[i];
    }
    const fmi2Status status = changed_by(self, answer(self, inner.fmi2SetReal(self->inner, encoded, nvr, values)));
    if (encoded != few_vr) free(encoded);
    if (values != few_value) free(values);
    return status;
}
#else
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    ENTER("fmi2SetRealInputDerivatives");
    if (!mode_allows(self, fn, IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi2Error;
    return changed_by(self, answer(self, inner.fmi2SetRealInputDerivatives(self->inner, vr, nvr, order, value)));
}
#endif

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    ENTER("fmi2GetRealOutputDerivatives");
    (void)fn;
    return answer(self, inner.fmi2GetRealOutputDerivatives(self->inner, vr, nvr, order, value));
}

/* ---- FMU states -------------------------------------------------------------------------------------- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    ENTER("fmi2GetFMUstate");
    if (!state_variable(self, fn, FMUstate)) return fmi2Error;
    if (*FMUstate != NULL && !live_state(self, fn, *FMUstate)) return fmi2Error;  /* else: one to overwrite */
    fmi2FMUstate fresh = NULL;
    const fmi2Status status = answer(self, inner.fmi2GetFMUstate(self->inner, &fresh));
    if (status > fmi2Warning || fresh == NULL || !remember_state(self, fresh, self->mode)) {
        if (fresh) inner.fmi2FreeFMUstate(self->inner, &fresh);
        return status > fmi2Warning ? status : refuse(self, fn, "no state was made (out of memory?)");
    }
    if (*FMUstate != NULL) {
        forget_state(self, *FMUstate);
        inner.fmi2FreeFMUstate(self->inner, FMUstate);
    }
    *FMUstate = fresh;
    return status;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    ENTER("fmi2SetFMUstate");
    if (!live_state(self, fn, FMUstate)) return fmi2Error;
    const int mode = self->states[state_index(self, FMUstate)].mode;
    return moving_to(self, changed_by(self, answer(self, inner.fmi2SetFMUstate(self->inner, FMUstate))), mode);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    ENTER("fmi2FreeFMUstate");
    if (!state_variable(self, fn, FMUstate)) return fmi2Error;
    if (*FMUstate == NULL) return fmi2OK;  /* nothing to free (FMI: the variable of a freed state holds NULL) */
    if (!is_live_state(self, *FMUstate)) return refuse(self, fn, NOT_A_LIVE_STATE);
    forget_state(self, *FMUstate);
    const fmi2Status status = answer(self, inner.fmi2FreeFMUstate(self->inner, FMUstate));
    *FMUstate = NULL;
    return status;
}

/* A serialized state: this header, then pythonfmu's bytes (the slave's own serialization). The header is the native
   FMU's (fmu_src/native/fmi2Functions.c, state_header) less its model fingerprint, which a front that knows nothing
   of the model cannot give: the slave checks which FMU a state belongs to when it is set. */
#define FRONT_STATE_FORMAT 1u
#define FRONT_STATE_BYTE_ORDER 0x01020304u
static const char front_state_magic[8] = {'L', 'N', 'K', 'P', 'Y', 'F', 'M', 'U'};

typedef struct front_state_header {
    char magic[8];
    uint32_t format;        /* FRONT_STATE_FORMAT */
    uint32_t byte_order;    /* FRONT_STATE_BYTE_ORDER as the writer stored it */
    uint64_t size;          /* bytes, this header included */
    uint32_t mode;          /* the instance's mode when the state was taken */
    uint32_t reserved;
    uint64_t checksum;      /* FNV-1a of the bytes after the header */
} front_state_header;

/* FNV-1a, 64 bits, as the native FMU's: a serialized state damaged in storage or transit is refused rather than run. */
static uint64_t checksum_of(const unsigned char *p, size_t n)
{
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

/* Why the n serialized bytes are not a state this front serialized, or NULL (the native FMU's words); their header
   is copied into *h. */
static const char *serialized_state_problem(const fmi2Byte *bytes, size_t n, front_state_header *h)
{
    memset(h, 0, sizeof *h);
    memcpy(h, bytes, n < sizeof *h ? n : sizeof *h);
    if (n < sizeof *h || memcmp(h->magic, front_state_magic, sizeof front_state_magic) != 0)
        return "not a linknet FMU state";
    if (h->byte_order != FRONT_STATE_BYTE_ORDER) return "a state written on a machine of another byte order";
    if (h->format != FRONT_STATE_FORMAT) return "a state of another format version (another linknet FMU release)";
    if (h->size != n) return "a state of the wrong size";
    if (h->mode > MODE_TERMINATED) return "a state with an invalid mode";
    if (h->checksum != checksum_of((const unsigned char *)bytes + sizeof *h, n - sizeof *h))
        return "the state's bytes are damaged (checksum mismatch)";
    return NULL;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    ENTER("fmi2SerializedFMUstateSize");
    if (size == NULL) return refuse(self, fn, "size is NULL");
    if (!live_state(self, fn, FMUstate)) return fmi2Error;
    size_t inner_size = 0;
    const fmi2Status status = answer(self, inner.fmi2SerializedFMUstateSize(self->inner, FMUstate, &inner_size));
    if (status <= fmi2Warning) *size = sizeof(front_state_header) + inner_size;
    return status;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    ENTER("fmi2SerializeFMUstate");
    if (!live_state(self, fn, FMUstate)) return fmi2Error;
    if (serializedState == NULL) return refuse(self, fn, "serializedState is NULL");
    size_t inner_size = 0;  /* pythonfmu copies the whole state whatever the buffer's size */
    fmi2Status status = answer(self, inner.fmi2SerializedFMUstateSize(self->inner, FMUstate, &inner_size));
    if (status > fmi2Warning) return status;
    const size_t needed = sizeof(front_state_header) + inner_size;
    if (size < needed) return refuse(self, fn, "a buffer of %zu bytes for a state of %zu", size, needed);
    status = answer(self, inner.fmi2SerializeFMUstate(self->inner, FMUstate, serializedState + sizeof(front_state_header),
                                                      inner_size));
    if (status > fmi2Warning) return status;
    front_state_header header;
    memset(&header, 0, sizeof header);
    memcpy(header.magic, front_state_magic, sizeof front_state_magic);
    header.format = FRONT_STATE_FORMAT;
    header.byte_order = FRONT_STATE_BYTE_ORDER;
    header.size = needed;
    header.mode = (uint32_t)self->states[state_index(self, FMUstate)].mode;
    header.checksum = checksum_of((const unsigned char *)serializedState + sizeof header, inner_size);
    memcpy(serializedState, &header, sizeof header);
    return status;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    ENTER("fmi2DeSerializeFMUstate");
    if (!state_variable(self, fn, FMUstate)) return fmi2Error;
    if (serializedState == NULL) return refuse(self, fn, "serializedState is NULL");
    front_state_header header;
    const char *problem = serialized_state_problem(serializedState, size, &header);
    if (problem) return refuse(self, fn, "refused: %s", problem);
    fmi2FMUstate fresh = NULL;
    const fmi2Status status = answer(self, inner.fmi2DeSerializeFMUstate(self->inner, serializedState + sizeof header,
                                                                         size - sizeof header, &fresh));
    if (status > fmi2Warning || fresh == NULL || !remember_state(self, fresh, (int)header.mode)) {
        if (fresh) inner.fmi2FreeFMUstate(self->inner, &fresh);
        return status > fmi2Warning ? status : refuse(self, fn, "no state was made (out of memory?)");
    }
    *FMUstate = fresh;
    return status;
}

/* ---- co-simulation ----------------------------------------------------------------------------------- */

/* the native FMU's words (fmu_src/native/fmi2Functions.c) */
#define REPEATED_STEP                                                                                            \
    "the step from t=%.17g with h=%.17g was discarded before, from this same state with these same inputs, so it "\
    "fails again the same way (not computed again); stop here, or set other inputs, restore another state or take " \
    "a shorter step."

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    ENTER("fmi2DoStep");
    if (self->mode != MODE_STEPPING) {  /* the native FMU's words */
        if (self->mode == MODE_INSTANTIATED || self->mode == MODE_INITIALIZATION)
            return refuse(self, fn, "called in %s: call fmi2ExitInitializationMode first", mode_names[self->mode]);
        return refuse(self, fn, "called after fmi2Terminate (fmi2Reset starts again)");
    }
    const double t = currentCommunicationPoint, h = communicationStepSize;
    if (self->discarded && t == self->discarded_t && h == self->discarded_h) {
        /* the slave is deterministic: from the same state with the same inputs the same step fails again. pythonfmu's
           states are Python objects the front cannot compare, so "the same state" is: nothing set, restored or reset
           since (changed_by forgets the discarded step) */
        self->terminated = 1;
        char text[sizeof self->discard_reason + 512];
        snprintf(text, sizeof text, "%s: fmi2Terminated is true (fmi2LastSuccessfulTime = %.17g): " REPEATED_STEP
                 " It failed with: %s", fn, t, t, h, self->discard_reason);
        emit(self, fmi2Discard, NULL, text);
        return fmi2Discard;
    }
    self->last_discard[0] = '\0';
    const fmi2Status status = answer(self, inner.fmi2DoStep(self->inner, t, h, noSetFMUStatePriorToCurrentPoint));
    if (status != fmi2Discard) return changed_by(self, status);
    self->discarded = 1;
    self->discarded_t = t;
    self->discarded_h = h;
    snprintf(self->discard_reason, sizeof self->discard_reason, "%s",
             self->last_discard[0] ? self->last_discard : "(the slave said nothing)");
    return status;
}

#define FORWARD_STATUS(function, type)                                              \
    fmi2Status function(fmi2Component c, const fmi2StatusKind s, type *value)       \
    {                                                                               \
        ENTER(#function);                                                           \
        if (value == NULL) return refuse(self, fn, "value is NULL");                \
        return answer(self, inner.function(self->inner, s, value));                 \
    }

FORWARD_STATUS(fmi2GetStatus, fmi2Status)
FORWARD_STATUS(fmi2GetRealStatus, fmi2Real)  /* pythonfmu's: the start of the last discarded step, or its end */
FORWARD_STATUS(fmi2GetIntegerStatus, fmi2Integer)
FORWARD_STATUS(fmi2GetStringStatus, fmi2String)

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    ENTER("fmi2GetBooleanStatus");
    if (value == NULL) return refuse(self, fn, "value is NULL");
    if (s != fmi2Terminated) return refuse(self, fn, "status kind %d is not a Boolean status", (int)s);
    *value = self->terminated ? fmi2True : fmi2False;  /* see fmi2DoStep */
    return fmi2OK;
}

/* FMI 3.0 Co-Simulation glue, written once for every linknet scene and ignorant of the physics: it drives the same
 * model as the FMI 2.0 glue (fmu_model.h, linknet_model.c with a scene's data from the FMU's resources) the way the
 * Modelica Reference-FMUs' fmi3Functions.c drives each model.c, with the FMI 2.0 glue's rules (fmi2Functions.c):
 *
 * - no call ever returns fmi3Fatal or brings the process down: a bad argument, a bad value or a call out of order
 *   returns fmi3Error with a logged message and changes nothing, so the instance stays usable; a step the solver
 *   cannot complete returns fmi3Discard and leaves the state where it was;
 * - after a discarded step, fmi3DoStep's terminateSimulation says whether the master should stop: true where the
 *   model knows that no retry of the step, however short, can succeed (FMU_DISCARD_FINAL), and when the very step
 *   that was discarded is asked again from the same model state (it would fail the same way: not computed again);
 *   lastSuccessfulTime is the FMU's time, where a discarded step leaves it;
 * - an FMU state handle is accepted only when this instance made it and has not freed it (fmu_states.h's registry);
 * - errors, discards and warnings always reach the host's logger (with loggingOn or not); other messages only with
 *   logging on. FMI 3 messages are plain text (no format characters to escape);
 * - instances share no mutable data.
 *
 * Variables: the FMI 3 value references are fmi3_variables.h's table, array variables (X [K,3], T [L], ...) over the
 * model's scalars; a Get/Set of n value references moves the sum of their element counts, row-major, and that sum
 * must be nValues. Events, clocks, intermediate updates, early return and the Model Exchange and Scheduled Execution
 * interfaces are not provided (their functions answer fmi3Error saying so).
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_api.h" /* the log categories both glues accept (linknet_log_categories); no fmi2 function is defined */
#include "fmi3/fmi3Functions.h"
#include "fmi3_variables.h"
#include "fmu_model.h"
#include "fmu_states.h"

enum mode { MODE_INSTANTIATED = 0, MODE_INITIALIZATION = 1, MODE_STEPPING = 2, MODE_TERMINATED = 3 };
static const char *const mode_names[] = {"instantiated (before fmi3EnterInitializationMode)",
                                         "initialization mode", "step mode", "terminated"};

#define INSTANCE_MAGIC 0x6c6e4b33u  /* a live instance; cleared when it is freed */

typedef struct instance {
    unsigned magic;
    char *name;
    fmi3LogMessageCallback logger;
    fmi3InstanceEnvironment environment;
    int logging_on;
    int mode;
    fmu_resource *resource;             /* the scene's data (fmu_resource.h): the model and the variables point into
                                           it */
    fmu_model *model;
    fmi3_variable *variables;           /* (n_variables) the FMI 3 variables, by value reference (fmi3_variables.h) */
    unsigned n_variables;
    char msg[FMU_MESSAGE];              /* the model's reason for a refusal */
    fmu_state_registry states;          /* the FMU states this instance handed out and has not freed */
    fmu_discard_memory discard;         /* the last discarded step and the state it was discarded from */
    int terminated;                     /* terminateSimulation: the master should stop (at lastSuccessfulTime) */
    unsigned *scratch;                  /* the model's value references of a call's variables */
    size_t scratch_capacity;
} instance;

/* ---- logging ------------------------------------------------------------------------------------- */

static const char *category_of(fmi3Status status)
{
    switch (status) {
    case fmi3Warning: return "logStatusWarning";
    case fmi3Discard: return "logStatusDiscard";
    case fmi3Error: return "logStatusError";
    case fmi3Fatal: return "logStatusFatal";
    default: return "logAll";
    }
}

static void emit_in(instance *self, fmi3Status status, const char *category, const char *text)
{
    if (status == fmi3OK && !self->logging_on) return;
    if (self->logger)
        self->logger(self->environment, status, category, text);
    else
        fprintf(stderr, "[%s] %s: %s\n", self->name, category, text);
}

static void logf_status(instance *self, fmi3Status status, const char *format, ...)
{
    char text[FMU_MESSAGE + 512];  /* a model's message and the glue's words around it */
    va_list args;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    emit_in(self, status, category_of(status), text);
}

static fmi3Status refuse(instance *self, const char *function, const char *format, ...)
{
    char text[FMU_MESSAGE];
    va_list args;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    logf_status(self, fmi3Error, "%s: %s", function, text);
    return fmi3Error;
}

/* A model result as an FMI status, with the model's reason logged. */
static fmi3Status report(instance *self, const char *function, int result)
{
    switch (result) {
    case FMU_OK: return fmi3OK;
    case FMU_WARNING: logf_status(self, fmi3Warning, "%s: %s", function, self->msg); return fmi3Warning;
    case FMU_DISCARD:
    case FMU_DISCARD_FINAL: logf_status(self, fmi3Discard, "%s: %s", function, self->msg); return fmi3Discard;
    case FMU_NOTE: {  /* information on a result computed as asked: seen by the host, the call is fmi3OK */
        char text[FMU_MESSAGE + 256];
        snprintf(text, sizeof text, "%s: %s", function, self->msg);
        emit_in(self, fmi3Warning, LINKNET_NOTE_CATEGORY, text);
        return fmi3OK;
    }
    default: logf_status(self, fmi3Error, "%s: %s", function, self->msg); return fmi3Error;
    }
}

/* The events of the step just taken, one message each with fmi3OK status in their own category (logging on). */
static void log_events(instance *self)
{
    if (!self->logging_on) return;
    char text[FMU_MESSAGE];
    for (size_t i = 0; fmu_model_event(self->model, i, text, sizeof text); i++)
        emit_in(self, fmi3OK, LINKNET_EVENT_CATEGORY, text);
}

static instance *checked(fmi3Instance c)
{
    instance *self = (instance *)c;
    if (self == NULL || self->magic != INSTANCE_MAGIC) return NULL;
    self->msg[0] = '\0';
    return self;
}

#define IN(mode) (1u << (mode))

static int mode_allows(instance *self, const char *function, unsigned allowed)
{
    if (allowed & (1u << self->mode)) return 1;
    refuse(self, function, "not allowed in %s", mode_names[self->mode]);
    return 0;
}

/* A call that may change what a step computes succeeded: the master is no longer asked to stop. */
static fmi3Status changed_by(instance *self, fmi3Status status)
{
    if (status <= fmi3Warning) self->terminated = 0;
    return status;
}

#define ENTER(function)                           \
    instance *self = checked(instance_);          \
    if (self == NULL) return fmi3Error;           \
    const char *const fn = function

/* ---- variables ----------------------------------------------------------------------------------- */

static const char *const kind_names[] = {"Float64 (the independent variable time)", "Float64", "String", "Boolean"};

static int vr_arguments(instance *self, const char *fn, const void *vr, size_t nvr, const void *values, size_t nValues)
{
    if (nvr > 0 && vr == NULL) {
        refuse(self, fn, "valueReferences is NULL with nValueReferences = %zu", nvr);
        return 0;
    }
    if (nValues > 0 && values == NULL) {
        refuse(self, fn, "values is NULL with nValues = %zu", nValues);
        return 0;
    }
    return 1;
}

/* The model's value references of the variables vr[0..nvr) (each of one of the kinds in the mask `kinds`), their
   elements in order, into self->scratch; 1, or 0 after logging why not (an unknown value reference, one of another
   type, or element counts that do not add up to nValues). `what` and `count` name the list and its number of values
   in messages. */
static int expand(instance *self, const char *fn, const char *what, const fmi3ValueReference vr[], size_t nvr,
                  unsigned kinds, size_t nValues, const char *count, size_t offset)
{
    size_t total = 0;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= self->n_variables) {
            refuse(self, fn, "%s[%zu] = %u is not a value reference of this FMU (0 .. %u)", what, i, (unsigned)vr[i],
                   self->n_variables - 1);
            return 0;
        }
        const fmi3_variable *v = &self->variables[vr[i]];
        if (!(kinds & (1u << v->kind))) {
            refuse(self, fn, "%s[%zu] = %u is %s, a variable of type %s", what, i, (unsigned)vr[i], v->name,
                   kind_names[v->kind]);
            return 0;
        }
        total += v->count;
    }
    if (total != nValues) {
        refuse(self, fn, "the %zu variables of %s hold %zu values, but %s is %zu (an array variable moves all its "
               "elements, row-major)", nvr, what, total, count, nValues);
        return 0;
    }
    if (offset + total > self->scratch_capacity) {
        unsigned *grown = realloc(self->scratch, (offset + total) * sizeof *grown);
        if (grown == NULL) {
            refuse(self, fn, "out of memory for %zu value references", offset + total);
            return 0;
        }
        self->scratch = grown;
        self->scratch_capacity = offset + total;
    }
    size_t j = offset;
    for (size_t i = 0; i < nvr; i++) {
        const fmi3_variable *v = &self->variables[vr[i]];
        for (unsigned e = 0; e < v->count; e++) self->scratch[j++] = v->first + e;
    }
    return 1;
}

#define KIND(k) (1u << (k))

fmi3Status fmi3GetFloat64(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    ENTER("fmi3GetFloat64");
    if (!vr_arguments(self, fn, vr, nvr, values, nValues)) return fmi3Error;
    if (!expand(self, fn, "valueReferences", vr, nvr, KIND(FMI3_TIME) | KIND(FMI3_FLOAT64), nValues, "nValues", 0))
        return fmi3Error;
    /* variable by variable, time among them; each read leaves the model as it was (outputs are evaluated lazily) */
    size_t j = 0;
    for (size_t i = 0; i < nvr; i++) {
        const fmi3_variable *v = &self->variables[vr[i]];
        if (v->kind == FMI3_TIME) {
            values[j++] = fmu_model_time(self->model);
            continue;
        }
        const int result = fmu_model_get_real(self->model, self->scratch + j, v->count, values + j,
                                              self->mode >= MODE_STEPPING, self->msg);
        if (result != FMU_OK) return report(self, fn, result);
        j += v->count;
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    ENTER("fmi3SetFloat64");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi3Error;
    if (!vr_arguments(self, fn, vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++)
        if (vr[i] < self->n_variables && self->variables[vr[i]].kind == FMI3_TIME)
            return refuse(self, fn, "valueReferences[%zu] = %u is time, the independent variable: it is not set "
                          "(doStep advances it)", i, (unsigned)vr[i]);
    if (!expand(self, fn, "valueReferences", vr, nvr, KIND(FMI3_FLOAT64), nValues, "nValues", 0)) return fmi3Error;
    /* one call: the model checks every value before it sets any */
    return changed_by(self, report(self, fn, fmu_model_set_real(self->model, self->scratch, nValues, values,
                                                                self->mode >= MODE_STEPPING, self->msg)));
}

fmi3Status fmi3GetString(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, fmi3String values[],
                         size_t nValues)
{
    ENTER("fmi3GetString");
    if (!vr_arguments(self, fn, vr, nvr, values, nValues)) return fmi3Error;
    if (!expand(self, fn, "valueReferences", vr, nvr, KIND(FMI3_STRING), nValues, "nValues", 0)) return fmi3Error;
    return report(self, fn, fmu_model_get_string(self->model, self->scratch, nValues, values, self->msg));
}

fmi3Status fmi3SetString(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, const fmi3String values[],
                         size_t nValues)
{
    ENTER("fmi3SetString");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi3Error;
    if (!vr_arguments(self, fn, vr, nvr, values, nValues)) return fmi3Error;
    if (!expand(self, fn, "valueReferences", vr, nvr, KIND(FMI3_STRING), nValues, "nValues", 0)) return fmi3Error;
    return changed_by(self, report(self, fn, fmu_model_set_string(self->model, self->scratch, nValues, values,
                                                                  self->mode >= MODE_STEPPING, self->msg)));
}

/* The model takes Booleans as ints (fmu_model.h); fmi3Boolean is C's bool. */
fmi3Status fmi3GetBoolean(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues)
{
    ENTER("fmi3GetBoolean");
    if (!vr_arguments(self, fn, vr, nvr, values, nValues)) return fmi3Error;
    if (!expand(self, fn, "valueReferences", vr, nvr, KIND(FMI3_BOOLEAN), nValues, "nValues", 0)) return fmi3Error;
    int *flags = malloc((nValues ? nValues : 1) * sizeof *flags);
    if (flags == NULL) return refuse(self, fn, "out of memory for %zu values", nValues);
    const int result = fmu_model_get_boolean(self->model, self->scratch, nValues, flags, self->msg);
    if (result == FMU_OK)
        for (size_t i = 0; i < nValues; i++) values[i] = flags[i] != 0;
    free(flags);
    return report(self, fn, result);
}

fmi3Status fmi3SetBoolean(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues)
{
    ENTER("fmi3SetBoolean");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi3Error;
    if (!vr_arguments(self, fn, vr, nvr, values, nValues)) return fmi3Error;
    if (!expand(self, fn, "valueReferences", vr, nvr, KIND(FMI3_BOOLEAN), nValues, "nValues", 0)) return fmi3Error;
    int *flags = malloc((nValues ? nValues : 1) * sizeof *flags);
    if (flags == NULL) return refuse(self, fn, "out of memory for %zu values", nValues);
    for (size_t i = 0; i < nValues; i++) flags[i] = values[i] ? 1 : 0;
    const int result = fmu_model_set_boolean(self->model, self->scratch, nValues, flags, self->mode >= MODE_STEPPING,
                                             self->msg);
    free(flags);
    return changed_by(self, report(self, fn, result));
}

/* The types this FMU has no variables of: any value reference given is refused, naming what it is. */
static fmi3Status no_such_type(instance *self, const char *fn, const char *type, const fmi3ValueReference vr[],
                               size_t nvr)
{
    if (nvr == 0) return fmi3OK;
    if (vr == NULL) return refuse(self, fn, "valueReferences is NULL with nValueReferences = %zu", nvr);
    if (vr[0] >= self->n_variables)
        return refuse(self, fn, "valueReferences[0] = %u is not a value reference of this FMU", (unsigned)vr[0]);
    return refuse(self, fn, "valueReferences[0] = %u is %s, a variable of type %s, not %s (this FMU has Float64, "
                  "String and Boolean variables only)", (unsigned)vr[0], self->variables[vr[0]].name,
                  kind_names[self->variables[vr[0]].kind], type);
}

#define NO_SUCH_TYPE(Type, ctype)                                                                                  \
    fmi3Status fmi3Get##Type(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, ctype values[],    \
                             size_t nValues)                                                                       \
    {                                                                                                              \
        (void)values, (void)nValues;                                                                               \
        ENTER("fmi3Get" #Type);                                                                                    \
        return no_such_type(self, fn, #Type, vr, nvr);                                                             \
    }                                                                                                              \
    fmi3Status fmi3Set##Type(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, const ctype values[], \
                             size_t nValues)                                                                       \
    {                                                                                                              \
        (void)values, (void)nValues;                                                                               \
        ENTER("fmi3Set" #Type);                                                                                    \
        return no_such_type(self, fn, #Type, vr, nvr);                                                             \
    }

NO_SUCH_TYPE(Float32, fmi3Float32)
NO_SUCH_TYPE(Int8, fmi3Int8)
NO_SUCH_TYPE(UInt8, fmi3UInt8)
NO_SUCH_TYPE(Int16, fmi3Int16)
NO_SUCH_TYPE(UInt16, fmi3UInt16)
NO_SUCH_TYPE(Int32, fmi3Int32)
NO_SUCH_TYPE(UInt32, fmi3UInt32)
NO_SUCH_TYPE(Int64, fmi3Int64)
NO_SUCH_TYPE(UInt64, fmi3UInt64)

fmi3Status fmi3GetBinary(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{
    (void)valueSizes, (void)values, (void)nValues;
    ENTER("fmi3GetBinary");
    return no_such_type(self, fn, "Binary", vr, nvr);
}

fmi3Status fmi3SetBinary(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    (void)valueSizes, (void)values, (void)nValues;
    ENTER("fmi3SetBinary");
    return no_such_type(self, fn, "Binary", vr, nvr);
}

fmi3Status fmi3GetClock(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{
    (void)values;
    ENTER("fmi3GetClock");
    return no_such_type(self, fn, "Clock", vr, nvr);
}

fmi3Status fmi3SetClock(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[])
{
    (void)values;
    ENTER("fmi3SetClock");
    return no_such_type(self, fn, "Clock", vr, nvr);
}

/* ---- common functions ---------------------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance_, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    ENTER("fmi3SetDebugLogging");
    if (nCategories > 0 && categories == NULL) return refuse(self, fn, "categories is NULL");
    const int events = fmu_model_info_get(self->model)->events;
    const char *unknown = linknet_unknown_log_category(nCategories, categories, events);
    if (unknown)
        return refuse(self, fn, "unknown log category \"%s\" (known: %s)", unknown, linknet_log_categories(events));
    self->logging_on = loggingOn;
    return fmi3OK;
}

static void say_before_instance(const char *name, fmi3InstanceEnvironment environment, fmi3LogMessageCallback logger,
                                const char *format, ...)
{
    instance probe;  /* for messages before the instance exists */
    memset(&probe, 0, sizeof probe);
    probe.name = (char *)name;
    probe.logger = logger;
    probe.environment = environment;
    char text[FMU_MESSAGE];
    va_list args;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    emit_in(&probe, fmi3Error, category_of(fmi3Error), text);
}

/* The FMI 3 variables of the resource's "fmi3.*" entries (written by fmu_src/native/build_fmi3.py) over the model's
   value references, each checked against them, into *table (allocated here); 0, or -1 with the reason in msg. */
static int load_variables(const fmu_resource *r, const fmu_model_info *info, fmi3_variable **table, unsigned *n,
                          char *msg)
{
    int64_t count;
    const char **names = NULL;
    const void *kinds = NULL, *firsts = NULL, *counts = NULL;
    *table = NULL;
    if (fmu_resource_scalar(r, "fmi3.n_variables", 'q', sizeof count, &count, msg, FMU_MESSAGE) != 0) return -1;
    if (count < 1 || count > (int64_t)info->n_real + 3) {
        snprintf(msg, FMU_MESSAGE, "the scene's resource %s: fmi3.n_variables = %lld does not fit the model's %u "
                 "Real variables", fmu_resource_path(r), (long long)count, info->n_real);
        return -1;
    }
    if (fmu_resource_texts(r, "fmi3.names", count, &names, msg, FMU_MESSAGE) != 0
        || fmu_resource_array(r, "fmi3.kind", 'i', sizeof(int32_t), count, 0, &kinds, msg, FMU_MESSAGE) != 0
        || fmu_resource_array(r, "fmi3.first", 'q', sizeof(int64_t), count, 0, &firsts, msg, FMU_MESSAGE) != 0
        || fmu_resource_array(r, "fmi3.count", 'q', sizeof(int64_t), count, 0, &counts, msg, FMU_MESSAGE) != 0) {
        free(names);
        return -1;
    }
    *table = calloc((size_t)count, sizeof **table);
    if (*table == NULL) {
        free(names);
        snprintf(msg, FMU_MESSAGE, "out of memory");
        return -1;
    }
    const int64_t n_real = info->n_real;
    for (int64_t v = 0; v < count; v++) {
        const int32_t kind = ((const int32_t *)kinds)[v];
        const int64_t first = ((const int64_t *)firsts)[v], elements = ((const int64_t *)counts)[v];
        /* each kind over the model's value references: Float64s among the Reals, the String and the Boolean after */
        const int fits = (kind == FMI3_TIME && elements == 1)
                         || (kind == FMI3_FLOAT64 && first >= 0 && elements >= 1 && elements <= n_real - first)
                         || (kind == FMI3_STRING && first == n_real && elements == 1)
                         || (kind == FMI3_BOOLEAN && first == n_real + 1 && elements == 1);
        if (!fits) {
            snprintf(msg, FMU_MESSAGE, "the scene's resource %s: FMI 3 variable %lld (%s) does not fit the model's "
                     "variables", fmu_resource_path(r), (long long)v, names[v]);
            free(names);
            free(*table);
            *table = NULL;
            return -1;
        }
        (*table)[v].name = names[v];
        (*table)[v].kind = (unsigned)kind;
        (*table)[v].first = (unsigned)(kind == FMI3_TIME ? 0 : first);
        (*table)[v].count = (unsigned)elements;
    }
    free(names);  /* the texts themselves stay in the resource */
    *n = (unsigned)count;
    return 0;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)visible, (void)requiredIntermediateVariables, (void)intermediateUpdate;
    (void)earlyReturnAllowed;  /* a step is never returned from early: allowed or not, nothing changes */
    const char *fn = "fmi3InstantiateCoSimulation";
    instance *self = calloc(1, sizeof *self);
    if (self == NULL) {
        say_before_instance(instanceName ? instanceName : "(unnamed instance)", instanceEnvironment, logMessage,
                            "%s: out of memory", fn);
        return NULL;
    }
    /* the scene: FMI 3.0's resourcePath is the resources folder's path itself (with a trailing separator) */
    if (resourcePath == NULL || resourcePath[0] == '\0')
        snprintf(self->msg, sizeof self->msg, "resourcePath is %s: this FMU reads its scene from resources/"
                 FMU_RESOURCE_FILE " and needs the path of the unzipped FMU's resources folder",
                 resourcePath ? "empty" : "NULL");
    else if ((self->resource = fmu_resource_load(resourcePath, self->msg, sizeof self->msg)) != NULL
             && (self->model = fmu_model_new(self->resource, self->msg)) != NULL)
        load_variables(self->resource, fmu_model_info_get(self->model), &self->variables, &self->n_variables,
                       self->msg);
    const fmu_model_info *info = self->model ? fmu_model_info_get(self->model) : NULL;
    const char *name = instanceName ? instanceName : info ? info->model_identifier : "(unnamed instance)";
    int refused = 1;
    if (self->variables == NULL)
        say_before_instance(name, instanceEnvironment, logMessage, "%s: %s", fn, self->msg);
    else if (instantiationToken == NULL || strcmp(instantiationToken, info->guid) != 0)
        say_before_instance(name, instanceEnvironment, logMessage, "%s: instantiationToken \"%s\" is not this FMU's "
                            "(%s): the modelDescription.xml and the resources come from different builds", fn,
                            instantiationToken ? instantiationToken : "(null)", info->guid);
    else if (eventModeUsed)
        say_before_instance(name, instanceEnvironment, logMessage, "%s: eventModeUsed is true, but %s has no event "
                            "mode (hasEventMode=\"false\")", fn, info->model_identifier);
    else if (nRequiredIntermediateVariables > 0)
        say_before_instance(name, instanceEnvironment, logMessage, "%s: %zu intermediate variables required, but %s "
                            "provides no intermediate update", fn, nRequiredIntermediateVariables,
                            info->model_identifier);
    else
        refused = 0;
    char *copy = refused ? NULL : malloc(strlen(name) + 1);
    if (copy == NULL) {
        if (!refused) say_before_instance(name, instanceEnvironment, logMessage, "%s: out of memory", fn);
        free(self->variables);
        fmu_model_free(self->model);
        fmu_resource_free(self->resource);
        free(self);
        return NULL;
    }
    strcpy(copy, name);
    self->name = copy;
    self->logger = logMessage;
    self->environment = instanceEnvironment;
    self->logging_on = loggingOn;
    self->mode = MODE_INSTANTIATED;
    self->magic = INSTANCE_MAGIC;
    return self;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    say_before_instance(instanceName ? instanceName : "(unnamed instance)", instanceEnvironment, logMessage,
                        "fmi3InstantiateModelExchange: this FMU is a Co-Simulation FMU only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    say_before_instance(instanceName ? instanceName : "(unnamed instance)", instanceEnvironment, logMessage,
                        "fmi3InstantiateScheduledExecution: this FMU is a Co-Simulation FMU only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance_)
{
    instance *self = checked(instance_);
    if (self == NULL) return;
    self->magic = 0;
    fmu_state_free_all(&self->states);  /* the states the host did not free: they belong to the instance */
    fmu_discard_free(&self->discard);
    free(self->scratch);
    free(self->variables);
    fmu_model_free(self->model);
    fmu_resource_free(self->resource);  /* after the model and the variables, which point into it */
    free(self->name);
    free(self);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance_, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    /* the integrator's tolerance is the FMU's "tolerance" parameter (as in the FMI 2.0 FMUs); the stop time bounds
       nothing: any doStep is integrated */
    (void)toleranceDefined, (void)tolerance;
    ENTER("fmi3EnterInitializationMode");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED))) return fmi3Error;
    if (!isfinite(startTime)) return refuse(self, fn, "startTime = %g is not finite", startTime);
    if (stopTimeDefined && !(isfinite(stopTime) && stopTime >= startTime))
        return refuse(self, fn, "stopTime = %g must be finite and >= startTime = %g", stopTime, startTime);
    const fmi3Status status = report(self, fn, fmu_model_set_start_time(self->model, startTime, self->msg));
    if (status <= fmi3Warning) self->mode = MODE_INITIALIZATION;
    return changed_by(self, status);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance_)
{
    ENTER("fmi3ExitInitializationMode");
    if (!mode_allows(self, fn, IN(MODE_INITIALIZATION))) return fmi3Error;
    const fmi3Status status = changed_by(self, report(self, fn, fmu_model_initialize(self->model, self->msg)));
    if (status <= fmi3Warning) self->mode = MODE_STEPPING;  /* else: still in initialization mode, fix and retry */
    return status;
}

fmi3Status fmi3Terminate(fmi3Instance instance_)
{
    ENTER("fmi3Terminate");
    if (!mode_allows(self, fn, IN(MODE_STEPPING))) return fmi3Error;
    self->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance_)
{
    ENTER("fmi3Reset");
    const fmi3Status status = changed_by(self, report(self, fn, fmu_model_reset(self->model, self->msg)));
    if (status <= fmi3Warning) self->mode = MODE_INSTANTIATED;
    return status;
}

/* ---- what this FMU does not provide -------------------------------------------------------------- */

#define NOT_PROVIDED(function, why)                                                                                \
    do {                                                                                                           \
        ENTER(function);                                                                                           \
        return refuse(self, fn, "not provided: %s", why);                                                          \
    } while (0)

#define NO_EVENTS "this Co-Simulation FMU has no event mode, clocks or discrete states (hasEventMode=\"false\")"
#define CS_ONLY "a Model Exchange function; this FMU is Co-Simulation only"

fmi3Status fmi3EnterEventMode(fmi3Instance instance_) { NOT_PROVIDED("fmi3EnterEventMode", NO_EVENTS); }
fmi3Status fmi3EnterStepMode(fmi3Instance instance_) { NOT_PROVIDED("fmi3EnterStepMode", NO_EVENTS); }
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance_)
{
    NOT_PROVIDED("fmi3EvaluateDiscreteStates", NO_EVENTS);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance_, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    (void)discreteStatesNeedUpdate, (void)terminateSimulation, (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged, (void)nextEventTimeDefined, (void)nextEventTime;
    NOT_PROVIDED("fmi3UpdateDiscreteStates", NO_EVENTS);
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance_)
{
    NOT_PROVIDED("fmi3EnterConfigurationMode", "this FMU has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance_)
{
    NOT_PROVIDED("fmi3ExitConfigurationMode", "this FMU has no structural parameters");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr, (void)nvr, (void)intervals, (void)qualifiers;
    NOT_PROVIDED("fmi3GetIntervalDecimal", NO_EVENTS);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr, (void)nvr, (void)counters, (void)resolutions, (void)qualifiers;
    NOT_PROVIDED("fmi3GetIntervalFraction", NO_EVENTS);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[])
{
    (void)vr, (void)nvr, (void)shifts;
    NOT_PROVIDED("fmi3GetShiftDecimal", NO_EVENTS);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    NOT_PROVIDED("fmi3GetShiftFraction", NO_EVENTS);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[])
{
    (void)vr, (void)nvr, (void)intervals;
    NOT_PROVIDED("fmi3SetIntervalDecimal", NO_EVENTS);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    NOT_PROVIDED("fmi3SetIntervalFraction", NO_EVENTS);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[])
{
    (void)vr, (void)nvr, (void)shifts;
    NOT_PROVIDED("fmi3SetShiftDecimal", NO_EVENTS);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    NOT_PROVIDED("fmi3SetShiftFraction", NO_EVENTS);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance_, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference, (void)activationTime;
    NOT_PROVIDED("fmi3ActivateModelPartition", "a Scheduled Execution function; this FMU is Co-Simulation only");
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance_, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference, (void)nDependencies;
    NOT_PROVIDED("fmi3GetNumberOfVariableDependencies",
                 "providesPerElementDependencies is false (the ModelStructure lists each array's dependencies)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance_, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents;
    (void)dependencyKinds, (void)nDependencies;
    NOT_PROVIDED("fmi3GetVariableDependencies",
                 "providesPerElementDependencies is false (the ModelStructure lists each array's dependencies)");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance_, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    NOT_PROVIDED("fmi3GetAdjointDerivative", "providesAdjointDerivatives is false (fmi3GetDirectionalDerivative is "
                 "provided)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance_, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    (void)vr, (void)orders, (void)values, (void)nValues;
    ENTER("fmi3GetOutputDerivatives");
    if (nvr == 0) return fmi3OK;
    return refuse(self, fn, "not provided (maxOutputDerivativeOrder is 0)");
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance_) { NOT_PROVIDED("fmi3EnterContinuousTimeMode", CS_ONLY); }

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance_, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    NOT_PROVIDED("fmi3CompletedIntegratorStep", CS_ONLY);
}

fmi3Status fmi3SetTime(fmi3Instance instance_, fmi3Float64 time)
{
    (void)time;
    NOT_PROVIDED("fmi3SetTime", CS_ONLY);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance_, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates, (void)nContinuousStates;
    NOT_PROVIDED("fmi3SetContinuousStates", CS_ONLY);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance_, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    (void)derivatives, (void)nContinuousStates;
    NOT_PROVIDED("fmi3GetContinuousStateDerivatives", CS_ONLY);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance_, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    (void)eventIndicators, (void)nEventIndicators;
    NOT_PROVIDED("fmi3GetEventIndicators", CS_ONLY);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance_, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    (void)continuousStates, (void)nContinuousStates;
    NOT_PROVIDED("fmi3GetContinuousStates", CS_ONLY);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance_, fmi3Float64 nominals[], size_t nContinuousStates)
{
    (void)nominals, (void)nContinuousStates;
    NOT_PROVIDED("fmi3GetNominalsOfContinuousStates", CS_ONLY);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance_, size_t *nEventIndicators)
{
    (void)nEventIndicators;
    NOT_PROVIDED("fmi3GetNumberOfEventIndicators", CS_ONLY);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance_, size_t *nContinuousStates)
{
    (void)nContinuousStates;
    NOT_PROVIDED("fmi3GetNumberOfContinuousStates", CS_ONLY);
}

/* ---- directional derivatives --------------------------------------------------------------------- */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance_, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    ENTER("fmi3GetDirectionalDerivative");
    if (self->mode == MODE_INSTANTIATED || self->mode == MODE_INITIALIZATION)
        return refuse(self, fn, "called in %s: derivatives are given at the current state once "
                      "fmi3ExitInitializationMode has fixed the parameters", mode_names[self->mode]);
    if (nUnknowns > 0 && unknowns == NULL) return refuse(self, fn, "unknowns is NULL with nUnknowns = %zu", nUnknowns);
    if (nKnowns > 0 && knowns == NULL) return refuse(self, fn, "knowns is NULL with nKnowns = %zu", nKnowns);
    if (nSeed > 0 && seed == NULL) return refuse(self, fn, "seed is NULL with nSeed = %zu", nSeed);
    if (nSensitivity > 0 && sensitivity == NULL)
        return refuse(self, fn, "sensitivity is NULL with nSensitivity = %zu", nSensitivity);
    /* the unknowns' elements, then the knowns', in one list: the model names what is not an output or an input */
    if (!expand(self, fn, "knowns", knowns, nKnowns, KIND(FMI3_FLOAT64), nSeed, "nSeed", nSensitivity))
        return fmi3Error;
    if (!expand(self, fn, "unknowns", unknowns, nUnknowns, KIND(FMI3_FLOAT64), nSensitivity, "nSensitivity", 0))
        return fmi3Error;
    return report(self, fn, fmu_model_directional_derivative(self->model, self->scratch, nSensitivity,
                                                             self->scratch + nSensitivity, nSeed, seed, sensitivity,
                                                             self->msg));
}

/* ---- FMU states ---------------------------------------------------------------------------------- */

#define NOT_A_LIVE_STATE                                                                                         \
    "FMUState is not a live state of this FMU instance (one it made with fmi3GetFMUState or "                  \
    "fmi3DeserializeFMUState and has not freed): a made-up handle, one already freed, or another FMU's or "    \
    "instance's; nothing was read or changed (a state moves to another instance serialized)"
#define HANDLE_FOR_ADDRESS                                                                                       \
    "FMUState is a state handle itself where the address of the host's fmi3FMUState variable belongs (call "  \
    "%s(instance, &state), not %s(instance, (fmi3FMUState *)state)); nothing was freed or written: the state "  \
    "stays live, and fmi3FreeInstance frees it if the host does not"

/* A state handle given by the host by value: live in this instance, or NULL after logging why not. */
static fmu_state_header *live_state(instance *self, const char *fn, fmi3FMUState FMUState)
{
    if (FMUState == NULL) {
        refuse(self, fn, "FMUState is NULL");
        return NULL;
    }
    if (!fmu_state_is_live(&self->states, FMUState)) {
        refuse(self, fn, NOT_A_LIVE_STATE);
        return NULL;
    }
    return (fmu_state_header *)FMUState;
}

/* The address of the host's state variable: 1 when it may be read and written, else 0 after logging why. A live
   state's own handle passed as that address is recognised by the registry before anything is read through it. */
static int state_variable(instance *self, const char *fn, const fmi3FMUState *FMUState)
{
    if (FMUState == NULL) {
        refuse(self, fn, "FMUState is NULL (the address of the host's fmi3FMUState variable is expected)");
        return 0;
    }
    if (fmu_state_is_live(&self->states, FMUState)) {
        refuse(self, fn, HANDLE_FOR_ADDRESS, fn, fn);
        return 0;
    }
    return 1;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance_, fmi3FMUState *FMUState)
{
    ENTER("fmi3GetFMUState");
    if (!state_variable(self, fn, FMUState)) return fmi3Error;
    fmu_state_header *h = NULL;
    if (*FMUState != NULL) {  /* a state of this instance to overwrite */
        if ((h = live_state(self, fn, *FMUState)) == NULL) return fmi3Error;
    } else {
        h = calloc(1, fmu_state_size(self->model));
        if (h == NULL) return refuse(self, fn, "out of memory for a state of %zu bytes", fmu_state_size(self->model));
        if (!fmu_state_remember(&self->states, h)) {
            free(h);
            return refuse(self, fn, "out of memory for the list of this instance's states");
        }
    }
    fmu_state_write(h, self->model, (uint32_t)self->mode);
    *FMUState = h;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance_, fmi3FMUState FMUState)
{
    ENTER("fmi3SetFMUState");
    const fmu_state_header *h = live_state(self, fn, FMUState);
    if (h == NULL) return fmi3Error;
    const int result = fmu_model_state_restore(self->model, (const unsigned char *)(h + 1),
                                               (size_t)h->size - sizeof *h, self->msg);
    if (result != FMU_OK) return report(self, fn, result);
    self->mode = (int)h->mode;
    return changed_by(self, fmi3OK);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance_, fmi3FMUState *FMUState)
{
    ENTER("fmi3FreeFMUState");
    if (!state_variable(self, fn, FMUState)) return fmi3Error;
    if (*FMUState == NULL) return fmi3OK;  /* nothing to free (FMI: the variable of a freed state holds NULL) */
    const size_t i = fmu_state_index(&self->states, *FMUState);
    if (i == self->states.n) return refuse(self, fn, NOT_A_LIVE_STATE);
    fmu_state_free_at(&self->states, i);
    *FMUState = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance_, fmi3FMUState FMUState, size_t *size)
{
    ENTER("fmi3SerializedFMUStateSize");
    if (size == NULL) return refuse(self, fn, "size is NULL");
    const fmu_state_header *h = live_state(self, fn, FMUState);
    if (h == NULL) return fmi3Error;
    *size = (size_t)h->size;
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance_, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    ENTER("fmi3SerializeFMUState");
    const fmu_state_header *h = live_state(self, fn, FMUState);
    if (h == NULL) return fmi3Error;
    if (serializedState == NULL) return refuse(self, fn, "serializedState is NULL");
    if (size < h->size) return refuse(self, fn, "buffer of %zu bytes for a state of %zu", size, (size_t)h->size);
    fmu_state_serialize(h, serializedState);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance_, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    ENTER("fmi3DeserializeFMUState");
    if (!state_variable(self, fn, FMUState)) return fmi3Error;
    if (serializedState == NULL) return refuse(self, fn, "serializedState is NULL");
    const char *problem = fmu_state_serialized_problem(self->model, serializedState, size, MODE_TERMINATED);
    if (problem) return refuse(self, fn, "refused: %s", problem);
    fmu_state_header *h = malloc(size);
    if (h == NULL) return refuse(self, fn, "out of memory for a state of %zu bytes", size);
    if (!fmu_state_remember(&self->states, h)) {
        free(h);
        return refuse(self, fn, "out of memory for the list of this instance's states");
    }
    memcpy(h, serializedState, size);
    h->reserved2 = 0;
    h->checksum = 0;
    *FMUState = h;
    return fmi3OK;
}

/* ---- co-simulation ------------------------------------------------------------------------------- */

fmi3Status fmi3DoStep(fmi3Instance instance_, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    ENTER("fmi3DoStep");
    if (eventHandlingNeeded == NULL || terminateSimulation == NULL || earlyReturn == NULL || lastSuccessfulTime == NULL)
        return refuse(self, fn, "%s is NULL (the address of the host's variable is expected)",
                      eventHandlingNeeded == NULL ? "eventHandlingNeeded"
                      : terminateSimulation == NULL ? "terminateSimulation"
                      : earlyReturn == NULL ? "earlyReturn" : "lastSuccessfulTime");
    /* no events, never an early return; the time the FMU is at, whatever happens below */
    *eventHandlingNeeded = fmi3False;
    *earlyReturn = fmi3False;
    *terminateSimulation = self->terminated ? fmi3True : fmi3False;
    *lastSuccessfulTime = fmu_model_time(self->model);
    if (self->mode != MODE_STEPPING) {
        if (self->mode == MODE_INSTANTIATED || self->mode == MODE_INITIALIZATION)
            return refuse(self, fn, "called in %s: call fmi3ExitInitializationMode first", mode_names[self->mode]);
        return refuse(self, fn, "called after fmi3Terminate (fmi3Reset starts again)");
    }
    const double t = currentCommunicationPoint, h = communicationStepSize;
    if (!(isfinite(h) && h > 0.0))
        return refuse(self, fn, "communication step size h=%.17g must be finite and > 0", h);
    const double t_fmu = fmu_model_time(self->model), scale = fabs(t_fmu) > 1.0 ? fabs(t_fmu) : 1.0;  /* no libm */
    if (!isfinite(t) || fabs(t - t_fmu) > 1e-9 * scale)
        return refuse(self, fn, "currentCommunicationPoint t=%.17g differs from the FMU's time %.17g", t, t_fmu);
    if (!isfinite(t + h)) return refuse(self, fn, "t + h = %.17g is not finite", t + h);
    if (fmu_discard_is_repeat(&self->discard, self->model, t, h)) {
        self->terminated = 1;
        *terminateSimulation = fmi3True;
        logf_status(self, fmi3Discard, "%s: terminateSimulation is true (lastSuccessfulTime = %.17g): " REPEATED_STEP
                    " It failed with: %s", fn, t_fmu, t, h, self->discard.reason);
        return fmi3Discard;
    }
    const int result = fmu_model_do_step(self->model, t, h, self->msg);
    *lastSuccessfulTime = fmu_model_time(self->model);
    if (result != FMU_DISCARD && result != FMU_DISCARD_FINAL) {
        self->discard.discarded = 0;
        log_events(self);
        const fmi3Status status = changed_by(self, report(self, fn, result));
        *terminateSimulation = self->terminated ? fmi3True : fmi3False;
        return status;
    }
    fmu_discard_remember(&self->discard, self->model, t, h, self->msg);
    self->terminated = result == FMU_DISCARD_FINAL;
    *terminateSimulation = self->terminated ? fmi3True : fmi3False;
    if (!self->terminated) return report(self, fn, result);
    logf_status(self, fmi3Discard, "%s: %s; so terminateSimulation is true (lastSuccessfulTime = %.17g)", fn,
                self->msg, t_fmu);
    return fmi3Discard;
}

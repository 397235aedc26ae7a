/* FMI 2.0 Co-Simulation glue, written once for every linknet scene and ignorant of the physics: it drives
 * the model of fmu_model.h (linknet_model.c with a scene's data from the FMU's resources) the way the Modelica
 * Reference-FMUs' fmi2Functions.c drives each model.c.
 *
 * Contract (docs: fmu_src/native/README.md):
 * - no call ever returns fmi2Fatal or brings the process down: a bad argument, a bad value or a call out of
 *   order returns fmi2Error with a logged message and changes nothing, so the instance stays usable; a
 *   step the solver cannot complete returns fmi2Discard and leaves the state where it was;
 * - after a discarded step fmi2GetBooleanStatus(fmi2Terminated) says whether the master should stop: true where
 *   the model knows that no retry of the step, however short, can succeed (fmu_model.h FMU_DISCARD_FINAL), and
 *   when the master asks for the very step that was discarded again from the same model state (its bytes, which
 *   hold the inputs and parameters too: whatever was set or restored in between): the model is deterministic, so
 *   it would fail the same way, and such a repeat is answered without being computed. fmi2LastSuccessfulTime is
 *   the FMU's time, where a discarded step leaves it. A master that retries the same step forever (fmpy's
 *   simulate_fmu, fmusim) so stops after at most one repeat, with the reason logged;
 * - an FMU state handle is accepted only when this instance made it and has not freed it (a registry, not a mark
 *   in the state's memory): a NULL, made-up, freed or foreign handle, a double free, and a state handle passed
 *   where the address of the host's variable belongs are fmi2Error with a logged message, nothing is read or
 *   written through them, and the instance goes on working. fmi2FreeInstance frees the states the host left;
 * - errors, discards and warnings always reach the host's logger (with loggingOn or not); other messages
 *   only with logging on;
 * - instances share no mutable data: several instances, on several threads, are independent (one
 *   instance must not be called from two threads at once, as FMI requires);
 * - an FMU state is a block of bytes with a header (format version, byte order, the model's fingerprint,
 *   size) that fmi2SetFMUstate and fmi2DeSerializeFMUstate check, so a state of another FMU is refused.
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_api.h"
#include "fmu_model.h"
#include "fmu_states.h"

enum mode { MODE_INSTANTIATED = 0, MODE_INITIALIZATION = 1, MODE_STEPPING = 2, MODE_TERMINATED = 3 };
static const char *const mode_names[] = {"instantiated (before fmi2EnterInitializationMode)",
                                         "initialization mode", "step mode", "terminated"};

#define INSTANCE_MAGIC 0x6c6e4b49u  /* a live instance; cleared when it is freed */

typedef struct instance {
    unsigned magic;
    char *name;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment environment;
    int logging_on;
    int mode;
    fmu_resource *resource;             /* the scene's data (fmu_resource.h): the model points into it */
    fmu_model *model;
    char msg[FMU_MESSAGE];              /* the model's reason for a refusal */
    char line[2 * FMU_MESSAGE + 256];   /* the logged message, format characters escaped */
    fmu_state_registry states;          /* the FMU states this instance handed out and has not freed */
    fmu_discard_memory discard;         /* the last discarded step and the state it was discarded from */
    int terminated;                     /* fmi2Terminated: the master should stop (at fmi2LastSuccessfulTime) */
} instance;

/* ---- logging ------------------------------------------------------------------------------------- */

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

/* The logger's message is a printf format with FMI's #<type><vr># references: a message that is plain text
   has its '%' and '#' doubled, so that hosts which expand them print it as written. */
static void emit_in(instance *self, fmi2Status status, const char *category, const char *text)
{
    if (status == fmi2OK && !self->logging_on) return;
    size_t j = 0;
    const size_t cap = sizeof self->line - 1;
    for (const char *p = text; *p && j + 2 < cap; p++) {
        if (*p == '%' || *p == '#') self->line[j++] = *p;
        self->line[j++] = *p;
    }
    self->line[j] = '\0';
    if (self->logger)
        self->logger(self->environment, self->name, status, category, self->line);
    else
        fprintf(stderr, "[%s] %s: %s\n", self->name, category, text);
}

static void emit(instance *self, fmi2Status status, const char *text) { emit_in(self, status, category_of(status), text); }

static void logf_status(instance *self, fmi2Status status, const char *format, ...)
{
    char text[FMU_MESSAGE + 512];  /* a model's message and the glue's words around it */
    va_list args;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    emit(self, status, text);
}

static fmi2Status refuse(instance *self, const char *function, const char *format, ...)
{
    char text[FMU_MESSAGE];
    va_list args;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    logf_status(self, fmi2Error, "%s: %s", function, text);
    return fmi2Error;
}

/* A model result as an FMI status, with the model's reason logged. */
static fmi2Status report(instance *self, const char *function, int result)
{
    switch (result) {
    case FMU_OK: return fmi2OK;
    case FMU_WARNING: logf_status(self, fmi2Warning, "%s: %s", function, self->msg); return fmi2Warning;
    case FMU_DISCARD:
    case FMU_DISCARD_FINAL: logf_status(self, fmi2Discard, "%s: %s", function, self->msg); return fmi2Discard;
    case FMU_NOTE: {  /* information on a result computed as asked: seen by the host, the call is fmi2OK */
        char text[FMU_MESSAGE + 256];
        snprintf(text, sizeof text, "%s: %s", function, self->msg);
        emit_in(self, fmi2Warning, LINKNET_NOTE_CATEGORY, text);
        return fmi2OK;
    }
    default: logf_status(self, fmi2Error, "%s: %s", function, self->msg); return fmi2Error;
    }
}

/* The events of the step just taken, one message each with fmi2OK status in their own category (logging on). */
static void log_events(instance *self)
{
    if (!self->logging_on) return;
    char text[FMU_MESSAGE];
    for (size_t i = 0; fmu_model_event(self->model, i, text, sizeof text); i++)
        emit_in(self, fmi2OK, LINKNET_EVENT_CATEGORY, text);
}

/* The instance behind a component handle, or NULL for a handle that is not a live instance of this FMU (no
   logger can be reached through such a handle). */
static instance *checked(fmi2Component c)
{
    instance *self = (instance *)c;
    if (self == NULL || self->magic != INSTANCE_MAGIC) return NULL;
    self->msg[0] = '\0';
    return self;
}

static int mode_allows(instance *self, const char *function, unsigned allowed)
{
    if (allowed & (1u << self->mode)) return 1;
    refuse(self, function, "not allowed in %s", mode_names[self->mode]);
    return 0;
}

/* A call that may change what a step computes (a value set, a state restored, a reset) succeeded: the master is
   no longer asked to stop (whether the discarded step is asked again from the same state, fmi2DoStep tells). */
static fmi2Status changed_by(instance *self, fmi2Status status)
{
    if (status <= fmi2Warning) self->terminated = 0;
    return status;
}

#define IN(mode) (1u << (mode))
#define ANY_MODE (IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEPPING) | IN(MODE_TERMINATED))

#define ENTER(function)                           \
    instance *self = checked(c);                  \
    if (self == NULL) return fmi2Error;           \
    const char *const fn = function

/* ---- common functions ---------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    ENTER("fmi2SetDebugLogging");
    if (nCategories > 0 && categories == NULL) return refuse(self, fn, "categories is NULL");
    const int events = fmu_model_info_get(self->model)->events;
    const char *unknown = linknet_unknown_log_category(nCategories, categories, events);
    if (unknown)
        return refuse(self, fn, "unknown log category \"%s\" (known: %s)", unknown, linknet_log_categories(events));
    self->logging_on = loggingOn != fmi2False;
    return fmi2OK;
}

/* The scene's resource (fmu_resource.h) in the folder FMI names and a model of it, or NULL with the reason logged as
   the probe instance's. */
static fmu_model *load_model(instance *probe, const char *location, fmu_resource **resource)
{
    char folder[4096];
    *resource = NULL;
    if (fmu_resource_folder_of_uri(location, folder, sizeof folder, probe->msg, sizeof probe->msg) != 0
        || (*resource = fmu_resource_load(folder, probe->msg, sizeof probe->msg)) == NULL) {
        logf_status(probe, fmi2Error, "fmi2Instantiate: %s", probe->msg);
        return NULL;
    }
    fmu_model *model = fmu_model_new(*resource, probe->msg);
    if (model == NULL) {
        logf_status(probe, fmi2Error, "fmi2Instantiate: %s", probe->msg);
        fmu_resource_free(*resource);
        *resource = NULL;
    }
    return model;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)visible;
    instance *probe = calloc(1, sizeof *probe);  /* for messages before the instance exists; the instance, if it is */
    if (probe == NULL) return NULL;  /* no memory to say so with */
    probe->name = (char *)(instanceName ? instanceName : "(unnamed instance)");
    probe->logger = functions ? functions->logger : NULL;
    probe->environment = functions ? functions->componentEnvironment : NULL;
    fmu_resource *resource;
    fmu_model *model = load_model(probe, fmuResourceLocation, &resource);
    if (model == NULL) {
        free(probe);
        return NULL;
    }
    const fmu_model_info *info = fmu_model_info_get(model);
    const char *refusal = NULL;
    if (fmuType != fmi2CoSimulation) {
        logf_status(probe, fmi2Error, "fmi2Instantiate: %s is a Co-Simulation FMU only (fmuType %d requested)",
                    info->model_identifier, (int)fmuType);
        refusal = "type";
    } else if (fmuGUID == NULL || strcmp(fmuGUID, info->guid) != 0) {
        logf_status(probe, fmi2Error, "fmi2Instantiate: GUID \"%s\" is not this FMU's (%s): the "
                    "modelDescription.xml and the resources come from different builds",
                    fmuGUID ? fmuGUID : "(null)", info->guid);
        refusal = "guid";
    }
    instance *self = probe;
    const char *name = instanceName ? instanceName : info->model_identifier;
    char *copy = refusal ? NULL : malloc(strlen(name) + 1);
    if (copy == NULL) {
        if (!refusal) logf_status(probe, fmi2Error, "fmi2Instantiate: out of memory");
        fmu_model_free(model);
        fmu_resource_free(resource);
        free(probe);
        return NULL;
    }
    strcpy(copy, name);
    self->name = copy;
    self->logging_on = loggingOn != fmi2False;
    self->mode = MODE_INSTANTIATED;
    self->resource = resource;
    self->model = model;
    self->magic = INSTANCE_MAGIC;
    return self;
}

void fmi2FreeInstance(fmi2Component c)
{
    instance *self = checked(c);
    if (self == NULL) return;
    self->magic = 0;
    fmu_state_free_all(&self->states);  /* the states the host did not free: they belong to the instance */
    fmu_discard_free(&self->discard);
    fmu_model_free(self->model);
    fmu_resource_free(self->resource);  /* after the model, which points into it */
    free(self->name);
    free(self);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    /* the integrator's tolerance is the FMU's "tolerance" parameter (as in the pythonfmu FMU); the stop
       time bounds nothing: any doStep is integrated */
    (void)toleranceDefined;
    (void)tolerance;
    ENTER("fmi2SetupExperiment");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED))) return fmi2Error;
    if (!isfinite(startTime)) return refuse(self, fn, "startTime = %g is not finite", startTime);
    if (stopTimeDefined && !(isfinite(stopTime) && stopTime >= startTime))
        return refuse(self, fn, "stopTime = %g must be finite and >= startTime = %g", stopTime, startTime);
    return changed_by(self, report(self, fn, fmu_model_set_start_time(self->model, startTime, self->msg)));
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    ENTER("fmi2EnterInitializationMode");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED))) return fmi2Error;
    self->mode = MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    ENTER("fmi2ExitInitializationMode");
    if (!mode_allows(self, fn, IN(MODE_INITIALIZATION))) return fmi2Error;
    const fmi2Status status = changed_by(self, report(self, fn, fmu_model_initialize(self->model, self->msg)));
    if (status <= fmi2Warning) self->mode = MODE_STEPPING;  /* else: still in initialization mode, fix and retry */
    return status;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    ENTER("fmi2Terminate");
    if (!mode_allows(self, fn, IN(MODE_STEPPING))) return fmi2Error;
    self->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    ENTER("fmi2Reset");
    const fmi2Status status = changed_by(self, report(self, fn, fmu_model_reset(self->model, self->msg)));
    if (status <= fmi2Warning) self->mode = MODE_INSTANTIATED;
    return status;
}

/* ---- values -------------------------------------------------------------------------------------- */

static int vr_arguments(instance *self, const char *fn, const void *vr, size_t nvr, const void *value)
{
    if (nvr > 0 && (vr == NULL || value == NULL)) {
        refuse(self, fn, "%s is NULL with nvr = %zu", vr == NULL ? "vr" : "value", nvr);
        return 0;
    }
    return 1;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    ENTER("fmi2GetReal");
    if (!vr_arguments(self, fn, vr, nvr, value)) return fmi2Error;
    return report(self, fn, fmu_model_get_real(self->model, vr, nvr, value, self->mode >= MODE_STEPPING, self->msg));
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    ENTER("fmi2SetReal");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi2Error;
    if (!vr_arguments(self, fn, vr, nvr, value)) return fmi2Error;
    return changed_by(self, report(self, fn, fmu_model_set_real(self->model, vr, nvr, value,
                                                                self->mode >= MODE_STEPPING, self->msg)));
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    ENTER("fmi2GetString");
    if (!vr_arguments(self, fn, vr, nvr, value)) return fmi2Error;
    return report(self, fn, fmu_model_get_string(self->model, vr, nvr, value, self->msg));
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    ENTER("fmi2SetString");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi2Error;
    if (!vr_arguments(self, fn, vr, nvr, value)) return fmi2Error;
    return changed_by(self, report(self, fn, fmu_model_set_string(self->model, vr, nvr, value,
                                                                  self->mode >= MODE_STEPPING, self->msg)));
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    ENTER("fmi2GetBoolean");
    if (!vr_arguments(self, fn, vr, nvr, value)) return fmi2Error;
    return report(self, fn, fmu_model_get_boolean(self->model, vr, nvr, value, self->msg));
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    ENTER("fmi2SetBoolean");
    if (!mode_allows(self, fn, IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi2Error;
    if (!vr_arguments(self, fn, vr, nvr, value)) return fmi2Error;
    return changed_by(self, report(self, fn, fmu_model_set_boolean(self->model, vr, nvr, value,
                                                                   self->mode >= MODE_STEPPING, self->msg)));
}

/* The model has no Integer variables. */
static fmi2Status no_such_type(instance *self, const char *fn, const char *type, const fmi2ValueReference vr[],
                               size_t nvr)
{
    if (nvr == 0) return fmi2OK;
    if (vr == NULL) return refuse(self, fn, "vr is NULL with nvr = %zu", nvr);
    return refuse(self, fn, "value reference %u is not a variable of type %s (this FMU has Real, String and "
                  "Boolean variables only)", vr[0], type);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    (void)value;
    ENTER("fmi2GetInteger");
    return no_such_type(self, fn, "Integer", vr, nvr);
}


fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    (void)value;
    ENTER("fmi2SetInteger");
    return no_such_type(self, fn, "Integer", vr, nvr);
}


fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    ENTER("fmi2GetDirectionalDerivative");
    if (self->mode == MODE_INSTANTIATED || self->mode == MODE_INITIALIZATION)
        return refuse(self, fn, "called in %s: derivatives are given at the current state once "
                      "fmi2ExitInitializationMode has fixed the parameters", mode_names[self->mode]);
    if (nUnknown > 0 && (vUnknown_ref == NULL || dvUnknown == NULL))
        return refuse(self, fn, "%s is NULL with nUnknown = %zu", vUnknown_ref == NULL ? "vUnknown_ref" : "dvUnknown",
                      nUnknown);
    if (nKnown > 0 && (vKnown_ref == NULL || dvKnown == NULL))
        return refuse(self, fn, "%s is NULL with nKnown = %zu", vKnown_ref == NULL ? "vKnown_ref" : "dvKnown", nKnown);
    return report(self, fn, fmu_model_directional_derivative(self->model, vUnknown_ref, nUnknown, vKnown_ref, nKnown,
                                                             dvKnown, dvUnknown, self->msg));
}

/* ---- FMU states ---------------------------------------------------------------------------------- */

#define NOT_A_LIVE_STATE                                                                                         \
    "FMUstate is not a live state of this FMU instance (one it made with fmi2GetFMUstate or "                  \
    "fmi2DeSerializeFMUstate and has not freed): a made-up handle, one already freed, or another FMU's or "    \
    "instance's; nothing was read or changed (a state moves to another instance serialized)"
#define HANDLE_FOR_ADDRESS                                                                                       \
    "FMUstate is a state handle itself where the address of the host's fmi2FMUstate variable belongs (call "  \
    "%s(c, &state), not %s(c, (fmi2FMUstate *)state)); nothing was freed or written: the state stays live, "   \
    "and fmi2FreeInstance frees it if the host does not"

/* A state handle given by the host by value: live in this instance, or NULL after logging why not. */
static fmu_state_header *live_state(instance *self, const char *fn, fmi2FMUstate FMUstate)
{
    if (FMUstate == NULL) {
        refuse(self, fn, "FMUstate is NULL");
        return NULL;
    }
    if (!fmu_state_is_live(&self->states, FMUstate)) {
        refuse(self, fn, NOT_A_LIVE_STATE);
        return NULL;
    }
    return (fmu_state_header *)FMUstate;
}

/* The address of the host's state variable (fmi2GetFMUstate, fmi2FreeFMUstate, fmi2DeSerializeFMUstate): 1 when
   it may be read and written, else 0 after logging why. A live state's own handle passed as that address (fmusim
   0.0.39 frees with fmi2FreeFMUstate(c, (fmi2FMUstate *)state)) is recognised by the registry before anything is
   read through it: it is refused, not taken as a request to free that state, since FMI asks the FMU to set the
   host's variable to NULL, which cannot be found here, and a host that gets fmi2OK never learns of its mistake.
   Any other address is the host's to vouch for: C cannot tell whether an arbitrary pointer may be read. */
static int state_variable(instance *self, const char *fn, const fmi2FMUstate *FMUstate)
{
    if (FMUstate == NULL) {
        refuse(self, fn, "FMUstate is NULL (the address of the host's fmi2FMUstate variable is expected)");
        return 0;
    }
    if (fmu_state_is_live(&self->states, FMUstate)) {
        refuse(self, fn, HANDLE_FOR_ADDRESS, fn, fn);
        return 0;
    }
    return 1;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    ENTER("fmi2GetFMUstate");
    if (!state_variable(self, fn, FMUstate)) return fmi2Error;
    fmu_state_header *h = NULL;
    if (*FMUstate != NULL) {  /* a state of this instance to overwrite */
        if ((h = live_state(self, fn, *FMUstate)) == NULL) return fmi2Error;
    } else {
        h = calloc(1, fmu_state_size(self->model));
        if (h == NULL) return refuse(self, fn, "out of memory for a state of %zu bytes", fmu_state_size(self->model));
        if (!fmu_state_remember(&self->states, h)) {
            free(h);
            return refuse(self, fn, "out of memory for the list of this instance's states");
        }
    }
    fmu_state_write(h, self->model, (uint32_t)self->mode);
    *FMUstate = h;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    ENTER("fmi2SetFMUstate");
    const fmu_state_header *h = live_state(self, fn, FMUstate);
    if (h == NULL) return fmi2Error;
    const int result = fmu_model_state_restore(self->model, (const unsigned char *)(h + 1),
                                               (size_t)h->size - sizeof *h, self->msg);
    if (result != FMU_OK) return report(self, fn, result);
    self->mode = (int)h->mode;
    return changed_by(self, fmi2OK);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    ENTER("fmi2FreeFMUstate");
    if (!state_variable(self, fn, FMUstate)) return fmi2Error;
    if (*FMUstate == NULL) return fmi2OK;  /* nothing to free (FMI: the variable of a freed state holds NULL) */
    const size_t i = fmu_state_index(&self->states, *FMUstate);
    if (i == self->states.n) return refuse(self, fn, NOT_A_LIVE_STATE);
    fmu_state_free_at(&self->states, i);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    ENTER("fmi2SerializedFMUstateSize");
    if (size == NULL) return refuse(self, fn, "size is NULL");
    const fmu_state_header *h = live_state(self, fn, FMUstate);
    if (h == NULL) return fmi2Error;
    *size = (size_t)h->size;
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    ENTER("fmi2SerializeFMUstate");
    const fmu_state_header *h = live_state(self, fn, FMUstate);
    if (h == NULL) return fmi2Error;
    if (serializedState == NULL) return refuse(self, fn, "serializedState is NULL");
    if (size < h->size) return refuse(self, fn, "buffer of %zu bytes for a state of %zu", size, (size_t)h->size);
    fmu_state_serialize(h, (unsigned char *)serializedState);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    ENTER("fmi2DeSerializeFMUstate");
    if (!state_variable(self, fn, FMUstate)) return fmi2Error;
    if (serializedState == NULL) return refuse(self, fn, "serializedState is NULL");
    const char *problem = fmu_state_serialized_problem(self->model, (const unsigned char *)serializedState, size,
                                                       MODE_TERMINATED);
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
    *FMUstate = h;
    return fmi2OK;
}

/* ---- co-simulation ------------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    ENTER("fmi2SetRealInputDerivatives");
    if (!mode_allows(self, fn, IN(MODE_INITIALIZATION) | IN(MODE_STEPPING))) return fmi2Error;
    if (nvr > 0 && order == NULL) return refuse(self, fn, "order is NULL with nvr = %zu", nvr);
    if (!vr_arguments(self, fn, vr, nvr, value)) return fmi2Error;
    return changed_by(self, report(self, fn, fmu_model_set_real_input_derivatives(self->model, vr, nvr, order, value,
                                                                                  self->mode >= MODE_STEPPING,
                                                                                  self->msg)));
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)order, (void)value;
    ENTER("fmi2GetRealOutputDerivatives");
    if (nvr == 0) return fmi2OK;
    return refuse(self, fn, "not provided (maxOutputDerivativeOrder is 0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    ENTER("fmi2DoStep");
    if (self->mode != MODE_STEPPING) {
        if (self->mode == MODE_INSTANTIATED || self->mode == MODE_INITIALIZATION)
            return refuse(self, fn, "called in %s: call fmi2ExitInitializationMode first", mode_names[self->mode]);
        return refuse(self, fn, "called after fmi2Terminate (fmi2Reset starts again)");
    }
    const double t = currentCommunicationPoint, h = communicationStepSize;
    if (!(isfinite(h) && h > 0.0))
        return refuse(self, fn, "communication step size h=%.17g must be finite and > 0", h);
    const double t_fmu = fmu_model_time(self->model), scale = fabs(t_fmu) > 1.0 ? fabs(t_fmu) : 1.0;  /* no libm */
    if (!isfinite(t) || fabs(t - t_fmu) > 1e-9 * scale)
        return refuse(self, fn, "currentCommunicationPoint t=%.17g differs from the FMU's time %.17g", t, t_fmu);
    if (!isfinite(t + h)) return refuse(self, fn, "t + h = %.17g is not finite", t + h);
    if (fmu_discard_is_repeat(&self->discard, self->model, t, h)) {
        /* the model is deterministic: from the same state with the same inputs the same step fails again */
        self->terminated = 1;
        logf_status(self, fmi2Discard, "%s: fmi2Terminated is true (fmi2LastSuccessfulTime = %.17g): " REPEATED_STEP
                    " It failed with: %s", fn, t_fmu, t, h, self->discard.reason);
        return fmi2Discard;
    }
    const int result = fmu_model_do_step(self->model, t, h, self->msg);
    if (result != FMU_DISCARD && result != FMU_DISCARD_FINAL) {
        self->discard.discarded = 0;
        log_events(self);
        return changed_by(self, report(self, fn, result));
    }
    fmu_discard_remember(&self->discard, self->model, t, h, self->msg);
    self->terminated = result == FMU_DISCARD_FINAL;
    if (!self->terminated) return report(self, fn, result);
    logf_status(self, fmi2Discard, "%s: %s; so fmi2Terminated is true (fmi2LastSuccessfulTime = %.17g)", fn, self->msg,
                t_fmu);
    return fmi2Discard;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    ENTER("fmi2CancelStep");
    return refuse(self, fn, "no asynchronous step to cancel (steps complete within fmi2DoStep)");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)value;
    ENTER("fmi2GetStatus");
    return refuse(self, fn, "status kind %d is not provided (steps are never pending)", (int)s);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    ENTER("fmi2GetRealStatus");
    if (value == NULL) return refuse(self, fn, "value is NULL");
    if (s != fmi2LastSuccessfulTime) return refuse(self, fn, "status kind %d is not a Real status", (int)s);
    *value = fmu_model_time(self->model);  /* a refused or discarded step leaves the FMU at its start */
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)value;
    ENTER("fmi2GetIntegerStatus");
    return refuse(self, fn, "status kind %d is not an Integer status", (int)s);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    ENTER("fmi2GetBooleanStatus");
    if (value == NULL) return refuse(self, fn, "value is NULL");
    if (s != fmi2Terminated) return refuse(self, fn, "status kind %d is not a Boolean status", (int)s);
    *value = self->terminated ? fmi2True : fmi2False;  /* see fmi2DoStep */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)value;
    ENTER("fmi2GetStringStatus");
    return refuse(self, fn, "status kind %d is not a String status", (int)s);
}

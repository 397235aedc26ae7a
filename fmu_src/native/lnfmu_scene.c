/* A scene's data read from the FMU's resource file (lnfmu_scene.h): the entries the lists name (LNFMU_SCENE_FIELDS,
 * the core's LN_MODEL_FIELDS, LN_RIGID_MODEL_FIELDS and LN_METHOD_FIELDS), each checked for its type and count,
 * pointed to where they lie in the resource, and checked against each other before the model runs on them: an index
 * out of its range would have the core read outside its arrays. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_model.h"
#include "lnfmu_scene.h"

typedef struct loaded {
    lnfmu_scene scene;              /* first: a scene's address is its loaded's */
    ln_model model;
    struct ln_rigid_model rigid;
    lnfmu_method *methods;
    lnfmu_variable *variables;
    const char **mass_names, **event_kind_names, **method_names, **variable_names;  /* the texts' pointer arrays */
} loaded;

#if defined __GNUC__
static int fail(char *msg, const char *format, ...) __attribute__((format(printf, 2, 3)));
#endif

static int fail(char *msg, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(msg, FMU_MESSAGE, format, args);
    va_end(args);
    return -1;
}

/* ---- a struct of a list, entry by entry --------------------------------------------------------- */

/* The entry "<prefix>.<name>" into out; a name too long for an entry (build.py writes none) becomes "", which no
   entry has, so that the read fails naming no other entry. */
static const char *entry_name(char *out, const char *prefix, const char *name)
{
    const int n = snprintf(out, FMU_RESOURCE_NAME, "%s.%s", prefix, name);
    if (n < 0 || n >= FMU_RESOURCE_NAME) out[0] = '\0';
    return out;
}

#define READ_SCALAR(type, name)                                                                                       \
    if (fmu_resource_scalar(r, entry_name(key, prefix, #name), LN_FIELD_CODE(type), sizeof(type), &s->name, msg,      \
                            FMU_MESSAGE))                                                                           \
        return -1;
#define READ_ARRAY_OR_ABSENT(type, name, count, absent_ok)                                                            \
    {                                                                                                                 \
        const void *data = NULL;                                                                                      \
        if (fmu_resource_array(r, entry_name(key, prefix, #name), LN_FIELD_CODE(type), sizeof(type), (int64_t)(count), \
                               absent_ok, &data, msg, FMU_MESSAGE))                                                   \
            return -1;                                                                                                \
        s->name = (const type *)data;                                                                                 \
    }
#define READ_ARRAY(type, name, count) READ_ARRAY_OR_ABSENT(type, name, count, 1)
#define READ_FIXED(type, name, n)                                                                                     \
    {                                                                                                                 \
        const void *data = NULL;                                                                                      \
        if (fmu_resource_array(r, entry_name(key, prefix, #name), LN_FIELD_CODE(type), sizeof(type), n, 0, &data, msg, \
                               FMU_MESSAGE))                                                                          \
            return -1;                                                                                                \
        memcpy(s->name, data, sizeof s->name);                                                                        \
    }
#define READ_OPAQUE(type, name) s->name = NULL;  /* rebuilt by the model */
#define COUNT_FIELD(...) +1
#define NO_FIELD(...)  /* an opaque pointer is not data: no entry */

/* The fields of a list are all there (but its opaque pointers), and no more: a resource of another list is refused as
   a whole. */
static int same_fields(const fmu_resource *r, const char *prefix, size_t fields, char *msg)
{
    char dotted[FMU_RESOURCE_NAME];
    entry_name(dotted, prefix, "");
    const size_t found = fmu_resource_entries_with_prefix(r, dotted);
    if (found == fields) return 0;
    return fail(msg, "the scene's resource %s has %zu entries %s*, this FMU's binary reads %zu (the binary and the "
                "resource come from different linknet releases: build the FMU again)", fmu_resource_path(r), found,
                dotted, fields);
}

static int read_model(const fmu_resource *r, const char *prefix, ln_model *s, char *msg)
{
    char key[FMU_RESOURCE_NAME];
    if (same_fields(r, prefix, 0 LN_MODEL_FIELDS(COUNT_FIELD, COUNT_FIELD, COUNT_FIELD, NO_FIELD), msg)) return -1;
    LN_MODEL_FIELDS(READ_SCALAR, READ_ARRAY, READ_FIXED, READ_OPAQUE)
    return 0;
}

static int read_method(const fmu_resource *r, const char *prefix, ln_method *s, char *msg)
{
    char key[FMU_RESOURCE_NAME];
    if (same_fields(r, prefix, 0 LN_METHOD_FIELDS(COUNT_FIELD, COUNT_FIELD, COUNT_FIELD, NO_FIELD), msg)) return -1;
    LN_METHOD_FIELDS(READ_SCALAR, READ_ARRAY, READ_FIXED, READ_OPAQUE)
    return 0;
}

static int read_rigid(const fmu_resource *r, const char *prefix, struct ln_rigid_model *s, const ln_model *m,
                      char *msg)
{
    char key[FMU_RESOURCE_NAME];
    if (same_fields(r, prefix, 0 LN_RIGID_MODEL_FIELDS(COUNT_FIELD, COUNT_FIELD, COUNT_FIELD, NO_FIELD), msg))
        return -1;
    LN_RIGID_MODEL_FIELDS(READ_SCALAR, READ_ARRAY, READ_FIXED, READ_OPAQUE)
    return 0;
}

#define READ_REQUIRED(type, name, count) READ_ARRAY_OR_ABSENT(type, name, count, 0)
#define READ_TEXT(name)                                                                                               \
    {                                                                                                                 \
        const void *data = NULL;                                                                                      \
        uint64_t count;                                                                                               \
        if (fmu_resource_entry(r, entry_name(key, prefix, #name), &data, NULL, NULL, &count) != 0 || count == 0       \
            || ((const char *)data)[count - 1] != '\0' || strlen((const char *)data) + 1 != count)                    \
            return fail(msg, "the scene's resource %s: entry %s is not one text", fmu_resource_path(r), key);         \
        s->name = data;                                                                                               \
    }
#define READ_TEXTS(name, count)                                                                                       \
    if (fmu_resource_texts(r, entry_name(key, prefix, #name), (int64_t)(count), &l->name, msg, FMU_MESSAGE))         \
        return -1;                                                                                                    \
    s->name = l->name;

static int read_scene(const fmu_resource *r, loaded *l, char *msg)
{
    static const char prefix[] = "scene";
    char key[FMU_RESOURCE_NAME];
    lnfmu_scene *s = &l->scene;
    if (same_fields(r, prefix, 0 LNFMU_SCENE_FIELDS(COUNT_FIELD, COUNT_FIELD, COUNT_FIELD, COUNT_FIELD, COUNT_FIELD,
                                                   COUNT_FIELD), msg))
        return -1;
    LNFMU_SCENE_FIELDS(READ_SCALAR, READ_REQUIRED, READ_ARRAY, READ_FIXED, READ_TEXT, READ_TEXTS)
    return 0;
}

/* ---- the entries against each other -------------------------------------------------------------- */

/* Whether every one of the n indices lies in [low, high). */
static int within(const ln_int *x, ln_int n, ln_int low, ln_int high)
{
    for (ln_int i = 0; x && i < n; i++)
        if (x[i] < low || x[i] >= high) return 0;
    return 1;
}

/* Why the model's indices do not fit its sizes, or NULL. */
static const char *model_problem(const ln_model *m, const lnfmu_scene *s)
{
    if (m->K != s->K || m->L != s->L) return "the model's sizes differ from the scene's";
    if (s->own_K < 0 || s->own_K > s->K) return "the scene's own masses are not among the model's";
    if (m->K < 0 || m->L < 0 || m->n_free < 0 || m->n_fixed < 0 || m->n_elements < 0 || m->n_pairs < 0
        || m->n_driven < 0 || m->n_free + m->n_fixed != m->K)
        return "the model's counts are not possible";
    if ((m->L && !(m->k1 && m->k2 && m->R && m->inv_R)) || (m->K && !(m->inv_m && m->is_fixed && m->F_scene
                                                                      && m->accel_weight)))
        return "an array of the model is missing";
    if (!within(m->k1, m->L, 0, m->K) || !within(m->k2, m->L, 0, m->K)) return "a link joins a mass out of range";
    if (!within(m->free_idx, m->n_free, 0, m->K) || !within(m->fixed_idx, m->n_fixed, 0, m->K)
        || !within(m->driven_idx, m->n_driven, 0, m->K) || !within(m->pair_mass, m->n_pairs, 0, m->K)
        || !within(m->element_mass, 2 * m->n_elements, -1, m->K))
        return "a mass index out of range";
    if (!within(m->pair_first, m->n_pairs, 0, m->L) || !within(m->pair_second, m->n_pairs, 0, m->L)
        || !within(m->chain_order, m->L, 0, m->L))
        return "a link index out of range";
    if (m->n_pairs && !(m->pair_first && m->pair_second && m->pair_weight && m->pair_mass && m->pair_sign))
        return "an array of the tension system is missing";
    if (m->solver < LN_SOLVER_NONE || m->solver > LN_SOLVER_MIN_NORM
        || (m->solver == LN_SOLVER_CHAIN && !(m->chain_order && m->chain_diag_weight && m->chain_off_weight)))
        return "the tension system's solver is not possible";
    if (m->n_driven && !(m->driven_idx && m->motion_kind && m->motion_pieces && m->sine))
        return "an array of the driven anchors is missing";
    if (m->n_ropes < 0 || m->n_ropes > m->L || (m->n_ropes && !(m->rope_link && m->rope_restitution))
        || !within(m->rope_link, m->n_ropes, 0, m->L))
        return "the ropes do not fit the links";
    /* a ground's contacts are ropes, and friction's grips the model's last links (the state keeps their mode) */
    if (m->n_contacts < 0 || m->n_contacts > m->n_ropes || (m->n_contacts && !m->contact_mass)
        || !within(m->contact_mass, m->n_contacts, 0, m->K)
        || !(m->n_grips == 0 || m->n_grips == 2 * m->n_contacts) || m->n_grips > m->L - m->n_contacts)
        return "the ground's contacts and grips do not fit the masses and links";
    return NULL;
}

/* Whether link l is one of the model's ropes. */
static int is_rope(const ln_model *m, ln_int l)
{
    for (ln_int r = 0; r < m->n_ropes; r++)
        if (m->rope_link[r] == l) return 1;
    return 0;
}

/* Why the variables do not fit the model, or NULL. */
static const char *variables_problem(const lnfmu_scene *s)
{
    const ln_model *m = s->model;
    for (ln_int vr = 0; vr < s->n_real; vr++) {
        const int kind = s->variable_kind[vr];
        ln_int size = 1;
        switch (kind) {
        case LNFMU_F: case LNFMU_X: case LNFMU_U: size = 3 * m->K; break;
        case LNFMU_T: case LNFMU_T_PEAK: case LNFMU_T_PEAK_TIME: case LNFMU_R: size = m->L; break;
        case LNFMU_FREACT: size = 3 * m->n_fixed; break;
        case LNFMU_M: size = m->K; break;
        case LNFMU_G: size = 3; break;
        case LNFMU_P: case LNFMU_V: case LNFMU_A: case LNFMU_JREACT: size = 3 * m->n_driven; break;
        case LNFMU_SLACK: case LNFMU_JROPE: size = m->L; break;
        case LNFMU_TOLERANCE: case LNFMU_STEP: case LNFMU_ERROR_ESTIMATE: break;
        default: return "a variable of a kind this FMU does not know";
        }
        if (s->variable_index[vr] < 0 || s->variable_index[vr] >= size) return "a variable's index out of range";
        if ((kind == LNFMU_SLACK || kind == LNFMU_JROPE) && !is_rope(m, s->variable_index[vr]))
            return "a rope's variable of a link that is not a rope";  /* the data keeps ropes' impulses only */
    }
    return NULL;
}

/* Why the events' names cannot name every kind of event the core logs, or NULL. */
static const char *event_kinds_problem(const lnfmu_scene *s)
{
    if (s->n_event_kinds < 0) return "a negative count of events' kinds";
    for (ln_int i = 0; i < s->n_event_kinds; i++)
        if (s->event_names_link[i] != 0 && s->event_names_link[i] != 1)
            return "an event's kind names neither a link nor a mass";
    return NULL;
}

/* Why the elimination order is not a permutation of the links, or NULL. */
static const char *ordering_problem(const lnfmu_scene *s)
{
    if (!s->ldl_ordering) return "the sparse LDL^T's elimination order is missing";
    unsigned char *seen = calloc((size_t)(s->L > 0 ? s->L : 1), 1);
    if (!seen) return "out of memory";
    const char *problem = NULL;
    for (ln_int i = 0; i < s->L && !problem; i++) {
        const ln_int l = s->ldl_ordering[i];
        if (l < 0 || l >= s->L || seen[l]) problem = "the sparse LDL^T's elimination order is not one of the links";
        else seen[l] = 1;
    }
    free(seen);
    return problem;
}

/* ---- the scene ----------------------------------------------------------------------------------- */

void lnfmu_scene_free(lnfmu_scene *s)
{
    loaded *l = (loaded *)s;
    if (!l) return;
    free(l->methods);
    free(l->variables);
    free(l->mass_names);
    free(l->event_kind_names);
    free(l->method_names);
    free(l->variable_names);
    free(l);
}

lnfmu_scene *lnfmu_scene_load(const fmu_resource *r, char *msg)
{
    loaded *l = calloc(1, sizeof *l);
    if (!l) {
        fail(msg, "out of memory");
        return NULL;
    }
    lnfmu_scene *s = &l->scene;
    const char *problem = NULL;
    char prefix[32];
    if (read_scene(r, l, msg) || read_model(r, "model", &l->model, msg)) goto failed;
    s->model = &l->model;
    problem = model_problem(&l->model, s);
    if (!problem && s->n_methods < 1) problem = "no integrator";
    if (!problem && (s->default_method < 0 || s->default_method >= s->n_methods))
        problem = "the default integrator out of range";
    if (!problem && (s->specialisation < LNFMU_POINT_MASSES || s->specialisation > LNFMU_RIGID))
        problem = "a specialisation this FMU does not know";
    if (!problem && l->model.solver == LN_SOLVER_LDL) problem = ordering_problem(s);
    if (!problem) problem = variables_problem(s);
    if (!problem) problem = event_kinds_problem(s);
    if (problem) goto failed;
    if (s->specialisation == LNFMU_RIGID) {
        if (read_rigid(r, "rigid", &l->rigid, &l->model, msg)) goto failed;
        if (l->rigid.n_bodies != s->n_bodies || !s->Y0 || !within(l->rigid.body_of, s->K, -1, s->n_bodies)) {
            problem = "the rigid bodies do not fit the scene";
            goto failed;
        }
        s->rigid = &l->rigid;
    } else if (fmu_resource_entries_with_prefix(r, "rigid.") != 0) {
        problem = "rigid bodies in a scene of another specialisation";
        goto failed;
    }
    l->methods = calloc((size_t)s->n_methods, sizeof *l->methods);
    l->variables = calloc((size_t)(s->n_real > 0 ? s->n_real : 1), sizeof *l->variables);
    if (!l->methods || !l->variables) {
        fail(msg, "out of memory");
        goto failed;
    }
    for (ln_int i = 0; i < s->n_methods; i++) {
        snprintf(prefix, sizeof prefix, "method%lld", (long long)i);
        if (read_method(r, prefix, &l->methods[i].method, msg)) goto failed;
        l->methods[i].name = s->method_names[i];
        l->methods[i].adaptive = s->method_adaptive[i];
        l->methods[i].order = s->method_order[i];
    }
    snprintf(prefix, sizeof prefix, "method%lld.", (long long)s->n_methods);
    if (fmu_resource_entries_with_prefix(r, prefix) != 0) {
        problem = "more integrators than the scene names";
        goto failed;
    }
    for (ln_int vr = 0; vr < s->n_real; vr++) {
        l->variables[vr].name = s->variable_names[vr];
        l->variables[vr].kind = s->variable_kind[vr];
        l->variables[vr].index = s->variable_index[vr];
    }
    s->methods = l->methods;
    s->variables = l->variables;
    return s;

failed:
    if (problem)
        fail(msg, "the scene's resource %s does not hold a consistent scene: %s", fmu_resource_path(r), problem);
    lnfmu_scene_free(s);
    return NULL;
}

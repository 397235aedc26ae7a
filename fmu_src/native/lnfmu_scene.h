/* The data of one scene's FMU, as fmu_src/native/build.py writes it into the FMU's resource file (fmu_resource.h)
 * and lnfmu_scene.c reads it back at instantiation: constant arrays and nothing else. The physics is the native
 * core's (linknet.h); linknet_model.c runs an ln_model built from this.
 *
 * The ln_model and the ln_methods are those linknet_core builds for the scene at the FMU's default parameters (the
 * library's own structs, written field by field with the core's lists, ln_model_fields.h), so that at the defaults
 * the FMU runs exactly the library's arithmetic. What a changed parameter needs besides (the scene's masses,
 * lengths, gravity and constant forces, the scene's own initial state) is here too.
 *
 * In the resource: the entries "scene.<field>" of LNFMU_SCENE_FIELDS below, "model.<field>" of the ln_model,
 * "rigid.<field>" of the bodies (LNFMU_RIGID only) and "method<i>.<field>" of each integrator's ln_method. build.py
 * reads this list and the kinds of Real variables (enum lnfmu_kind) from this file: each is written here only.
 */
#ifndef LINKNET_FMU_SCENE_H
#define LINKNET_FMU_SCENE_H

#include <stdint.h>

#include "fmu_resource.h"
#include "linknet.h"
#include "rigid.h"

/* What a Real variable is. */
enum lnfmu_kind {
    LNFMU_F = 0,        /* input: force on a free mass; index 3 k + i */
    LNFMU_X = 1,        /* output: position; index 3 k + i */
    LNFMU_U = 2,        /* output: velocity; index 3 k + i */
    LNFMU_T = 3,        /* output: tension of link index */
    LNFMU_FREACT = 4,   /* output: force on an anchor; index 3 j + i, j the anchor's row in ln_model.fixed_idx */
    LNFMU_M = 5,        /* parameter: mass of free mass index */
    LNFMU_R = 6,        /* parameter: length of link index */
    LNFMU_G = 7,        /* parameter: gravity component index */
    LNFMU_TOLERANCE = 8,/* parameter: rtol of the adaptive methods */
    LNFMU_STEP = 9,     /* parameter: internal step of the fixed-step methods */
    LNFMU_P = 10,       /* input: position of an anchor driven by inputs; index 3 j + i, j its row in
                           ln_model.driven_idx */
    LNFMU_V = 11,       /* input: its velocity; index as P */
    LNFMU_A = 12,       /* input: its acceleration; index as P */
    LNFMU_JREACT = 13,  /* output: impulse on a driven anchor at the last step's start; index as P */
    LNFMU_ERROR_ESTIMATE = 14,  /* output: the run's estimated largest position error (the companion run's gap) */
    LNFMU_T_PEAK = 15,  /* output: the largest |T| of link index over the last step, signed */
    LNFMU_T_PEAK_TIME = 16,     /* output: when it occurred */
    LNFMU_SLACK = 17,   /* output: 1 where rope link index is slack at the state (its T is 0), else 0 */
    LNFMU_JROPE = 18    /* output: the impulse of unilateral link index of the core's model over the last step:
                           a rope's jerks (Jrope), or a ground contact's landings (Jground: the contact links follow
                           the scene's links in the model, unilateral.native_ground_scene) */
};
#define LNFMU_KINDS 19

/* The specialisation the library chose for the scene (linknet_core.Simulator). */
enum lnfmu_specialisation { LNFMU_POINT_MASSES = 0, LNFMU_STATIC = 1, LNFMU_RIGID = 2 };

/* The scene's entries, as ln_model_fields.h lists the core's structs (SCALAR, ARRAY, FIXED as there; count
 * expressions read the scene's earlier fields through `s`), with
 *   OPTIONAL(type, name, count)  as ARRAY, or absent (NULL) where the scene has none
 *   TEXT(name)                   const char *name;            one text
 *   TEXTS(name, count)           const char *const *name;     count texts */
#define LNFMU_SCENE_FIELDS(SCALAR, ARRAY, OPTIONAL, FIXED, TEXT, TEXTS)                                            \
    TEXT(model_identifier)                                                                                          \
    TEXT(scene_name)                                                                                                \
    TEXT(guid)                                          /* the modelDescription's: fmi2Instantiate checks it */     \
    SCALAR(uint64_t, fingerprint)                       /* identity of the FMU's build: an FMU state carries it */ \
    /* the scene as given: defaults of the parameters, and what a changed one is combined with */                   \
    SCALAR(ln_int, K)                                                                                               \
    SCALAR(ln_int, L)                                                                                               \
    SCALAR(ln_int, own_K)                               /* the scene's own masses, the model's first: a ground's     \
                                                           virtual anchors follow them (the FMU's variables are of  \
                                                           these) */                                                 \
    TEXTS(mass_names, s->K)                                                                                         \
    ARRAY(double, mass, s->K)                           /* anchors' entries unused */                               \
    ARRAY(double, length, s->L)                                                                                     \
    FIXED(double, gravity, 3)                                                                                       \
    ARRAY(double, force, 3 * s->K)                      /* (K,3) constant forces */                                 \
    ARRAY(double, X0, 3 * s->K)                         /* (K,3) the scene's initial positions and velocities,      \
                                                           before any projection */                                 \
    ARRAY(double, U0, 3 * s->K)                                                                                     \
    SCALAR(int, project_initial)                        /* "options": {"project_initial_positions": true} */        \
    SCALAR(double, length_tol)                          /* relative violation of (11) accepted in the initial       \
                                                           positions */                                             \
    /* the library's rules for settings and inputs (linknet_core.integrators, Simulator) */                         \
    SCALAR(double, tolerance_min)                       /* rtol lies in [tolerance_min, tolerance_max) */           \
    SCALAR(double, tolerance_max)                                                                                   \
    SCALAR(double, max_force)                           /* an input force beyond this (N) is refused; 0: no limit */\
    TEXT(linearization_refusal)                         /* why the directional derivatives are refused (the     \
                                                           library's words: a scene with ropes), or empty */        \
    SCALAR(ln_int, n_event_kinds)                       /* the kinds of the core's events (enum ln_event_kind) */\
    TEXTS(event_kind_names, s->n_event_kinds)           /* by the library's names (linknet_core.clib.library    \
                                                           .EVENT_KINDS), as both FMUs log them */              \
    ARRAY(int, event_names_link, s->n_event_kinds)      /* 1 where an event of the kind names a link, 0 a mass  \
                                                           (rope_events.LINK_KINDS) */                          \
    OPTIONAL(ln_int, ldl_ordering, s->L)                /* LN_SOLVER_LDL: the elimination order (position -> link) */\
    SCALAR(int, specialisation)                         /* enum lnfmu_specialisation */                             \
    SCALAR(ln_int, n_bodies)                            /* LNFMU_RIGID: the bodies ("rigid.*" at the defaults) */   \
    OPTIONAL(double, Y0, LN_RIGID_STATE * s->n_bodies)  /* (B,13) their initial states */                           \
    /* the library's initial state and internals at the defaults (Simulator after construction) */                  \
    ARRAY(double, X_init, 3 * s->K)                     /* (K,3) */                                                 \
    ARRAY(double, U_init, 3 * s->K)                                                                                 \
    SCALAR(double, h_next_init)                                                                                     \
    SCALAR(int, planar_init)                                                                                        \
    SCALAR(ln_int, max_steps)                           /* steps one advance may take */                            \
    /* integrators, by the name the parameter "integrator" takes ("method<i>.*": the ln_method of each) */          \
    SCALAR(ln_int, n_methods)                                                                                       \
    TEXTS(method_names, s->n_methods)                                                                               \
    ARRAY(int, method_adaptive, s->n_methods)           /* the parameter "tolerance" applies (else "step") */       \
    ARRAY(int, method_order, s->n_methods)              /* (ln_companion_settings: a fixed step's Richardson        \
                                                           factor) */                                               \
    SCALAR(ln_int, default_method)                                                                                  \
    SCALAR(double, default_step)                                                                                    \
    SCALAR(double, default_tolerance)                                                                               \
    SCALAR(int, default_estimate)                       /* the Boolean parameter "estimate_error" (value reference  \
                                                           n_real + 1) */                                           \
    /* Real variables by value reference; the String parameter "integrator" has value reference n_real, the        \
       Boolean parameter "estimate_error" n_real + 1 */                                                             \
    SCALAR(ln_int, n_real)                                                                                          \
    TEXTS(variable_names, s->n_real)                                                                                \
    ARRAY(int, variable_kind, s->n_real)                /* enum lnfmu_kind */                                       \
    ARRAY(ln_int, variable_index, s->n_real)            /* its index (enum lnfmu_kind says of what) */

typedef struct lnfmu_variable {
    const char *name;
    int kind;                       /* enum lnfmu_kind */
    ln_int index;
} lnfmu_variable;

typedef struct lnfmu_method {
    const char *name;
    int adaptive;                   /* the parameter "tolerance" applies (else "step") */
    int order;                      /* the method's order (ln_companion_settings: a fixed step's Richardson factor) */
    ln_method method;               /* as the library builds it; dt, rtol and atol come from the parameters */
} lnfmu_method;

#define LNFMU_DECLARE_TEXT(name) const char *name;
#define LNFMU_DECLARE_TEXTS(name, count) const char *const *name;

typedef struct lnfmu_scene {
    LNFMU_SCENE_FIELDS(LN_DECLARE_SCALAR, LN_DECLARE_ARRAY, LN_DECLARE_ARRAY, LN_DECLARE_FIXED, LNFMU_DECLARE_TEXT,
                       LNFMU_DECLARE_TEXTS)
    /* made from the entries at instantiation */
    const ln_model *model;                  /* the native model at the defaults; its ldl and rigid are NULL */
    const struct ln_rigid_model *rigid;     /* LNFMU_RIGID: the bodies at the defaults */
    const lnfmu_method *methods;            /* (n_methods) */
    const lnfmu_variable *variables;        /* (n_real) */
} lnfmu_scene;

/* The scene in a resource (lnfmu_scene.c): its entries read, checked against each other (every count, every kind and
   index of a variable, the default integrator) and pointed to in place, so the resource must outlive the scene. NULL
   with the reason, naming the file and the entry, in msg (FMU_MESSAGE bytes). */
lnfmu_scene *lnfmu_scene_load(const fmu_resource *r, char *msg);
void lnfmu_scene_free(lnfmu_scene *s);

/* The core structs a model runs on (linknet_model.c), for a benchmark that times ln_advance itself next to
   fmi2DoStep from the same sources. */
struct fmu_model;
void lnfmu_core(struct fmu_model *m, const ln_model **model, const ln_method **method, ln_data **data);

#endif

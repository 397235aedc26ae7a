/* The data of one scene's FMU, as fmu_src/native/build.py writes it into a generated C file: constant
 * arrays and nothing else. The physics is the native core's (linknet.h); linknet_model.c builds an ln_model
 * from this at instantiation.
 *
 * The ln_model and the ln_methods are those linknet_core builds for the scene at the FMU's default
 * parameters (read field by field from the library's own structs), so that at the defaults the FMU runs
 * exactly the library's arithmetic. What a changed parameter needs besides (the scene's masses, lengths,
 * gravity and constant forces, the scene's own initial state) is here too.
 */
#ifndef LINKNET_FMU_SCENE_H
#define LINKNET_FMU_SCENE_H

#include <stdint.h>

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
    LNFMU_ERROR_ESTIMATE = 14   /* output: the run's estimated largest position error (the companion run's gap) */
};

/* The specialisation the library chose for the scene (linknet_core.Simulator). */
enum lnfmu_specialisation { LNFMU_POINT_MASSES = 0, LNFMU_STATIC = 1, LNFMU_RIGID = 2 };

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

typedef struct lnfmu_scene {
    const char *model_identifier;
    const char *scene_name;
    const char *guid;
    uint64_t fingerprint;

    /* the scene as given: defaults of the parameters, and what a changed one is combined with */
    ln_int K, L;
    const char *const *mass_names;  /* (K) */
    const double *mass;             /* (K) (anchors' entries unused) */
    const double *length;           /* (L) */
    double gravity[3];
    const double *force;            /* (K,3) constant forces */
    const double *X0, *U0;          /* (K,3) the scene's initial positions and velocities, before any projection */
    int project_initial;            /* "options": {"project_initial_positions": true} */
    double length_tol;              /* relative violation of (11) accepted in the initial positions */

    /* the library's rules for settings and inputs (linknet_core.integrators, Simulator) */
    double tolerance_min, tolerance_max;    /* rtol lies in [tolerance_min, tolerance_max) */
    double max_force;                       /* an input force beyond this (N) is refused; 0: no limit */

    /* the native model at the defaults; its ldl and rigid pointers are NULL (built at instantiation) */
    const ln_model *model;
    const ln_int *ldl_ordering;     /* (L) LN_SOLVER_LDL: the elimination order (position -> link) */
    int specialisation;             /* enum lnfmu_specialisation */
    const struct ln_rigid_model *rigid;     /* LNFMU_RIGID: the bodies at the defaults */
    const double *Y0;               /* (B,13) their initial states */

    /* the library's initial state and internals at the defaults (Simulator after construction) */
    const double *X_init, *U_init;  /* (K,3) */
    double h_next_init;
    int planar_init;
    ln_int max_steps;               /* steps one advance may take */

    /* integrators, by the name the parameter "integrator" takes */
    ln_int n_methods;
    const lnfmu_method *methods;
    ln_int default_method;
    double default_step, default_tolerance;
    int default_estimate;           /* the Boolean parameter "estimate_error" (value reference n_real + 1) */

    /* Real variables by value reference; the String parameter "integrator" has value reference n_real, the Boolean
       parameter "estimate_error" n_real + 1 */
    ln_int n_real;
    const lnfmu_variable *variables;
} lnfmu_scene;

extern const lnfmu_scene lnfmu_scene_data;

/* The core structs a model runs on (linknet_model.c), for a benchmark that times ln_advance itself next to
   fmi2DoStep from the same sources. */
struct fmu_model;
void lnfmu_core(struct fmu_model *m, const ln_model **model, const ln_method **method, ln_data **data);

#endif

/* The DIM-generic stages in dependency order, included by dim2.c and dim3.c: one translation unit per DIM,
   so that the small per-link helpers inline across stages. No include guard: included once per DIM. */
#include "stages/forces.c"
#include "stages/tension.c"
#include "stages/minnorm.c"
#include "stages/accelerations.c"
#include "stages/projections.c"
#include "stages/rattle.c"
#include "stages/friction.c"
#include "stages/runge_kutta.c"
#include "stages/ropes.c"

/* The 3-D copies of the DIM-generic stages: every scene that is not planar. One translation
   unit, so that the small per-link helpers inline across stages. */
#define DIM 3
#include "stages/forces.c"
#include "stages/tension.c"
#include "stages/minnorm.c"
#include "stages/accelerations.c"
#include "stages/projections.c"
#include "stages/rattle.c"
#include "stages/runge_kutta.c"

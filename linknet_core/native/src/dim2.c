/* The 2-D copies of the DIM-generic stages: planar scenes run in their plane's coordinates. One translation
   unit, so that the small per-link helpers inline across stages. */
#define DIM 2
#include "stages/forces.c"
#include "stages/tension.c"
#include "stages/minnorm.c"
#include "stages/accelerations.c"
#include "stages/projections.c"
#include "stages/rattle.c"
#include "stages/runge_kutta.c"

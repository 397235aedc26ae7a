/* Driven anchors inside the core (drive.c): what the stages call. Scenes with driven anchors run in 3-D, so
   dim is 3 wherever these are reached; the DIM-generic stages pass their DIM. */
#ifndef LINKNET_DRIVE_H
#define LINKNET_DRIVE_H

#include "linknet.h"

/* The driven rows at time t: of X (P_a), of U (V_a) and of F (A_a: the base force's rows of driven anchors carry
   their accelerations, which B of (26) reads with weight 1); any of the three may be NULL. Arrays (K, dim). */
int ln_drive_rows(const ln_model *m, ln_data *d, double t, double *X, double *U, double *F, int dim);

/* At the start of an advance: the state's driven rows to the motion at d->t. Where they jump, the positions are
   projected onto (11) and the velocities onto (12) in the mass metric (an inelastic impulse); d->impulse (which
   the advance's rope events add to), d->jump_impulse, d->jump_position, d->jump_velocity and d->jumps record it. */
int ln_drive_jump(const ln_model *m, const ln_method *meth, ln_data *d);

#endif

/* Minimum-norm solves of the tension system (25) where A is singular (stages/minnorm.c).
 *
 * A = C M^-1 C^T is symmetric positive semi-definite. Where links are redundant (states of self-stress,
 * (27)-(31)) or the configuration is singular, A T = B has many solutions; all give the same forces on
 * the masses (31), and the one reported is the minimum-norm one. Its workspace lives in ln_data
 * (d->minnorm), allocated at the first factorisation and freed by ln_minnorm_free.
 */
#ifndef LINKNET_MINNORM_H
#define LINKNET_MINNORM_H

#include "linknet.h"

LN_API void ln_minnorm_free(struct ln_minnorm_work *w);
/* Rank of the last factorisation (-1 on the iterative path, which does not reveal it). */
LN_API ln_int ln_minnorm_rank(const struct ln_minnorm_work *w);

#endif

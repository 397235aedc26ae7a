/* Sparse LDL^T of the tension matrix A (25) on a pattern analysed once (engine_ldl.c).
 *
 * A's pattern is fixed by the topology: two links are coupled where they share a free mass. Everything
 * that depends only on the pattern is computed once, before a run: the elimination order, the pattern of
 * P A P^T, the elimination tree, the pattern of L and the schedule of the numeric factorisation. A step
 * repeats only the arithmetic. The numeric algorithm is QDLDL's up-looking one (Stellato, Banjac et al.,
 * Apache-2.0): it touches only the non-zeros of L, so for chains and trees in a leaves-first order it
 * costs O(L).
 *
 * Both structs are opaque outside engine_ldl.c.
 */
#ifndef LINKNET_LDL_H
#define LINKNET_LDL_H

#include "linknet.h"

/* Analyse the pattern of an n x n symmetric matrix given as n_pairs (first, second) index pairs, each the
   position of one entry of the lower or upper triangle (diagonal pairs included; a pair may repeat, its
   values then add up). ordering (n): the elimination order (position -> index), or NULL to let the
   analysis choose a fill-reducing one. NULL on out of memory or an invalid ordering. */
struct ln_ldl_symbolic *ln_ldl_analyse(ln_int n, ln_int n_pairs, const ln_int *pair_first, const ln_int *pair_second,
                                       const ln_int *ordering);
void ln_ldl_symbolic_free(struct ln_ldl_symbolic *s);
ln_int ln_ldl_nnz_L(const struct ln_ldl_symbolic *s);
void ln_ldl_get_ordering(const struct ln_ldl_symbolic *s, ln_int *ordering);  /* (n) position -> index */

struct ln_ldl_numeric *ln_ldl_numeric_new(const struct ln_ldl_symbolic *s);
void ln_ldl_numeric_free(struct ln_ldl_numeric *f);

/* Factor the matrix whose entries are pair_values (n_pairs, in the order of the pairs given to
   ln_ldl_analyse). Returns -1, or the first elimination column whose pivot fell below pivot_tol times
   its diagonal entry (the matrix is singular or nearly so there). */
ln_int ln_ldl_factor(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *pair_values,
                     double pivot_tol);

/* x = A^-1 b with the last factorisation; b and x (n) in the original numbering, may be the same array. */
void ln_ldl_solve(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *b, double *x);

#endif

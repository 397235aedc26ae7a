/* Sparse LDL^T of the tension matrix A (25) on a pattern analysed once (engine_ldl.c).
 *
 * A's pattern is fixed by the topology: two links are coupled where they share a free mass. Everything
 * that depends only on the pattern is computed once, before a run: the elimination order (AMD unless the
 * caller gives one), the pattern of P A P^T, the elimination tree, the pattern of L and the schedule of
 * the numeric factorisation. A step repeats only the arithmetic. Where L has few entries per column
 * (chains and trees in a leaves-first order: no fill, O(L); small scenes) the numeric algorithm is QDLDL's
 * up-looking one (Stellato, Banjac et al., Apache-2.0); where it has many (large nets) it is a supernodal
 * left-looking LDL^T on dense blocks.
 *
 * Both structs are opaque outside engine_ldl.c.
 */
#ifndef LINKNET_LDL_H
#define LINKNET_LDL_H

#include "linknet.h"

/* Analyse the pattern of an n x n symmetric matrix given as n_pairs (first, second) index pairs, each the
   position of one entry of the lower or upper triangle (diagonal pairs included; a pair may repeat, its
   values then add up). ordering (n): the elimination order (position -> index), or NULL to let the
   analysis choose a fill-reducing one (AMD). NULL on out of memory or an invalid ordering. */
LN_API struct ln_ldl_symbolic *ln_ldl_analyse(ln_int n, ln_int n_pairs, const ln_int *pair_first, const ln_int *pair_second,
                                       const ln_int *ordering);
LN_API void ln_ldl_symbolic_free(struct ln_ldl_symbolic *s);
LN_API ln_int ln_ldl_nnz_L(const struct ln_ldl_symbolic *s);   /* entries of L below the diagonal (structural) */
LN_API void ln_ldl_get_ordering(const struct ln_ldl_symbolic *s, ln_int *ordering);  /* (n) position -> index */

/* What the analysis chose, for benchmarks and tests: info[0] 1 if supernodal, 0 if column by column;
   info[1] nnz(L) below the diagonal; info[2] supernodes (columns for the column algorithm); info[3] values
   stored for L (dense blocks' upper triangles and amalgamation zeros included); info[4] multiply-adds of one
   factorisation counted on the structure of L; info[5] 1 if the supernodal factorisation runs its AVX2 copy. */
LN_API void ln_ldl_info(const struct ln_ldl_symbolic *s, double info[6]);

/* Whether analyses from now on pick the AVX2 copy of the supernodal factorisation where the processor has
   it: enable 1 (the default) or 0, or -1 to only ask. Returns whether they will. Process-wide, for tests and
   benchmarks: both copies give bitwise the same factorisation. */
LN_API int ln_ldl_vector_kernels(int enable);

LN_API struct ln_ldl_numeric *ln_ldl_numeric_new(const struct ln_ldl_symbolic *s);
LN_API void ln_ldl_numeric_free(struct ln_ldl_numeric *f);

/* Factor the matrix whose entries are pair_values (n_pairs, in the order of the pairs given to
   ln_ldl_analyse). Returns -1, or the first elimination column whose pivot fell below pivot_tol times
   its diagonal entry (the matrix is singular or nearly so there); such a pivot is zeroed (its column
   drops out of the solves). */
LN_API ln_int ln_ldl_factor(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *pair_values,
                     double pivot_tol);

/* The pivots d_k of the last factorisation in elimination order into D (n, if not NULL); returns how many
   were zeroed (n - rank of A as the factorisation sees it). */
LN_API ln_int ln_ldl_get_pivots(const struct ln_ldl_symbolic *s, const struct ln_ldl_numeric *f, double *D);

/* x = A^-1 b with the last factorisation; b and x (n) in the original numbering, may be the same array. */
LN_API void ln_ldl_solve(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *b, double *x);

#endif

/* Test driver for stages/minnorm.c: both DIM copies in one translation unit, behind a small handle API that
   ctypes can call with numpy buffers. Built by tests/native/test_minnorm_c.py into a private library. */
#include <stdlib.h>

#include "linknet.h"

#define DIM 3
#include "dim.h"
#include "stages/minnorm.c"
#undef FN
#undef DIM
#define DIM 2
#include "dim.h"
#include "stages/minnorm.c"

typedef struct {
    int dim;
    ln_model m;
    ln_data d;
} mn_handle;

mn_handle *mn_new(void) { return calloc(1, sizeof(mn_handle)); }

/* The model's arrays stay owned by the caller; the data (and its minimum-norm workspace) is kept, so that
   a second model on the same handle exercises the workspace's growth. */
void mn_set_model(mn_handle *h, int dim, ln_int K, ln_int L, const ln_int *k1, const ln_int *k2, const double *inv_m,
                  ln_int n_pairs, const ln_int *pair_first, const ln_int *pair_second, const double *pair_weight,
                  double rank_tol, ln_int dense_min_norm_limit)
{
    ln_model z = {0};
    h->m = z;
    h->dim = dim;
    h->m.K = K;
    h->m.L = L;
    h->m.k1 = k1;
    h->m.k2 = k2;
    h->m.inv_m = inv_m;
    h->m.solver = LN_SOLVER_MIN_NORM;
    h->m.n_pairs = n_pairs;
    h->m.pair_first = pair_first;
    h->m.pair_second = pair_second;
    h->m.pair_weight = pair_weight;
    h->m.rank_tol = rank_tol;
    h->m.dense_min_norm_limit = dense_min_norm_limit;
}

int mn_factor(mn_handle *h, const double *E)
{
    return h->dim == 2 ? ln_minnorm_factor_2d(&h->m, &h->d, E) : ln_minnorm_factor_3d(&h->m, &h->d, E);
}

void mn_solve(mn_handle *h, const double *b, double *x)
{
    if (h->dim == 2) ln_minnorm_solve_2d(&h->m, &h->d, b, x);
    else ln_minnorm_solve_3d(&h->m, &h->d, b, x);
}

ln_int mn_rank(const mn_handle *h) { return ln_minnorm_rank(h->d.minnorm); }

/* The last iterative solve: iterations, least relative residual, why it stopped (enum mn_stop). */
void mn_cg_info(const mn_handle *h, ln_int *iterations, double *residual, int *stop)
{
    const struct ln_minnorm_work *w = h->d.minnorm;
    *iterations = w ? w->iterations : -1;
    *residual = w ? w->residual : -1.0;
    *stop = w ? w->stop : -1;
}

void mn_free(mn_handle *h)
{
    if (!h) return;
    ln_minnorm_free(h->d.minnorm);
    free(h);
}

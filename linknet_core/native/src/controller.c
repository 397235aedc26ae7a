/* The step-size controller of the embedded Runge-Kutta pairs (Hairer, Norsett and Wanner), shared by the
   point-mass path (stages/runge_kutta.c) and the free-rigid-body path (engine_rigid.c). */
#include <math.h>

#include "linknet.h"
#include "ln_math.h"

double ln_controlled_step(double h_next, double t, double t_target)
{
    const double remaining = t_target - t;
    double h = ln_fmin(h_next, remaining);
    if (h < remaining && remaining < 1.1 * h) h = 0.5 * remaining;  /* no sliver of a last step */
    const double tt = ln_fmax(fabs(t), 1.0);
    if (h <= 16.0 * (ln_next_up(tt) - tt) && h < remaining) return -1.0;
    return h;
}

double ln_next_step_size(const ln_method *meth, double h, double h_next, double err)
{
    if (!isfinite(err)) return h * meth->min_factor;  /* the estimate itself blew up: shrink the most */
    if (err > 1.0) return h * ln_fmax(meth->min_factor, meth->safety * ln_pow(err, meth->exponent));
    const double factor = err == 0.0 ? meth->max_factor
                                     : ln_fmin(meth->max_factor, meth->safety * ln_pow(err, meth->exponent));
    /* a step shortened only to land on t_target says nothing against the longer step */
    return h < h_next ? ln_fmax(h_next, h * factor) : h * factor;
}

double ln_trial_step(double d0, double d1, double span)
{
    const double h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    return ln_fmin(h0, span);
}

double ln_starting_step(const ln_method *meth, double h0, double d1, double d2, double span)
{
    const double h1 = (d1 <= 1e-15 && d2 <= 1e-15) ? ln_fmax(1e-6, h0 * 1e-3)
                                                   : ln_pow(0.01 / ln_fmax(d1, d2), -meth->exponent);
    return ln_fmin(ln_fmin(100.0 * h0, h1), span);
}

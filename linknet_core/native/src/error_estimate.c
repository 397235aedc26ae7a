/* A run's global error, estimated by a companion run: the one rule every path follows (the library's Simulator and
   simulate, on either backend, and the native FMU).

   A fixed-step method of order p (RATTLE 2, the compositions 4, 6, 8) is compared with itself at half the step:
   with err(h) ~ C h^p (Richardson), x(h) - x(h/2) = err(h) (1 - 2^-p), so err(h) ~ 2^p / (2^p - 1) |x(h) - x(h/2)|.
   Half the step, not twice: an interval shorter than two steps (an FMU whose communication step equals its step)
   would give a doubled step the very same steps.

   An error-controlled method is compared with itself at a tenth of its tolerances. Its global error follows the
   tolerance roughly in proportion, so the companion's is about a tenth of the run's and |x(rtol) - x(rtol/10)|
   estimates the run's error within some ten per cent to a factor two (tolerance proportionality is not exact;
   the comparison against independent references is in tests/core/test_error_estimate.py). A tenth, not ten
   times: a looser companion's error could match the run's and hide it.

   The estimate is the largest distance |X_k - X_companion,k| over the masses, in metres, times that factor. */
#include "linknet.h"

#include <math.h>

LN_API const double ln_rtol_min = 1e-15;     /* below, double precision cannot deliver a relative tolerance */
LN_API const double ln_companion_rtol_ratio = 0.1;

LN_API double ln_companion_settings(int adaptive, int order, double dt, double rtol, double atol,
                                    double *dt_companion, double *rtol_companion, double *atol_companion)
{
    if (adaptive) {
        *dt_companion = 0.0;
        *rtol_companion = fmax(rtol * ln_companion_rtol_ratio, ln_rtol_min);
        *atol_companion = atol * ln_companion_rtol_ratio;
        return 1.0;
    }
    const double gain = ldexp(1.0, order);  /* 2^p */
    *dt_companion = 0.5 * dt;
    *rtol_companion = *atol_companion = 0.0;
    return gain / (gain - 1.0);
}

LN_API double ln_position_gap(ln_int K, const double *Xa, const double *Xb)
{
    double worst = 0.0;
    for (ln_int k = 0; k < K; k++) {
        const double dx = Xa[3 * k] - Xb[3 * k], dy = Xa[3 * k + 1] - Xb[3 * k + 1], dz = Xa[3 * k + 2] - Xb[3 * k + 2];
        const double d = sqrt(dx * dx + dy * dy + dz * dz);
        if (!(d <= worst))  /* NaN too: a non-finite gap is the answer */
            worst = d;
    }
    return worst;
}

/* What a run is asked for, in metres of position: the goal its error estimate is held to (a warning where it is
   exceeded). Local error control keeps each step's error within rtol; over a run those errors add up and the
   motion amplifies them, and on the shipped scenes the global error ends 1-20 times rtol times the scene's size
   (docs/accuracy.md), so the goal is ln_goal_per_rtol times that: 1e-6 of the scene's size at the default rtol.
   A fixed-step run is held to the default's goal. */
LN_API const double ln_default_rtol = 1e-8;
LN_API const double ln_goal_per_rtol = 100.0;

LN_API double ln_error_goal(int adaptive, double rtol, double atol, double size)
{
    if (!adaptive)
        rtol = atol = ln_default_rtol;
    return ln_goal_per_rtol * fmax(rtol * size, atol);
}

LN_API double ln_scene_size(ln_int K, const double *X)
{
    double size = 0.0;
    for (int i = 0; i < 3; i++) {
        double lo = INFINITY, hi = -INFINITY;
        for (ln_int k = 0; k < K; k++) {
            lo = fmin(lo, X[3 * k + i]);
            hi = fmax(hi, X[3 * k + i]);
        }
        if (hi - lo > size)
            size = hi - lo;
    }
    return size > 0.0 ? size : 1.0;
}

/* A run's global error, estimated by a companion run: the one rule every path follows (the library's Simulator and
   simulate, on either backend, and the native FMU).

   A fixed-step method of order p (RATTLE 2, the compositions 4, 6, 8) is compared with itself at half the step:
   with err(h) ~ C h^p (Richardson), x(h) - x(h/2) = err(h) (1 - 2^-p), so err(h) ~ 2^p / (2^p - 1) |x(h) - x(h/2)|.
   Half the step, not twice: an interval shorter than two steps (an FMU whose communication step equals its step)
   would give a doubled step the very same steps.

   Either companion takes each interval between two communication points (or outputs) as two halves
   (ln_companion_advance): n equal steps of a fixed-step run then become exactly 2n of the companion, also where the
   interval is shorter than the step (n = 1), where a companion stepping dt/2 over the whole interval would take the
   run's single step; and an error-controlled run whose every step is cut short by the communication points (an FMU
   stepping faster than its tolerance needs) gets a companion that steps twice as often, where one at a tenth of the
   tolerance would accept the very same steps and read 0.

   An error-controlled method is compared with itself at a tenth of its tolerances. Its global error follows the
   tolerance roughly in proportion, so the companion's is about a tenth of the run's and |x(rtol) - x(rtol/10)|
   estimates the run's error within some ten per cent to a factor two (tolerance proportionality is not exact;
   the comparison against independent references is in tests/core/test_error_estimate.py). A tenth, not ten
   times: a looser companion's error could match the run's and hide it.

   The estimate is the largest distance |X_k - X_companion,k| over the masses, in metres, times that factor. */
#include "linknet.h"
#include "ln_math.h"

#include <math.h>
#include <stdio.h>

LN_API const double ln_rtol_min = 1e-15;     /* below, double precision cannot deliver a relative tolerance */
static const double companion_rtol_ratio = 0.1;

LN_API double ln_companion_settings(int adaptive, int order, double dt, double rtol, double atol,
                                    double *dt_companion, double *rtol_companion, double *atol_companion)
{
    if (adaptive) {
        *dt_companion = 0.0;
        *rtol_companion = ln_fmax(rtol * companion_rtol_ratio, ln_rtol_min);
        *atol_companion = atol * companion_rtol_ratio;
        return 1.0;
    }
    const double gain = ln_pow2(order);  /* 2^p */
    *dt_companion = 0.5 * dt;
    *rtol_companion = *atol_companion = 0.0;
    return gain / (gain - 1.0);
}

LN_API double ln_position_gap(ln_int K, const double *Xa, const double *Xb)
{
    double worst = 0.0;
    for (ln_int k = 0; k < K; k++) {
        const double dx = Xa[3 * k] - Xb[3 * k], dy = Xa[3 * k + 1] - Xb[3 * k + 1], dz = Xa[3 * k + 2] - Xb[3 * k + 2];
        const double d = ln_sqrt(dx * dx + dy * dy + dz * dz);
        if (!(d <= worst))  /* NaN too: a non-finite gap is the answer */
            worst = d;
    }
    return worst;
}

LN_API void ln_position_gaps(ln_int n, ln_int K, const double *Xa, const double *Xb, double *out)
{
    for (ln_int i = 0; i < n; i++)
        out[i] = ln_position_gap(K, Xa + 3 * K * i, Xb + 3 * K * i);
}

/* What a run is asked for, in metres of position: the goal its error estimate is held to (a warning where it is
   exceeded). Local error control keeps each step's error within rtol; over a run those errors add up and the
   motion amplifies them, and on the shipped scenes the global error ends 1-20 times rtol times the scene's size
   (docs/accuracy.md), so the goal is goal_per_rtol times that: 1e-6 of the scene's size at the default rtol.
   A fixed-step run is held to the default's goal. */
LN_API const double ln_default_rtol = 1e-8;
static const double goal_per_rtol = 100.0;

LN_API double ln_error_goal(int adaptive, double rtol, double atol, double size)
{
    if (!adaptive)
        rtol = atol = ln_default_rtol;
    return goal_per_rtol * ln_fmax(rtol * size, atol);
}

LN_API double ln_scene_size(ln_int K, const double *X)
{
    double size = 0.0;
    for (int i = 0; i < 3; i++) {
        double lo = INFINITY, hi = -INFINITY;
        for (ln_int k = 0; k < K; k++) {
            lo = ln_fmin(lo, X[3 * k + i]);
            hi = ln_fmax(hi, X[3 * k + i]);
        }
        if (hi - lo > size)
            size = hi - lo;
    }
    return size > 0.0 ? size : 1.0;
}

/* Advance the companion dc to t_target as the rule above says: through the interval's midpoint. LN_OK or the
   failing ln_advance's status. */
LN_API int ln_companion_advance(const ln_model *m, const ln_method *companion, ln_data *dc, double t_target,
                                ln_int max_steps)
{
    const double t_mid = dc->t + 0.5 * (t_target - dc->t);
    if (t_mid > dc->t && t_mid < t_target) {
        const int status = ln_advance(m, companion, dc, t_mid, max_steps);
        if (status != LN_OK)
            return status;
    }
    return ln_advance(m, companion, dc, t_target, max_steps);
}

/* The warning of a run whose estimated error exceeds its goal from time t on (largest: the run's largest estimate,
   named when above estimate; 0 for none): the one text of the library and the native FMU. */
LN_API void ln_accuracy_text(const char *name, double t, double estimate, double goal, double largest, char *out,
                             size_t n)
{
    char worst[64] = "";
    if (largest > estimate)
        snprintf(worst, sizeof worst, " (largest %.3g m)", largest);
    snprintf(out, n, "%s: the estimated position error %.3g m at t = %g s exceeds the run's goal %.3g m%s. Tighten "
             "rtol (or the step); where a tighter tolerance does not bring it down, the motion passes a configuration "
             "it cannot resolve (docs/accuracy.md)", name, estimate, t, goal, worst);
}

/* The note of a run whose companion failed where the run went through (why: where and how the companion failed):
   the run's result stands, its error is unknown from there on. The library's and the native FMU's one text. */
LN_API void ln_estimate_failure_text(const char *name, const char *why, char *out, size_t n)
{
    snprintf(out, n, "%s: the error of this run cannot be estimated: its companion run failed %s (the error estimate "
             "is +inf from there on; the run's own result stands)", name, why);
}

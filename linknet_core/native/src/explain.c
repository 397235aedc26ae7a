/* A failed advance in words: what happened, where, and what may help. The one text of every path: the Python
 * binding (linknet_core.native.integrator.NativeIntegrator.explain), the numpy reference (through
 * linknet_core.errors.projection_failure, which passes its own numbers) and the self-contained FMU.
 *
 * Stage-independent: it reads the diagnostics a failure leaves in ln_data (the link, residuals, floor of a failed
 * projection onto (11); the tensions at the start of the step that failed) and the method, never the state.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "linknet.h"
#include "ln_math.h"

/* A residual that stalled within this factor of the floor its last Newton step allowed stalled at that floor. */
LN_API const double ln_near_floor = 4.0;
/* h omega above which an explicit step (RATTLE is Stormer-Verlet on the links' manifold) amplifies an oscillation
   of angular frequency omega instead of following it: a 1e12 mass-ratio chain hanging at rest runs at h omega =
   1.95 and fails at 2.05 with omega from ln_fastest_oscillation. */
LN_API const double ln_stability_limit = 2.0;
/* A failed step's omega is estimated from the tensions at its start, one moment of an oscillation that has grown
   and swings the tensions with it, so it can read low: falling chains of mass ratio 1e9 and 1e12 failed with
   h omega read between 0.8 and 200 (RATTLE and its compositions, dt 1e-3 .. 1e-6). So a failure beyond
   ln_stability_limit / ln_reads_low is put down to the step, and the advice keeps that margin. */
LN_API const double ln_reads_low = 4.0;

/* x as Python's repr writes a float: the fewest significant digits that read back as x, positional from 1e-4 to
   below 1e16 (with at least one decimal), scientific outside. Times and tolerances in messages then read the
   same from every path, and exactly. */
static void format_real(double x, char *out, size_t n)
{
    if (isnan(x) || isinf(x)) {
        snprintf(out, n, "%s", isnan(x) ? "nan" : x > 0 ? "inf" : "-inf");
        return;
    }
    char text[48];
    int digits = 1;
    for (; digits < 17; digits++) {
        snprintf(text, sizeof text, "%.*e", digits - 1, x);
        if (strtod(text, NULL) == x) break;
    }
    snprintf(text, sizeof text, "%.*e", digits - 1, x);
    const int exponent = atoi(strchr(text, 'e') + 1);
    if (exponent < -4 || exponent >= 16) {
        snprintf(out, n, "%s", text);
        return;
    }
    const int decimals = digits - 1 - exponent > 0 ? digits - 1 - exponent : 0;
    snprintf(out, n, "%.*f%s", decimals, x, decimals ? "" : ".0");
}

double ln_fastest_oscillation(const ln_model *m, const double *T)
{
    /* omega_k^2 = sum over the links of mass k of |T_l| / (M_k R_l): summed over k1 and k2 apart, each in link
       order, as linknet_core.dynamics.equations.fastest_oscillation does */
    if (m->L == 0 || m->K == 0) return 0.0;
    double *sum = calloc((size_t)(2 * m->K), sizeof(double));
    if (!sum) return 0.0;
    double *as_first = sum, *as_second = sum + m->K;
    for (ln_int l = 0; l < m->L; l++) {
        const double stiffness = fabs(T[l]) / m->R[l];
        as_first[m->k1[l]] += stiffness;
        as_second[m->k2[l]] += stiffness;
    }
    double worst = -INFINITY;
    for (ln_int k = 0; k < m->K; k++) {
        const double per_mass = (as_first[k] + as_second[k]) * m->inv_m[k];
        if (!(per_mass <= worst)) worst = per_mass;  /* a NaN is kept */
    }
    free(sum);
    return isfinite(worst) ? ln_sqrt(worst) : 0.0;
}

void ln_projection_failure(const char *where, double reached, double before, double floor, double dt,
                           double stage_fraction, double omega, char *out, size_t n)
{
    char head[2048];
    snprintf(head, sizeof head, "position projection onto the link lengths (11) did not converge %s (it was %.3g "
             "relative before projection)", where, before);
    const double h = stage_fraction * dt;
    if (h * omega > ln_stability_limit / ln_reads_low) {
        /* beyond the stability limit the steps amplify the oscillation: the step, not the configuration, is the
           cause, whatever the iteration's floor */
        char stage[64] = "";
        if (stage_fraction != 1.0) snprintf(stage, sizeof stage, " (its largest stage, %.3g dt)", stage_fraction);
        const double safe = ln_stability_limit / ln_reads_low;
        snprintf(out, n, "%s: the step exceeds the stability limit of explicit steps here: h omega = %.3g, for the "
                 "step h = %.3g s%s and omega = %.3g rad/s, the fastest oscillation of a mass between its tensioned "
                 "links, estimated at the start of the step that failed. The limit is h omega = %g; once the "
                 "oscillation has grown the estimate can read up to %g times low, and omega grows with the tensions "
                 "as the motion goes on. Use dop853 (the default: error-controlled, it follows omega as it grows), "
                 "or with a fixed step use dt below %.3g s (h omega = %g at this estimate; a motion that is still "
                 "loading up can need a smaller one later)", head, h * omega, h, stage, omega, ln_stability_limit,
                 ln_reads_low,
                 safe / (stage_fraction * omega), safe);
    } else if (floor > 0 && reached <= ln_near_floor * floor) {
        /* the linear model itself cannot remove the residual: a smaller step does not help */
        snprintf(out, n, "%s: it stalls at the floor this configuration allows (%.3g relative): the links' Newton "
                 "matrix is singular or badly conditioned here (a taut string, a loop passing a flat position, "
                 "extreme mass ratios), so a smaller step cannot help. Change the configuration or the masses", head,
                 floor);
    } else {
        /* the linear model would remove the residual but the step does not: outside Newton's region of
           convergence, which shrinks with the step */
        snprintf(out, n, "%s: Newton's linear model would remove the residual but its steps do not (the step is too "
                 "large for this configuration's nonlinearity, e.g. fast motion of light masses between heavy ones). "
                 "Reduce the step (or use an adaptive method, which chooses its own)", head);
    }
}

const char *ln_status_name(int status)
{
    static const char *const names[] = {"ok", "projection failed", "singular", "non-finite", "step underflow",
                                        "too many steps", "left the plane", "implicit kick failed", "bad argument",
                                        "out of memory", "anchor motion failed", "rope event chatter",
                                        "no rope mode", "not linearizable"};
    return status >= 0 && status < (int)(sizeof names / sizeof names[0]) ? names[status] : "unknown status";
}

void ln_explain(const ln_model *m, const ln_method *meth, const ln_data *d, int status, double t, double t_target,
                ln_int max_steps, const char *link_label, char *out, size_t n)
{
    char t0[48], t1[48], span[128];
    format_real(t, t0, sizeof t0);
    format_real(t_target, t1, sizeof t1);
    snprintf(span, sizeof span, "between t = %s and t = %s", t0, t1);
    const char *link = d->fail_link >= 0 && link_label ? link_label : "a link";
    switch (status) {
    case LN_PROJECTION_FAILED: {
        char where[1536];
        snprintf(where, sizeof where, "%s: after %lld iterations the residual is %.3g relative at %s", span,
                 (long long)d->fail_iterations, d->fail_residual, link);
        double dt = 0.0, stage_fraction = 1.0, omega = 0.0;
        if (meth->kind == LN_COMPOSITION) {  /* the core left the tensions at the start of the step that failed */
            stage_fraction = 0.0;
            for (ln_int i = 0; i < meth->n_gammas; i++) stage_fraction = ln_fmax(stage_fraction, fabs(meth->gammas[i]));
            dt = meth->dt;
            omega = ln_fastest_oscillation(m, d->T);
        }
        ln_projection_failure(where, d->fail_residual, d->fail_before, d->fail_floor, dt, stage_fraction, omega, out,
                              n);
        break;
    }
    case LN_IMPLICIT_KICK_FAILED:
        snprintf(out, n, "the implicit velocity half step (drag, dampers) does not converge %s at dt = %g: the damping "
                 "is too stiff for this step (h c / 2m near or above 1); reduce dt", span, meth->dt);
        break;
    case LN_STEP_UNDERFLOW: {
        char rtol[48], why[768] = "singular configuration or discontinuous input?";
        format_real(meth->rtol, rtol, sizeof rtol);
        if (d->fail_link >= 0)  /* the steps were cut because their positions could not be projected onto (11) */
            snprintf(why, sizeof why, "the position projection onto the link lengths (11) kept failing, last at %s "
                     "(residual %.3g relative after %lld iterations): a singular configuration such as a taut "
                     "string?", link, d->fail_residual, (long long)d->fail_iterations);
        snprintf(out, n, "step size underflow %s: the tolerance rtol = %s cannot be met (%s)", span, rtol, why);
        break;
    }
    case LN_TOO_MANY_STEPS: {
        char why[768] = "raise max_steps or the tolerance (or advance over shorter intervals)";
        if (d->floor_stops)  /* the steps were cut where the links' Newton matrix is (nearly) singular */
            snprintf(why, sizeof why, "the position projection onto the link lengths (11) has stopped at its "
                     "conditioning floor %lld times in this run (largest residual %.3g relative): a singular or badly "
                     "conditioned configuration (a taut string, a flat braced cell pushed out of its plane), where "
                     "more steps or a looser tolerance may not help", (long long)d->floor_stops, d->floor_reached);
        snprintf(out, n, "more than %lld steps %s; %s", (long long)max_steps, span, why);
        break;
    }
    case LN_NON_FINITE:
        snprintf(out, n, "the state became non-finite %s (the forces or the state contain NaN or infinity, or the "
                 "motion blew up); reduce the step or tolerance", span);
        break;
    case LN_BAD_ARGUMENT:
        snprintf(out, n, "cannot advance from t = %s to t = %s: the target must be later and finite", t0, t1);
        break;
    case LN_EVENT_CHATTER:
        snprintf(out, n, "more than %lld rope events in consecutive steps %s (a chatter of jerks): reduce the "
                 "tolerance, or the ropes' restitution", (long long)m->max_events_per_step, span);
        break;
    case LN_NO_MODE:
        snprintf(out, n, "the complementarity problem of the ropes at their length has no solution %s (the "
                 "constraints contradict each other, as a rope shorter than a rod beside it would), or it cycled and "
                 "has more than %lld touching ropes to enumerate", span, (long long)m->enumeration_limit);
        break;
    default:
        if (status > 0 && status <= LN_NOT_LINEARIZABLE)
            snprintf(out, n, "the native core stopped %s: %s", span, ln_status_name(status));
        else
            snprintf(out, n, "the native core stopped %s: status %d", span, status);
        break;
    }
}

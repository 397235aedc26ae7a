/* Located tension peaks (tension_peaks.h): the largest |T_l| of each link over an advance and its time. */
#include <math.h>
#include <string.h>

#include "tension_peaks.h"

void ln_peaks_begin(const ln_model *m, ln_data *d, double t)
{
    const ln_int L = m->L;
    const double *T = d->T;
    double *newer = d->T_history + L, *peak = d->peak_work, *when = d->peak_work + L;
    for (ln_int l = 0; l < L; l++) {
        peak[l] = T[l];
        when[l] = t;
        newer[l] = T[l];
    }
    d->history_t1 = t;
    d->history_points = 1;
}

/* With T at the last three step ends y0, y1, y2 (times t0 < t1 < t2, h1 = t1 - t0, h2 = t2 - t1), the quadratic
   through them in Newton's form about t1: q(t1 + s) = y1 + slope s + c s^2, c the second divided difference, slope
   q'(t1). Its vertex lies at s = a / c, a = -slope / 2, where q = y1 + slope s / 2; it counts where it lies inside
   (t0, t2) (-h1 < s < h2: a + c h1 and c h2 - a both of c's sign, tested without dividing) and beats the peak so far
   in magnitude (then it is a maximum of |q|: q is monotone on either side of it, and |q| there exceeds |q| at the
   three step ends around it). ~0.2 us per step on 100 links (the branches are rarely taken: a branchless form that
   vectorized took 0.28 us). */
void ln_peaks_step(const ln_model *m, ln_data *d, double t)
{
    const ln_int L = m->L;
    const double *T = d->T;
    double *older = d->T_history, *newer = d->T_history + L, *peak = d->peak_work, *when = d->peak_work + L;
    const double t1 = d->history_t1, h2 = t - t1;
    if (d->history_points >= 2) {
        const double h1 = t1 - d->history_t0, r1 = 1.0 / h1, r2 = 1.0 / h2, r_span = 1.0 / (t - d->history_t0);
        for (ln_int l = 0; l < L; l++) {
            const double y0 = older[l], y1 = newer[l], y2 = T[l];
            if (fabs(y2) > fabs(peak[l])) {
                peak[l] = y2;
                when[l] = t;
            }
            const double d1 = (y1 - y0) * r1, c = ((y2 - y1) * r2 - d1) * r_span;
            const double slope = d1 + c * h1, a = -0.5 * slope, p = a + c * h1, q = c * h2 - a;
            if ((c > 0.0 && p > 0.0 && q > 0.0) || (c < 0.0 && p < 0.0 && q < 0.0)) {
                const double s = a / c, top = y1 + 0.5 * slope * s;
                if (fabs(top) > fabs(peak[l])) {
                    peak[l] = top;
                    when[l] = t1 + s;
                }
            }
            older[l] = y1;
            newer[l] = y2;
        }
    } else {
        for (ln_int l = 0; l < L; l++) {
            if (fabs(T[l]) > fabs(peak[l])) {
                peak[l] = T[l];
                when[l] = t;
            }
            older[l] = newer[l];
            newer[l] = T[l];
        }
    }
    d->history_t0 = t1;
    d->history_t1 = t;
    d->history_points++;
}

void ln_peaks_publish(const ln_model *m, ln_data *d)
{
    if (!m->L) return;
    memcpy(d->T_peak, d->peak_work, (size_t)m->L * sizeof(double));
    memcpy(d->T_peak_time, d->peak_work + m->L, (size_t)m->L * sizeof(double));
}

int ln_tension_peaks_located(const ln_data *d) { return d->history_points > 0; }

void ln_tension_peaks(const ln_model *m, const ln_data *d, int advanced, double *peak, double *time)
{
    const ln_int L = m->L;
    if (advanced && ln_tension_peaks_located(d)) {
        if (L) {
            memcpy(peak, d->T_peak, (size_t)L * sizeof(double));
            memcpy(time, d->T_peak_time, (size_t)L * sizeof(double));
        }
        return;
    }
    for (ln_int l = 0; l < L; l++) {
        peak[l] = d->T[l];
        time[l] = d->t;
    }
}

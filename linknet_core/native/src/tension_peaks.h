/* Located tension peaks: for each link, the largest |T_l| over an advance (one output or communication interval),
 * signed, and when it occurred, from the tensions (25)-(26) that the step loops have at every accepted step's end.
 *
 * The step loops call ln_peaks_begin with d->T at the advance's start (under the inputs held over it: the right limit
 * there, so a jump of the input at the start is seen), ln_peaks_step with d->T at each accepted step's end, and
 * ln_peaks_publish when the interval is done. Every
 * such value is a candidate, the interval's ends included; and where three consecutive step ends (t0, t1, t2) put
 * the vertex of the quadratic through them inside (t0, t2), the vertex is one too: the peak between the step ends,
 * located. Its error is the quadratic's interpolation error, about |T'''| h^3 / 16 with h the step, and the time's
 * about |T'''| h^2 / (4 |T''|) (docs/accuracy.md, "Tension peaks between outputs", measures them). O(L) work per
 * step, no solve. The numpy reference does the same (linknet_core.integrators.base.TensionPeaks).
 */
#ifndef LINKNET_TENSION_PEAKS_H
#define LINKNET_TENSION_PEAKS_H

#include "linknet.h"

/* A new interval at t: d->T is T there. */
void ln_peaks_begin(const ln_model *m, ln_data *d, double t);
/* An accepted step's end at t: d->T is T there. */
void ln_peaks_step(const ln_model *m, ln_data *d, double t);
/* The interval's peaks into d->T_peak, d->T_peak_time, once all its steps went through: an advance that fails leaves
   those of the last one that did not. */
void ln_peaks_publish(const ln_model *m, ln_data *d);
/* Whether the last advance located peaks (not on the static and free rigid bodies' paths, nor before any advance). */
int ln_tension_peaks_located(const ln_data *d);
/* The peaks of the interval just advanced over (advanced 1) into peak, time (L each); where that advance located
   none (a static scene, whose tensions stand still over an interval with its input held; the free rigid bodies'
   path, whose tensions the steps do not evaluate) or nothing was advanced (advanced 0), T and t as they stand in the
   data: evaluate first (ln_evaluate). */
void ln_tension_peaks(const ln_model *m, const ln_data *d, int advanced, double *peak, double *time);

#endif

/* Ropes: links that pull and never push, |X_k2 - X_k1| <= R_l with T_l >= 0, their mode, impacts and events, for
 * every method. The numpy reference of every rule here is linknet_core.dynamics.unilateral (the
 * model, the impact, the mode), linknet_core.dynamics.complementarity (the LCP) and linknet_core.integrators.events
 * (detection, location, the event); this file mirrors them for ropes and a ground with Coulomb friction
 * (stages/friction.c has the sliding friction and the slip law; a stuck contact's grips are links of the mode, a
 * sliding one's friction a column of the complementarity problems' matrix).
 *
 * A ground's contact is a rope too: from its free mass to a virtual anchor (the model's last masses, fixed, of
 * infinite mass) placed straight above it before every evaluation at the contact length R_c from the plane, so that
 * its E is the plane's normal, its term of (26) (n . U_k)^2 / R_c and its gap the height above the plane
 * (ModeDynamics' contact); its gap and rate are taken from the plane directly.
 *
 * A rope's gap is g_l = R_l - |X_k2 - X_k1| >= 0, its rate dg/dt = -(d . dU) / |d|. While taut a rope is a link of
 * the seed in (9), (11)-(13), (25)-(26); slack, it is out of the system: the mode's model (a copy of the model whose
 * 1/R_l is 0 on the slack ropes, d->mode_inv_R) gives it E_l = 0, no term of (26), no residual of (11) and a unit
 * diagonal in A (stages/tension.c), so that every stage of the rod path serves the mode unchanged.
 *
 * Which touching ropes carry tension is the mixed LCP (Moreau; Lotstedt; Pfeiffer and Glocker, Multibody Dynamics
 * with Unilateral Contacts, 1996; Cottle, Pang and Stone, The Linear Complementarity Problem, 1992, sec. 1.2, 4.2):
 * with W = C M^-1 C^T (A of (25)) and b = B of (26), (W lambda - b)_i = 0 on the rods, and lambda_i >= 0,
 * w_i = (W lambda - b)_i >= 0, lambda_i w_i = 0 on the touching ropes. Solved by principal pivoting with Murty's
 * least-index rule (Murty 1974): each basis is the rods and the basis ropes as equalities, solved by the core's own
 * tension solver on the basis's mask (minimum-norm (31) where singular), w of the other rows from C M^-1 C^T lambda -
 * b; the lowest rope that breaks its sign condition is flipped; a problem that cycles has its active sets enumerated
 * (at most 2^enumeration_limit). At an impact the same problem one level down gives the impulses: Moreau's impact
 * law with Newton's restitution, b = -(C U + e min(C U, 0)); inelastic, the velocities are the projection onto the
 * impact's active set in the mass metric; with a common e, U- + (1 + e)(P U- - U-).
 *
 * Events, after every accepted step, in the mode it was taken in: the slack ropes' gaps along the step's cubic
 * Hermite of X, whose sign is the sextic R^2 - |d(theta)|^2, screened by its Bernstein coefficients (Farouki and
 * Rajan, Computer Aided Geometric Design 5, 1988) and looked at exactly where they allow a dip, each dip confirmed on
 * the method's own step to its lowest point; the taut ropes' tensions at the step's end against -force_tol of the
 * largest |T|, and where the end shows none, at the step's inner stages (a tension that dips through zero and
 * recovers within one step: an adaptive method's stages, a fixed-step method's RATTLE stages' midpoints), each
 * candidate confirmed on the method's own step. The event is
 * taken on the method's own step: a gap's time by Newton's method on the step's length, a force's by Illinois'
 * regula falsi on it, ending just past the zero; there the positions go onto the touching ropes,
 * the impact is applied and the next mode chosen. The adaptive methods end the step at the event and go on with their
 * controller; the fixed-step ones (RATTLE and its compositions) finish the step from the event in the new mode, so
 * that their steps stay where they are (a part shorter than short_step of dt by a Taylor step).
 */
#include <math.h>
#include <string.h>

#include "../dim.h"
#include "../drive.h"
#include "../linknet.h"
#include "../ln_math.h"
#include "../stages.h"

#define ROPE_EPS 2.220446049250313e-16
#define ROPE_TINY 2.2250738585072014e-308

/* ---- DIM-independent helpers (static: one copy in each DIM's translation unit, which includes this file once) -- */
typedef double (*rope_root_fn)(void *ctx, double x);

/* (lo, hi): the bracket of a sign change of f, f(lo) >= 0 > f(hi), shrunk to xtol (relative) by the Illinois
   variant of regula falsi, with a bisection wherever the last three iterations did not halve it; the first point
   tried is guess where has_guess; a regula falsi point within a sixteenth of the tolerance of an end is moved that
   far inside it, so that one more value closes the bracket (linknet_core.dynamics.roots.bracketed_root). */
static void rope_bracketed_root(rope_root_fn f, void *ctx, double *lo_io, double *hi_io, double f_lo, double f_hi,
                                double xtol, int has_guess, double guess)
{
    double lo = *lo_io, hi = *hi_io, widths[200], m = guess;
    int last = 0, n_widths = 0, have_m = has_guess;
    for (int it = 0; it < 200; it++) {
        if (hi - lo <= xtol * ln_fmax(1.0, ln_fmax(fabs(lo), fabs(hi)))) break;
        if (!have_m) {
            if (n_widths >= 3 && hi - lo > 0.5 * widths[n_widths - 3]) m = 0.5 * (lo + hi);
            else {
                const double close = xtol / 16 * ln_fmax(1.0, ln_fmax(fabs(lo), fabs(hi)));
                m = (lo * f_hi - hi * f_lo) / (f_hi - f_lo);
                m = ln_fmax(ln_fmin(m, hi - close), lo + close);
            }
        }
        if (!(lo < m && m < hi)) {
            m = 0.5 * (lo + hi);
            if (!(lo < m && m < hi)) break;
        }
        const double fm = f(ctx, m);
        if (fm >= 0) {
            lo = m;
            f_lo = fm;
            if (last == 1) f_hi *= 0.5;  /* the same end moved twice: halve the other's value (Illinois) */
            last = 1;
        } else {
            hi = m;
            f_hi = fm;
            if (last == -1) f_lo *= 0.5;
            last = -1;
        }
        widths[n_widths++] = hi - lo;
        have_m = 0;
    }
    *lo_io = lo;
    *hi_io = hi;
}

/* p(x), coefficients lowest degree first, by Horner's rule from the highest (as numpy's polyval). */
static double rope_polyval(const double *p, int n, double x)
{
    double s = 0.0;
    for (int i = n - 1; i >= 0; i--) s = s * x + p[i];
    return s;
}

/* sign p(x) + shift, for the bracketing root find (which wants f(lo) >= 0 > f(hi)) */
struct rope_poly {
    int n;
    double p[7], sign, shift;
};

static double rope_poly_fn(void *ctx, double x)
{
    const struct rope_poly *q = ctx;
    return q->sign * rope_polyval(q->p, q->n, x) + q->shift;
}

/* The real roots in (0, 1) of the polynomial p of n coefficients (degree n - 1 <= 6), ascending, into roots;
   returns their count. Recursively: the roots of p' cut [0, 1] into monotone pieces, each sign change is bracketed. */
static int rope_roots_01(const double *p, int n, double *roots)
{
    while (n > 0 && p[n - 1] == 0.0) n--;
    if (n < 2) return 0;
    double dp[7], cuts[8];
    for (int i = 1; i < n; i++) dp[i - 1] = (double)i * p[i];
    int n_cuts = 0;
    cuts[n_cuts++] = 0.0;
    n_cuts += rope_roots_01(dp, n - 1, cuts + 1);
    cuts[n_cuts++] = 1.0;
    struct rope_poly q = {n, {0}, 1.0, 0.0};
    for (int i = 0; i < n; i++) q.p[i] = p[i];
    int count = 0;
    for (int i = 0; i + 1 < n_cuts; i++) {
        double a = cuts[i], b = cuts[i + 1];
        const double fa = rope_polyval(p, n, a), fb = rope_polyval(p, n, b);
        if (fa == 0.0 && a > 0.0 && (count == 0 || roots[count - 1] != a)) roots[count++] = a;
        if (!((fa > 0.0 && fb < 0.0) || (fa < 0.0 && fb > 0.0))) continue;
        q.sign = fa > 0.0 ? 1.0 : -1.0;
        rope_bracketed_root(rope_poly_fn, &q, &a, &b, q.sign * fa, q.sign * fb, 4e-16, 0, 0.0);
        roots[count++] = b;
    }
    return count;
}

/* Whether the sextic P (7 coefficients, lowest degree first) can fall below -depth on [0, 1]: the minimum of its
   Bernstein coefficients of degree 6, b_j = sum_{i <= j} C(j, i) / C(6, i) a_i (Farouki and Rajan 1988, eq. 2). */
static int rope_may_fall_below(const double *P, double depth)
{
    static const double binom[7][7] = {{1}, {1, 1}, {1, 2, 1}, {1, 3, 3, 1}, {1, 4, 6, 4, 1}, {1, 5, 10, 10, 5, 1},
                                       {1, 6, 15, 20, 15, 6, 1}};
    double lowest = INFINITY;
    for (int j = 0; j <= 6; j++) {
        double b = 0.0;
        for (int i = 0; i <= j; i++) b += P[i] * (binom[j][i] / binom[6][i]);
        if (b < lowest) lowest = b;
    }
    return lowest < -depth;
}

/* Each excursion of the polynomial p (7 coefficients) below -depth on [0, 1], in order, however brief: its zero
   crossing on the way down and its lowest point, into crossing, lowest (3 at most: a sextic has 3 minima);
   returns the count (linknet_core.integrators.events.gap_dips). */
static int rope_gap_dips(const double *p_in, double depth, double *crossing, double *lowest)
{
    int n = 7;
    while (n > 0 && p_in[n - 1] == 0.0) n--;
    if (n < 2) {
        if (n == 1 && p_in[0] < -depth) {
            crossing[0] = lowest[0] = 0.0;
            return 1;
        }
        return 0;
    }
    double dp[6], cuts[8], values[8];
    for (int i = 1; i < n; i++) dp[i - 1] = (double)i * p_in[i];
    int n_cuts = 0;
    cuts[n_cuts++] = 0.0;
    n_cuts += rope_roots_01(dp, n - 1, cuts + 1);
    cuts[n_cuts++] = 1.0;
    for (int i = 0; i < n_cuts; i++) values[i] = rope_polyval(p_in, n, cuts[i]);
    int count = 0, after = -1, j = 0;
    while (j < n_cuts && count < 3) {
        if (!(values[j] < -depth)) {
            j++;
            continue;
        }
        int k = j;
        while (k + 1 < n_cuts && values[k + 1] < -depth) k++;
        int low = j;
        for (int i = j + 1; i <= k; i++)
            if (values[i] < values[low]) low = i;
        lowest[count] = cuts[low];
        if (j == 0) {
            crossing[count] = 0.0;
        } else {
            int i = -1;
            for (int q = after + 1; q < j; q++)
                if (values[q] >= 0.0) i = q;
            const double shift = i >= 0 ? 0.0 : depth;
            if (i < 0) i = j - 1;
            struct rope_poly poly = {n, {0}, 1.0, shift};
            for (int c = 0; c < n; c++) poly.p[c] = p_in[c];
            double a = cuts[i], b = cuts[i + 1];
            rope_bracketed_root(rope_poly_fn, &poly, &a, &b, values[i] + shift, values[i + 1] + shift, 4e-16, 0, 0.0);
            crossing[count] = b;
        }
        count++;
        after = k;
        j = k + 1;
    }
    return count;
}

/* ---- the ground's contacts --------------------------------------------------------------------------------------- */
/* A ground runs on the 3-D path only (the library builds its model with no plane). Contact c is the model's rope
   n_ropes - n_contacts + c, its link L - n_grips - n_contacts + c from its mass to its virtual anchor, the mass
   K - n_grips - n_contacts + c; with friction grip i of contact c is link L - n_grips + 2 c + i, its anchor mass
   K - n_grips + 2 c + i (ln_model.n_grips). */
static inline int FN(is_contact)(const ln_model *m, ln_int l)
{
    return l >= m->L - m->n_grips - m->n_contacts && l < m->L - m->n_grips;
}


/* The height of mass k above the ground, n . (X_k - p) (Ground.gaps). */
static inline double FN(contact_height)(const ln_model *m, const double *X, ln_int k)
{
    double s = 0.0;
    for (int e = 0; e < DIM; e++) s += (X[k * DIM + e] - m->ground_point[e]) * m->ground_normal[e];
    return s;
}

/* Each contact's virtual anchor straight above its mass at the contact length R_c from the ground, Q = X_k +
   (R_c - g_k) n (ModeDynamics.pad without its grips). */
static void FN(contacts_place_anchors)(const ln_model *m, double *X)
{
    const ln_int first_anchor = m->K - m->n_grips - m->n_contacts;
    const double Rc = m->scene_size, *n = m->ground_normal;
    for (ln_int c = 0; c < m->n_contacts; c++) {
        const ln_int k = m->contact_mass[c], q = first_anchor + c;
        const double lift = Rc - FN(contact_height)(m, X, k);
        for (int e = 0; e < DIM; e++) X[q * DIM + e] = X[k * DIM + e] + lift * n[e];
    }
}

/* A field V on the masses (a velocity, or a displacement) padded as the anchors move with it: each contact's virtual
   anchor with its mass's part along the plane, V_Q = V_k - (n . V_k) n, the grips' anchors at rest
   (ModeDynamics.pad_velocity): a contact's row of C V is then n . V_k, a grip's t_i . V_k. */
static void FN(contacts_pad_velocity)(const ln_model *m, double *V)
{
    const ln_int first_anchor = m->K - m->n_grips - m->n_contacts, first_grip = m->K - m->n_grips;
    const double *n = m->ground_normal;
    for (ln_int c = 0; c < m->n_contacts; c++) {
        const ln_int k = m->contact_mass[c], q = first_anchor + c;
        double normal = 0.0;
        for (int e = 0; e < DIM; e++) normal += V[k * DIM + e] * n[e];
        for (int e = 0; e < DIM; e++) V[q * DIM + e] = V[k * DIM + e] - normal * n[e];
    }
    for (ln_int i = first_grip * DIM; i < m->K * DIM; i++) V[i] = 0.0;
}

/* Each contact's virtual anchor straight above its mass (contacts_place_anchors), moving with the mass along the
   plane (contacts_pad_velocity): the link's E is then n, its term of (26) (n . U_k)^2 / R_c and its gap g_k. With
   friction each contact's two grip anchors beside its mass at X_k + R_c t_i, at rest (a grip's E is t_i, its row of
   C t_i . U_k). U may be NULL. */
void FN(ln_contacts_place)(const ln_model *m, double *X, double *U)
{
    const ln_int first_grip = m->K - m->n_grips;
    const double Rc = m->scene_size;
    FN(contacts_place_anchors)(m, X);
    for (ln_int c = 0; c < m->n_contacts && m->n_grips; c++) {
        const ln_int k = m->contact_mass[c];
        for (ln_int i = 0; i < 2; i++) {
            const ln_int g = first_grip + 2 * c + i;
            for (int e = 0; e < DIM; e++) X[g * DIM + e] = X[k * DIM + e] + Rc * m->ground_tangent[3 * i + e];
        }
    }
    if (U) FN(contacts_pad_velocity)(m, U);
}

/* Whether every contact of the mode in use (d->mode_inv_R) has its mass on the plane at X, within tol of the contact
   length and 8 ulps of the largest coordinate of the scene's masses (ModeDynamics.project_positions' test). */
static int FN(contacts_on_plane)(const ln_model *mm, const double *X, double tol)
{
    double largest = 0.0;
    for (ln_int i = 0; i < (mm->K - mm->n_contacts - mm->n_grips) * DIM; i++) largest = ln_fmax(largest, fabs(X[i]));
    const double limit = tol * mm->scene_size + 8 * ROPE_EPS * largest;
    for (ln_int c = 0; c < mm->n_contacts; c++)
        if (mm->inv_R[FN(contact_link)(mm, c)] != 0.0
            && !(fabs(FN(contact_height)(mm, X, mm->contact_mass[c])) <= limit))
            return 0;
    return 1;
}

/* The positions X projected onto (11) of the mode in use (d->mode_inv_R) along M^-1 C(X)^T from X itself, to tol;
   with a ground, repeated with the anchors re-placed until every active contact's gap is within tol of the
   contact length and 8 ulps of the largest coordinate: the projection moves a mass onto the sphere |X_k - Q| = R_c,
   which touches the plane under Q, and a mass moved sideways by tau within it ends tau^2 / (2 R_c) off the plane
   (ModeDynamics.project_positions). The unit vectors at the result in d->E0, A factored there. */
int FN(ln_contacts_project)(const ln_model *mm, const ln_method *meth, ln_data *d, double *X, double tol)
{
    int status = LN_OK;
    for (int pass = 0; pass < 4; pass++) {
        if (mm->n_contacts) FN(ln_contacts_place)(mm, X, NULL);
        FN(ln_unit_vectors)(mm, X, d->E0);
        if ((status = FN(ln_factor_tension_matrix)(mm, d, d->E0)) != LN_OK) return status;
        if ((status = project_positions(mm, d, X, d->E0, tol, meth->max_projection_iter)) != LN_OK) return status;
        if (!mm->n_contacts || FN(contacts_on_plane)(mm, X, tol)) break;
    }
    if (mm->n_contacts) FN(ln_contacts_place)(mm, X, NULL);
    return status;
}

/* RATTLE's position stage with a ground (ModeDynamics.project_positions with direction_at, seed (11)): Xc onto the
   mode's (11) along M^-1 C(X)^T, E_dir the unit vectors at the stage's start X, A factored there on entry; each pass
   re-places the contacts' anchors above Xc and leaves the grips where the stage's start put them (at rest through
   the drift: a stuck mass is pulled back to where the stage began), until every active contact is on the plane.
   A pass after one that needed exact Newton (whose solves leave another factorisation) factors A at E_dir again. */
static int FN(contacts_project_along)(const ln_model *mm, const ln_method *meth, ln_data *d, double *Xc,
                                      const double *E_dir, double tol)
{
    const ln_int exact = d->exact_newton_projections;
    int status = LN_OK;
    for (int pass = 0; pass < 4; pass++) {
        FN(contacts_place_anchors)(mm, Xc);
        if (pass > 0 && d->exact_newton_projections != exact
            && (status = FN(ln_factor_tension_matrix)(mm, d, E_dir)) != LN_OK)
            return status;
        if ((status = project_positions(mm, d, Xc, E_dir, tol, meth->max_projection_iter)) != LN_OK) return status;
        if (FN(contacts_on_plane)(mm, Xc, tol)) break;
    }
    return status;
}

/* ---- the ropes' geometry, unmasked ---------------------------------------------------------------------------- */
static inline double FN(rope_gap)(const ln_model *m, const double *X, ln_int l)
{
    if (FN(is_contact)(m, l)) return FN(contact_height)(m, X, m->k1[l]);
    const ln_int a = m->k1[l], b = m->k2[l];
    double dd = 0.0;
    for (int e = 0; e < DIM; e++) {
        const double x = X[b * DIM + e] - X[a * DIM + e];
        dd += x * x;
    }
    const double R = m->R[l];
    return (R * R - dd) / (R + ln_sqrt(dd));  /* no cancellation at g ~ 0 */
}

static inline double FN(rope_rate)(const ln_model *m, const double *X, const double *U, ln_int l)
{
    if (FN(is_contact)(m, l)) {  /* n . U_k */
        double s = 0.0;
        for (int e = 0; e < DIM; e++) s += U[m->k1[l] * DIM + e] * m->ground_normal[e];
        return s;
    }
    const ln_int a = m->k1[l], b = m->k2[l];
    double dd = 0.0, s = 0.0;
    for (int e = 0; e < DIM; e++) {
        const double x = X[b * DIM + e] - X[a * DIM + e];
        dd += x * x;
        s += x * (U[b * DIM + e] - U[a * DIM + e]);
    }
    return -s / ln_sqrt(dd);
}

/* The fastest free mass, or what gravity gives over the scene's size (UnilateralDynamics.velocity_scale). */
static double FN(rope_velocity_scale)(const ln_model *m, const double *U)
{
    double fastest = 0.0;
    for (ln_int f = 0; f < m->n_free; f++) {
        const ln_int k = m->free_idx[f];
        double s = 0.0;
        for (int e = 0; e < DIM; e++) s += U[k * DIM + e] * U[k * DIM + e];
        fastest = ln_fmax(fastest, s);
    }
    return ln_fmax(ln_fmax(ln_sqrt(fastest), ln_sqrt(m->gravity_norm * m->scene_size)), 1e-300);
}

/* Below this rebound speed an impact is perfectly inelastic: a fall of rest_height of the scene's size under its
   acceleration scale (UnilateralDynamics.rest_speed). */
static double FN(rope_rest_speed)(const ln_model *m, const double *U)
{
    const double v = FN(rope_velocity_scale)(m, U);
    const double acceleration = ln_fmax(m->gravity_norm, v * v / m->scene_size);
    return ln_sqrt(2.0 * acceleration * m->rest_height * m->scene_size);
}

/* The largest |coordinate| of the positions in 3-D (the numpy reference's np.abs(X).max(), the scale of the events'
   round-off tolerances): a planar run's X = o + P x. */
static double FN(rope_largest_coordinate)(const ln_model *m, const double *X)
{
    double s = 0.0;
#if DIM == 2
    const double *P = m->plane_P, *o = m->plane_o;
    for (ln_int k = 0; k < m->K; k++)
        for (int e = 0; e < 3; e++)
            s = ln_fmax(s, fabs(o[e] + P[2 * e] * X[2 * k] + P[2 * e + 1] * X[2 * k + 1]));
#else
    for (ln_int i = 0; i < (m->K - m->n_contacts - m->n_grips) * DIM; i++)
        s = ln_fmax(s, fabs(X[i]));  /* not the anchors */
#endif
    return s;
}

/* The mode's model sees the links of mask (1: in the system) through d->mode_inv_R. */
static void FN(rope_use_mask)(const ln_model *m, ln_data *d, const uint8_t *mask)
{
    for (ln_int l = 0; l < m->L; l++) d->mode_inv_R[l] = mask[l] ? 1.0 / m->R[l] : 0.0;
}

/* The mask of the rods, the ropes r with flags[r] and the grips of the contacts that stick in the mode. */
static void FN(rope_mask_of)(const ln_model *m, ln_data *d, const uint8_t *flags)
{
    for (ln_int l = 0; l < m->L; l++) d->mask[l] = 1;
    for (ln_int r = 0; r < m->n_ropes; r++) d->mask[m->rope_link[r]] = flags[r];
    for (ln_int l = m->L - m->n_grips; l < m->L; l++) d->mask[l] = d->link_active[l];
    FN(rope_use_mask)(m, d, d->mask);
}

/* The driven anchors' rows of X, U and of the base force at t (a no-op without driven anchors; 3-D there), and the
   contacts' virtual anchors placed: what every evaluation at (X, U) needs first. */
static int FN(rope_drive)(const ln_model *m, ln_data *d, double t, double *X, double *U)
{
    if (m->n_contacts) FN(ln_contacts_place)(m, X, U);
    return m->n_driven ? ln_drive_rows(m, d, t, X, U, d->F_base, DIM) : LN_OK;
}

/* The forces F of (9) at (X, U): the base force and the force elements, into F (K, DIM). */
static const double *FN(rope_forces)(const ln_model *m, ln_data *d, const double *X, const double *U,
                                     const double *F_base)
{
    if (m->n_elements == 0) return F_base;
    FN(ln_scene_forces)(m, X, U, F_base, d->F);
    return d->F;
}

/* ---- the mixed LCP of the touching ropes (linknet_core.dynamics.complementarity.solve_mixed_lcp) --------------- */
struct FN(rope_lcp) {
    const double *E;      /* (L, DIM) every link's unit vector */
    const double *b;      /* (L) right-hand side on the problem's rows */
    const uint8_t *rows;  /* (n_ropes) the ropes that are rows of the problem (the rods always are) */
    uint8_t *basis;       /* (n_ropes) in: the start; out: the ropes in the final basis */
    const uint8_t *release;  /* (n_ropes) or NULL */
    double *lam;          /* (L) out */
    double *w;            /* (L) scratch: W lambda - b */
    double *v;            /* (K, DIM) scratch */
    /* friction: the problem's matrix is W + sum_j cols_j e_{col_row_j}^T, a sliding contact's friction carried into
       its column (ModeDynamics.normal_system's -D; the impact's rate shift); solved in each basis from W's own
       solves (stages/friction.c's scratch) */
    ln_int n_cols;
    const ln_int *col_row;  /* (n_cols) the link of each column */
    const double *cols;     /* (n_cols, L) */
};

/* lambda of one basis: the rods and the basis ropes as equalities, solved by the tension solver on their mask. */
static int FN(rope_basis_solution)(const ln_model *mm, ln_data *d, const struct FN(rope_lcp) *p, const uint8_t *basis)
{
    FN(rope_mask_of)(mm, d, basis);
    double *Em = d->E0, *rhs = d->phi;
    FN(ln_unit_vectors)(mm, d->Xc, Em);
    const int status = FN(ln_factor_tension_matrix)(mm, d, Em);
    if (status != LN_OK) return status;
    for (ln_int l = 0; l < mm->L; l++) rhs[l] = d->mask[l] ? p->b[l] : 0.0;
    FN(ln_solve_tension_system)(mm, d, rhs, p->lam);
    for (ln_int l = 0; l < mm->L; l++)
        if (!d->mask[l]) p->lam[l] = 0.0;
    if (!p->n_cols) return LN_OK;
    /* the friction's columns of the basis' rows: lambda = W_B^-1 b - sum_j y_j lambda_{row j}, y_j = W_B^-1 col_j,
       and on those rows (I + Y) x = (W_B^-1 b)_rows, as the acceleration level's (I - Y_ss) N_s = T0_s */
    struct FN(friction_work) fw = FN(friction_scratch)(mm, d);
    const ln_int L = mm->L;
    ln_int *on = fw.starting, n_on = 0;
    for (ln_int j = 0; j < p->n_cols; j++) {
        if (!d->mask[p->col_row[j]]) continue;
        double *y = fw.ycols + n_on * L;
        for (ln_int l = 0; l < L; l++) rhs[l] = d->mask[l] ? p->cols[j * L + l] : 0.0;
        FN(ln_solve_tension_system)(mm, d, rhs, y);
        for (ln_int l = 0; l < L; l++)
            if (!d->mask[l]) y[l] = 0.0;
        on[n_on++] = j;
    }
    if (!n_on) return LN_OK;
    for (ln_int i = 0; i < n_on; i++) {
        const ln_int row = p->col_row[on[i]];
        for (ln_int j = 0; j < n_on; j++) fw.matrix[i * n_on + j] = (i == j) + fw.ycols[j * L + row];
        fw.rhs[i] = p->lam[row];
    }
    if (friction_dense_solve(n_on, fw.matrix, fw.rhs)) return LN_SINGULAR;
    for (ln_int j = 0; j < n_on; j++)
        for (ln_int l = 0; l < L; l++) p->lam[l] -= fw.ycols[j * L + l] * fw.rhs[j];
    return LN_OK;
}

/* w = C M^-1 C^T lambda - b on the ropes of the problem. */
static void FN(rope_lcp_w)(const ln_model *mm, const struct FN(rope_lcp) *p)
{
    for (ln_int i = 0; i < mm->K * DIM; i++) p->v[i] = 0.0;
    FN(ln_add_correction)(mm, p->E, p->lam, 1.0, p->v);
    for (ln_int r = 0; r < mm->n_ropes; r++) {
        if (!p->rows[r]) continue;
        const ln_int l = mm->rope_link[r], a = mm->k1[l], b = mm->k2[l];
        double s = 0.0;
        for (int e = 0; e < DIM; e++) s += p->E[l * DIM + e] * (p->v[a * DIM + e] - p->v[b * DIM + e]);
        for (ln_int j = 0; j < p->n_cols; j++) s += p->cols[j * mm->L + l] * p->lam[p->col_row[j]];
        p->w[l] = s - p->b[l];
    }
}

/* Solves the problem; the state the unit vectors were taken at is in d->Xc. LN_OK or LN_NO_MODE. */
static int FN(rope_solve_lcp)(const ln_model *mm, ln_data *d, struct FN(rope_lcp) *p)
{
    const ln_int L = mm->L, R = mm->n_ropes;
    /* the problem's scale: its rows' largest |b| and largest diagonal entry of W, |E_l|^2 (1/M_k1 + 1/M_k2) */
    double b_scale = 0.0, diag = 0.0;
    ln_int n_rows = 0;
    for (ln_int l = 0; l < L; l++) d->mask[l] = l < L - mm->n_grips || d->link_active[l];  /* the grips in the mode */
    for (ln_int r = 0; r < R; r++) {
        d->mask[mm->rope_link[r]] = p->rows[r];
        n_rows += p->rows[r] != 0;
        if (!p->rows[r]) p->basis[r] = 0;
    }
    for (ln_int l = 0; l < L; l++) {
        if (!d->mask[l]) continue;
        b_scale = ln_fmax(b_scale, fabs(p->b[l]));
        double sq = 0.0;
        for (int e = 0; e < DIM; e++) sq += p->E[l * DIM + e] * p->E[l * DIM + e];
        diag = ln_fmax(diag, fabs(sq * (mm->inv_m[mm->k1[l]] + mm->inv_m[mm->k2[l]])));
    }
    b_scale = ln_fmax(b_scale, ROPE_TINY);
    diag = ln_fmax(diag, ROPE_TINY);
    const double tol_w = mm->lcp_tol * b_scale, tol_l = mm->lcp_tol * b_scale / diag;
    int status;
    for (ln_int it = 0; it < mm->pivots_per_row * n_rows + 1; it++) {
        if ((status = FN(rope_basis_solution)(mm, d, p, p->basis)) != LN_OK) return status;
        FN(rope_lcp_w)(mm, p);
        ln_int bad = -1;
        for (ln_int r = 0; r < R && bad < 0; r++) {
            if (!p->rows[r]) continue;
            const ln_int l = mm->rope_link[r];
            const double low = p->release && p->release[r] ? tol_l : -tol_l;
            if ((p->basis[r] && p->lam[l] < low) || (!p->basis[r] && p->w[l] < -tol_w)) bad = r;
        }
        if (bad < 0) return LN_OK;
        p->basis[bad] = !p->basis[bad];
    }
    /* a degenerate problem that cycles: every active set, the one that breaks the conditions least */
    if (n_rows > mm->enumeration_limit) return LN_NO_MODE;
    uint8_t *trial = d->rope_flags + 7 * R, *best_basis = d->rope_flags + 6 * R;  /* slots of their own */
    double best = -1.0;
    for (uint64_t code = 0; code < ((uint64_t)1 << n_rows); code++) {
        ln_int j = 0;
        for (ln_int r = 0; r < R; r++) {
            trial[r] = 0;
            if (!p->rows[r]) continue;
            trial[r] = (uint8_t)((code >> (n_rows - 1 - j)) & 1u);  /* the first row varies slowest */
            j++;
        }
        if ((status = FN(rope_basis_solution)(mm, d, p, trial)) != LN_OK) return status;
        FN(rope_lcp_w)(mm, p);
        double worst_l = 0.0, worst_w = 0.0;
        for (ln_int r = 0; r < R; r++) {
            if (!p->rows[r]) continue;
            const ln_int l = mm->rope_link[r];
            if (trial[r]) worst_l = ln_fmax(worst_l, ln_fmax(-p->lam[l], 0.0));
            else worst_w = ln_fmax(worst_w, ln_fmax(-p->w[l], 0.0));
        }
        const double worst = ln_fmax(worst_l / tol_l, worst_w / tol_w);
        if (best < 0.0 || worst < best) {
            best = worst;
            memcpy(best_basis, trial, (size_t)R);
        }
    }
    if (best > 1.0 / mm->lcp_tol) return LN_NO_MODE;
    memcpy(p->basis, best_basis, (size_t)R);
    return FN(rope_basis_solution)(mm, d, p, p->basis);
}

/* Every link's unit vector at X, slack or not, into d->E_full (kept in d->Xc: the state of the problem). */
static void FN(rope_full_vectors)(const ln_model *m, ln_data *d, const double *X)
{
    memcpy(d->Xc, X, (size_t)(m->K * DIM) * sizeof(double));
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        const double r = 1.0 / m->R[l];
        for (int e = 0; e < DIM; e++) d->E_full[l * DIM + e] = (X[b * DIM + e] - X[a * DIM + e]) * r;
    }
}

/* The active set at (X, U) (driven rows set): the acceleration LCP on the ropes candidates, started from start,
   release (or NULL) the ropes whose tension has just fallen to 0 (UnilateralDynamics.select_mode). The ropes in
   the final basis into active (n_ropes). */
static int FN(rope_select_mode)(const ln_model *mm, ln_data *d, const double *X, const double *U, const double *F_base,
                                const uint8_t *candidates, const uint8_t *start, const uint8_t *release,
                                uint8_t *active)
{
    const ln_int L = mm->L;
    double *B = d->link_values, *lam = d->link_values + L, *w = d->link_values + 2 * L;
    FN(rope_full_vectors)(mm, d, X);
    const double *F = FN(rope_forces)(mm, d, X, U, F_base);
    /* B of (26) for every link, with the full unit vectors (accelerations.c's link_terms) */
    for (ln_int l = 0; l < L; l++) {
        const ln_int a = mm->k1[l], b = mm->k2[l];
        const double r = 1.0 / mm->R[l], ia = mm->accel_weight[a], ib = mm->accel_weight[b];
        double du2 = 0.0, proj = 0.0;
        for (int e = 0; e < DIM; e++) {
            const double u = (X[b * DIM + e] - X[a * DIM + e]) * r;
            const double du = U[b * DIM + e] - U[a * DIM + e];
            du2 += du * du;
            proj += u * (F[b * DIM + e] * ib - F[a * DIM + e] * ia);
        }
        B[l] = du2 * r + proj;
    }
    for (ln_int r = 0; r < mm->n_ropes; r++) active[r] = candidates[r] && start[r];
    struct FN(rope_lcp) p = {d->E_full, B, candidates, active, release, lam, w, d->Uh, 0, NULL, NULL};
    if (mm->n_grips) {
        /* the sliding contacts of the candidates' mode (the grips in link_active stuck): their friction -mu N d in
           the problem's matrix, W - D, D's column c being B's response to the load -mu d_c at k_c at zero velocity
           (ModeDynamics.normal_system) */
        struct FN(friction_work) fw = FN(friction_scratch)(mm, d);
        FN(rope_mask_of)(mm, d, candidates);
        if (FN(any_sliding)(mm)) {
            const int status = FN(factored_slip_directions)(mm, d, &fw, X, U, F_base, fw.dirs);
            if (status != LN_OK) return status;
            ln_int *col_row = fw.sliding;
            for (ln_int c = 0; c < mm->n_contacts; c++) {
                const double *dc = fw.dirs + 3 * c;
                if (!FN(contact_sliding)(mm, c) || (dc[0] == 0.0 && dc[1] == 0.0 && dc[2] == 0.0)) continue;
                const ln_int k = mm->contact_mass[c];
                double *col = fw.cols + p.n_cols * L;
                for (ln_int l = 0; l < L; l++) {
                    col[l] = 0.0;
                    const ln_int a = mm->k1[l], b = mm->k2[l];
                    if (a != k && b != k) continue;
                    const double r = 1.0 / mm->R[l], weight = b == k ? mm->accel_weight[b] : -mm->accel_weight[a];
                    double proj = 0.0;
                    for (int e = 0; e < DIM; e++)
                        proj += (X[b * DIM + e] - X[a * DIM + e]) * r * (-mm->friction * dc[e]) * weight;
                    col[l] = -proj;
                }
                col_row[p.n_cols++] = FN(contact_link)(mm, c);
            }
            p.col_row = col_row;
            p.cols = fw.cols;
        }
    }
    return FN(rope_solve_lcp)(mm, d, &p);
}

/* The mode's tensions at (X, U) (driven rows set at their time), slack ropes' exactly 0, into T; acc into acc. */
static int FN(rope_mode_tensions)(const ln_model *mm, ln_data *d, const double *X, const double *U,
                                  const double *F_base, double *acc, double *T)
{
    const int status = FN(stage_accelerations)(mm, d, X, U, F_base, acc, T, 1);
    for (ln_int l = 0; l < mm->L; l++)
        if (mm->inv_R[l] == 0.0) T[l] = 0.0;
    return status;
}

/* ---- the state's mode, for the outputs ------------------------------------------------------------------------ */
/* Ropes at their length (gap within touch_tol of R_l) and, given U, not separating faster than touch_tol of the
   velocity scale (UnilateralDynamics.touching). */
static void FN(rope_touching)(const ln_model *m, const double *X, const double *U, uint8_t *out)
{
    const double scale = U ? FN(rope_velocity_scale)(m, U) : 0.0;
    for (ln_int r = 0; r < m->n_ropes; r++) {
        const ln_int l = m->rope_link[r];
        out[r] = fabs(FN(rope_gap)(m, X, l)) <= m->touch_tol * m->R[l];
        if (U && out[r]) out[r] = FN(rope_rate)(m, X, U, l) <= m->touch_tol * scale;
    }
}

/* ---- Coulomb friction: which contacts stick --------------------------------------------------------------------- */
/* The contacts whose masses do not slip, tangential speed within touch_tol of the velocity scale, into out
   (n_contacts) (UnilateralDynamics.resting). */
static void FN(friction_resting)(const ln_model *m, const double *U, uint8_t *out)
{
    const double scale = FN(rope_velocity_scale)(m, U), *n = m->ground_normal;
    for (ln_int c = 0; c < m->n_contacts; c++) {
        const ln_int k = m->contact_mass[c];
        double normal = 0.0, speed = 0.0;
        for (int e = 0; e < 3; e++) normal += U[k * DIM + e] * n[e];
        for (int e = 0; e < 3; e++) {
            const double v = U[k * DIM + e] - normal * n[e];
            speed += v * v;
        }
        out[c] = ln_sqrt(speed) <= m->touch_tol * scale;
    }
}

/* The grips of the contacts stuck[c] in the mode (their links' link_active). */
static void FN(friction_set_stuck)(const ln_model *m, ln_data *d, const uint8_t *stuck)
{
    for (ln_int c = 0; c < m->n_contacts; c++)
        for (int i = 0; i < 2; i++) d->link_active[FN(grip_link)(m, c, i)] = stuck[c] != 0;
}

/* mu N - |F_t| of each stuck contact of the mode in use from its tensions T (L) (N the contact's tension, F_t = T_g1
   t_1 + T_g2 t_2 its grips' force on the mass), +inf on the others (UnilateralDynamics.stick_margins). */
static void FN(friction_margins)(const ln_model *mm, const double *T, double *margins)
{
    for (ln_int c = 0; c < mm->n_contacts; c++) {
        margins[c] = INFINITY;
        if (!(mm->n_grips && mm->inv_R[FN(grip_link)(mm, c, 0)] != 0.0)) continue;
        double Ft = 0.0;
        for (int e = 0; e < 3; e++) {
            const double f = T[FN(grip_link)(mm, c, 0)] * mm->ground_tangent[e]
                             + T[FN(grip_link)(mm, c, 1)] * mm->ground_tangent[3 + e];
            Ft += f * f;
        }
        margins[c] = mm->friction * T[FN(contact_link)(mm, c)] - ln_sqrt(Ft);
    }
}

/* Which of the candidates (contacts) the ground holds in the mode of the ropes active (n_ropes), into the grips'
   link_active (UnilateralDynamics.choose_stuck): all of them stuck, then the one whose tangential force is furthest
   beyond mu N let slip, until every stuck one is within the friction cone (to force_tol of the largest force). The
   mode's mask is the chosen one on return. */
static int FN(friction_choose_stuck)(const ln_model *mm, ln_data *d, const double *X, const double *U,
                                     const double *F_base, const uint8_t *active, const uint8_t *candidates)
{
    uint8_t *stuck = d->friction_flags + mm->n_contacts;
    double *margins = d->friction_values + 3 * mm->n_contacts;
    const ln_int first_contact = mm->n_ropes - mm->n_contacts;
    for (ln_int c = 0; c < mm->n_contacts; c++) stuck[c] = candidates[c] && active[first_contact + c];
    for (;;) {
        FN(friction_set_stuck)(mm, d, stuck);
        FN(rope_mask_of)(mm, d, active);
        int any = 0;
        for (ln_int c = 0; c < mm->n_contacts; c++) any |= stuck[c];
        if (!any) return LN_OK;
        const int status = FN(rope_mode_tensions)(mm, d, X, U, F_base, d->acc1, d->T);
        if (status != LN_OK) return status;
        FN(friction_margins)(mm, d->T, margins);
        double largest = 0.0;
        for (ln_int l = 0; l < mm->L; l++) largest = ln_fmax(largest, fabs(d->T[l]));
        ln_int worst = 0;
        for (ln_int c = 1; c < mm->n_contacts; c++)
            if (margins[c] < margins[worst]) worst = c;
        if (margins[worst] >= -mm->force_tol * largest) return LN_OK;
        stuck[worst] = 0;
    }
}

/* The sliding contacts' slip directions at (X, U) (driven rows and anchors placed) in the mode in use become the
   step's reference, the others' cleared (UnilateralDynamics.set_slip_reference). */
static int FN(friction_set_reference)(const ln_model *mm, ln_data *d, const double *X, const double *U,
                                      const double *F_base)
{
    struct FN(friction_work) w = FN(friction_scratch)(mm, d);
    if (FN(any_sliding)(mm)) {
        const int status = FN(factored_slip_directions)(mm, d, &w, X, U, F_base, w.dirs);
        if (status != LN_OK) return status;
    } else {
        for (ln_int i = 0; i < 3 * mm->n_contacts; i++) w.dirs[i] = 0.0;
    }
    memcpy(d->slip_reference, w.dirs, (size_t)(3 * mm->n_contacts) * sizeof(double));
    return LN_OK;
}

/* The mode of the state (X, U): the acceleration LCP on the touching ropes, every one of them started taut; with
   friction, the resting contacts' grips in it as equalities, then those the ground can hold (choose_stuck) in the
   grips' link_active (UnilateralDynamics.state_mode). */
static int FN(rope_state_mode)(const ln_model *mm, ln_data *d, const double *X, const double *U, const double *F_base,
                               uint8_t *active)
{
    uint8_t *candidates = d->rope_flags + 5 * mm->n_ropes;
    FN(rope_touching)(mm, X, U, candidates);
    uint8_t *resting = d->friction_flags;
    if (mm->n_grips) {
        FN(friction_resting)(mm, U, resting);
        for (ln_int c = 0; c < mm->n_contacts; c++) resting[c] &= candidates[mm->n_ropes - mm->n_contacts + c];
        FN(friction_set_stuck)(mm, d, resting);
    }
    int status = FN(rope_select_mode)(mm, d, X, U, F_base, candidates, candidates, NULL, active);
    if (status == LN_OK && mm->n_grips) status = FN(friction_choose_stuck)(mm, d, X, U, F_base, active, resting);
    return status;
}

/* The integrator's mode from the state at the first advance (EventHandling._ensure_mode), and its mask in use. */
int FN(ln_rope_start)(const ln_model *mm, ln_data *d, double *X, double *U, const double *F_base, double t)
{
#if DIM == 2
    if (mm->n_contacts) return LN_BAD_ARGUMENT;  /* a ground runs on the 3-D path (the library builds no plane) */
#endif
    if (!d->mode_chosen) {
        int status = FN(rope_drive)(mm, d, t, X, U);
        uint8_t *active = d->rope_flags + 4 * mm->n_ropes;
        if (status == LN_OK) status = FN(rope_state_mode)(mm, d, X, U, F_base, active);
        if (status != LN_OK) return status;
        for (ln_int l = 0; l < mm->L - mm->n_grips; l++) d->link_active[l] = 1;
        for (ln_int r = 0; r < mm->n_ropes; r++) d->link_active[mm->rope_link[r]] = active[r];
        d->mode_chosen = 1;
        if (mm->n_grips) {  /* the first step's slip reference, from a cleared one */
            for (ln_int i = 0; i < 3 * mm->n_contacts; i++) d->slip_reference[i] = 0.0;
            FN(rope_use_mask)(mm, d, d->link_active);
            if ((status = FN(friction_set_reference)(mm, d, X, U, F_base)) != LN_OK) return status;
        }
    }
    d->events_this_step = 0;
    FN(rope_use_mask)(mm, d, d->link_active);
    return LN_OK;
}

/* The forces at RATTLE stage j's midpoint of a fixed step (node: its fraction of the step, at t_mid), X + hs/2 U_mid
   from the stage's start X with its half kick's velocity U_mid (scratch: its driven rows and anchors set here), into
   row j of d->stage_tensions: the node, then the ropes' tensions in the mode (FixedStepEvents._midpoint_tensions);
   the largest |T| of the mode's links over the step's midpoints into d->stage_force_scale (the first starts it). */
static int FN(rope_keep_midpoint)(const ln_model *mm, ln_data *d, ln_int j, double node, double t_mid, const double *X,
                                  double *U_mid, double hs, const double *F_base)
{
    const ln_int R = mm->n_ropes;
    double *Xm = d->Xs, *row = d->stage_tensions + j * (R + 1);
    for (ln_int i = 0; i < mm->K * DIM; i++) Xm[i] = X[i] + 0.5 * hs * U_mid[i];
    int status = FN(rope_drive)(mm, d, t_mid, Xm, U_mid);
    if (status == LN_OK) status = FN(rope_mode_tensions)(mm, d, Xm, U_mid, F_base, d->acc1, d->T);
    if (status != LN_OK) return status;
    row[0] = node;
    for (ln_int r = 0; r < R; r++) row[1 + r] = d->T[mm->rope_link[r]];
    double largest = j == 0 ? 0.0 : d->stage_force_scale;
    for (ln_int l = 0; l < mm->L; l++)
        if (d->link_active[l]) largest = ln_fmax(largest, fabs(d->T[l]));
    d->stage_force_scale = largest;
    return LN_OK;
}

/* ---- the method's own step ------------------------------------------------------------------------------------ */
/* A fixed-step method's step from (X0, U0) at t0 to t1 in the mode, into (Xo, Uo) (FixedStepEvents._plain_step): the
   composition's step (split where its position stage fails), or, for a part of a step shorter than short_step of
   dt, the second-order Taylor step X + h U + h^2 A / 2, U + h A projected onto the mode: RATTLE's velocity takes its
   position stage's correction over h, whose round-off a very short step would magnify, and the Taylor step's own
   error, h^3 times the jerk, is below round-off there. samples (NULL: none kept): the composition's RATTLE stages'
   midpoints kept in d->stage_tensions (rope_keep_midpoint), their count into *samples (0 after a Taylor step or a
   split one). */
static int FN(rope_plain_step)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X0,
                               const double *U0, const double *F_base, double t0, double t1, double *Xo, double *Uo,
                               ln_int *samples)
{
    const ln_int size = mm->K * DIM;
    const double h = t1 - t0;
    int status;
    if (samples) *samples = 0;
    if (h < mm->short_step * meth->dt) {
        double *Xa = d->event_states + 14 * 3 * mm->K, *Ua = Xa + 3 * mm->K, *A = d->acc1;
        memcpy(Xa, X0, (size_t)size * sizeof(double));
        memcpy(Ua, U0, (size_t)size * sizeof(double));
        if ((status = FN(rope_drive)(mm, d, t0, Xa, Ua)) != LN_OK) return status;
        if ((status = FN(rope_mode_tensions)(mm, d, Xa, Ua, F_base, A, d->T)) != LN_OK) return status;
        for (ln_int i = 0; i < size; i++) {
            Xo[i] = X0[i] + h * U0[i] + (0.5 * h * h) * A[i];
            Uo[i] = U0[i] + h * A[i];
        }
        if ((status = FN(rope_drive)(mm, d, t1, Xo, Uo)) != LN_OK) return status;
        if (mm->n_contacts) {  /* onto the mode's (11) and the ground from Xo itself (the anchors placed there) */
            if ((status = FN(ln_contacts_project)(mm, meth, d, Xo, 1e-14)) != LN_OK) return status;
            FN(ln_contacts_place)(mm, Xo, Uo);
        } else {
            FN(ln_unit_vectors)(mm, Xo, d->E0);
            if ((status = FN(ln_factor_tension_matrix)(mm, d, d->E0)) != LN_OK) return status;
            if ((status = project_positions(mm, d, Xo, d->E0, 1e-14, meth->max_projection_iter)) != LN_OK)
                return status;
        }
        return project_velocities(mm, d, Xo, Uo, d->E0);
    }
    double *E0 = d->E0, *E1 = d->E1;
    memcpy(Xo, X0, (size_t)size * sizeof(double));
    memcpy(Uo, U0, (size_t)size * sizeof(double));
    if (mm->n_contacts) FN(ln_contacts_place)(mm, Xo, Uo);  /* A(X) at the start with its anchors placed */
    memcpy(d->X_step, Xo, (size_t)size * sizeof(double));  /* where a split step starts again */
    memcpy(d->U_step, Uo, (size_t)size * sizeof(double));
    FN(ln_unit_vectors)(mm, Xo, E0);
    if ((status = FN(ln_factor_tension_matrix)(mm, d, E0)) != LN_OK) return status;
    status = composition_step(mm, meth, d, Xo, Uo, F_base, h, t0, t1, &E0, &E1, samples != NULL);
    if (samples) *samples = meth->n_gammas;
    if (status == LN_PROJECTION_FAILED || status == LN_IMPLICIT_KICK_FAILED) {
        if (samples) *samples = 0;  /* a split step keeps no samples (FixedStepEvents._plain_step) */
        status = split_step(mm, meth, d, Xo, Uo, F_base, h, t0, t1, &E0, &E1, status);
    }
    return status;
}

/* The method's own step of length h from (X0, U0) at t0, into (Xo, Uo): a fixed-step method's plain step, or an
   embedded Runge-Kutta step without error control followed by the projections onto (11) and (12) of the mode
   (ProjectedRungeKutta.step). Scratch: the step loops' own. */
static int FN(rope_method_step)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X0,
                                const double *U0, const double *F_base, double t0, double h, double *Xo, double *Uo)
{
    if (meth->kind == LN_COMPOSITION) return FN(rope_plain_step)(mm, meth, d, X0, U0, F_base, t0, t0 + h, Xo, Uo, NULL);
    const ln_int size = mm->K * DIM, s = meth->n_stages;
    double *KX = d->KX, *KU = d->KU, *Xs = d->Xs, *Us = d->Us, *acc = d->acc;
    double *Xa = d->event_states + 14 * 3 * mm->K, *Ua = Xa + 3 * mm->K;
    memcpy(Xa, X0, (size_t)size * sizeof(double));
    memcpy(Ua, U0, (size_t)size * sizeof(double));
    int status;
    if ((status = FN(rope_drive)(mm, d, t0, Xa, Ua)) != LN_OK) return status;
    d->n_rhs++;
    if ((status = FN(stage_accelerations)(mm, d, Xa, Ua, F_base, acc, d->T, 1)) != LN_OK) return status;
    store_stage(size, 0, Ua, acc, KX, KU);
    const double t_end = t0 + h;
    for (ln_int i = 1; i <= s; i++) {
        double *Yx = i < s ? Xs : Xo, *Yu = i < s ? Us : Uo;
        combine(size, Xa, Ua, h, meth->AB + i * s, i, KX, KU, Yx, Yu);
        if ((status = FN(rope_drive)(mm, d, i < s ? t0 + meth->C[i] * h : t_end, Yx, Yu)) != LN_OK) return status;
        d->n_rhs++;
        if ((status = FN(stage_accelerations)(mm, d, Yx, Yu, F_base, acc, d->T, 1)) != LN_OK) return status;
        store_stage(size, i, Yu, acc, KX, KU);
    }
    status = mm->n_contacts ? FN(ln_contacts_project)(mm, meth, d, Xo, meth->position_tol)
                            : project_positions(mm, d, Xo, d->E1, meth->position_tol, meth->max_projection_iter);
    if (status != LN_OK) return status;
    if (mm->n_contacts) FN(ln_contacts_place)(mm, Xo, Uo);
    return project_velocities(mm, d, Xo, Uo, d->E1);
}

/* ---- detection and location ------------------------------------------------------------------------------------ */
struct FN(rope_event_ctx) {
    const ln_model *mm;
    const ln_method *meth;
    ln_data *d;
    const double *X0, *U0, *X1, *U1, *A0, *A1, *F_base;
    double t0, h;
    ln_int index;               /* the watched value (watched_value) */
    int status;
    double *Xt, *Ut;            /* a trial state */
    double *X_hi, *U_hi;        /* the state at the bracket's upper end */
    double hi_kept;             /* where X_hi, U_hi were taken (-1: none) */
};

/* With friction, what must stay >= 0 of each contact at the state (X, U) whose mode's tensions are in d->T and
   whose largest |T| is scale, into d->friction_values (n_contacts), how far below 0 it may go before it is an event
   after them (n_contacts): a stuck contact's margin mu N - |F_t| (force_tol of scale), a sliding one's velocity
   along the step's slip reference (touch_tol of the velocity scale); +inf on a contact off the ground (the
   friction rows of EventHandling._forces_at). */
static void FN(friction_watch)(const ln_model *mm, ln_data *d, const double *U, double scale)
{
    const ln_int n_c = mm->n_contacts;
    double *values = d->friction_values, *tols = d->friction_values + n_c;
    FN(friction_margins)(mm, d->T, values);
    const double vtol = mm->touch_tol * FN(rope_velocity_scale)(mm, U), *n = mm->ground_normal;
    for (ln_int c = 0; c < n_c; c++) {
        tols[c] = mm->force_tol * scale;
        if (values[c] != INFINITY || mm->inv_R[FN(contact_link)(mm, c)] == 0.0) continue;
        const ln_int k = mm->contact_mass[c];
        double normal = 0.0, along = 0.0;
        for (int e = 0; e < 3; e++) normal += U[k * DIM + e] * n[e];
        for (int e = 0; e < 3; e++) along += (U[k * DIM + e] - normal * n[e]) * d->slip_reference[3 * c + e];
        values[c] = along;
        tols[c] = vtol;
    }
}

/* The watched value index at the last evaluation: rope index's tension (index < n_ropes), else contact
   index - n_ropes's friction value (friction_watch). */
static inline double FN(watched_value)(const ln_model *mm, const ln_data *d, ln_int index)
{
    return index < mm->n_ropes ? d->T[mm->rope_link[index]] : d->friction_values[index - mm->n_ropes];
}

/* The largest |T| of the mode's links, and the ropes' tensions (and the contacts' friction values), at (X, U) and t
   (EventHandling._forces_at). */
static int FN(rope_forces_at)(const ln_model *mm, ln_data *d, double t, const double *X, const double *U,
                              const double *F_base, double *scale)
{
    double *Xt = d->event_states + 12 * 3 * mm->K, *Ut = Xt + 3 * mm->K;
    memcpy(Xt, X, (size_t)(mm->K * DIM) * sizeof(double));
    memcpy(Ut, U, (size_t)(mm->K * DIM) * sizeof(double));
    int status = FN(rope_drive)(mm, d, t, Xt, Ut);
    if (status == LN_OK) status = FN(rope_mode_tensions)(mm, d, Xt, Ut, F_base, d->acc1, d->T);
    double largest = 0.0;
    for (ln_int l = 0; l < mm->L; l++) largest = ln_fmax(largest, fabs(d->T[l]));
    *scale = largest;
    if (mm->n_grips) FN(friction_watch)(mm, d, Ut, largest);
    return status;
}

/* Rope `link`'s tension in the mode along the step's Hermite interpolant at theta (X from X, U; U from U, A). */
static double FN(rope_force_on_interpolant)(void *vctx, double theta)
{
    struct FN(rope_event_ctx) *c = vctx;
    const ln_model *mm = c->mm;
    ln_data *d = c->d;
    const double t2 = theta * theta, t3 = t2 * theta, h = c->h;
    const double h00 = 2 * t3 - 3 * t2 + 1, h10 = t3 - 2 * t2 + theta, h01 = 3 * t2 - 2 * t3, h11 = t3 - t2;
    for (ln_int i = 0; i < mm->K * DIM; i++) {
        c->Xt[i] = h00 * c->X0[i] + h10 * h * c->U0[i] + h01 * c->X1[i] + h11 * h * c->U1[i];
        c->Ut[i] = h00 * c->U0[i] + h10 * h * c->A0[i] + h01 * c->U1[i] + h11 * h * c->A1[i];
    }
    int status = FN(rope_drive)(mm, d, c->t0 + theta * h, c->Xt, c->Ut);
    if (status == LN_OK) status = FN(rope_mode_tensions)(mm, d, c->Xt, c->Ut, c->F_base, d->acc1, d->T);
    if (status != LN_OK) {
        c->status = status;
        return NAN;
    }
    if (mm->n_grips && c->index >= mm->n_ropes) {
        double largest = 0.0;
        for (ln_int l = 0; l < mm->L; l++) largest = ln_fmax(largest, fabs(d->T[l]));
        FN(friction_watch)(mm, d, c->Ut, largest);
    }
    return FN(watched_value)(mm, d, c->index);
}

/* Rope `link`'s tension in the mode at the end of the method's own step of length h. */
static double FN(rope_force_on_step)(void *vctx, double h)
{
    struct FN(rope_event_ctx) *c = vctx;
    const ln_model *mm = c->mm;
    ln_data *d = c->d;
    double scale;
    int status = FN(rope_method_step)(mm, c->meth, d, c->X0, c->U0, c->F_base, c->t0, h, c->Xt, c->Ut);
    if (status == LN_OK) status = FN(rope_forces_at)(mm, d, c->t0 + h, c->Xt, c->Ut, c->F_base, &scale);
    if (status != LN_OK) {
        c->status = status;
        return NAN;
    }
    const double f = FN(watched_value)(mm, d, c->index);
    if (!(f >= 0)) {  /* the bracket's new upper end: its state kept */
        memcpy(c->X_hi, c->Xt, (size_t)(mm->K * DIM) * sizeof(double));
        memcpy(c->U_hi, c->Ut, (size_t)(mm->K * DIM) * sizeof(double));
        c->hi_kept = h;
    }
    return f;
}

/* The first event within the accepted step from (X0, U0) at t0 to (X1, U1) at t0 + h, in the mode it was taken in
   (EventHandling._first_event): *found 0 (none), 1 (a gap: a slack rope reached its length) or 2 (a force: a taut
   rope's tension fell through 0), the rope in *rope, theta in *theta. */
static int FN(rope_first_event)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X0,
                                const double *U0, double t0, const double *X1, const double *U1, double h,
                                const double *F_base, int *found, ln_int *rope, double *theta)
{
    const ln_int R = mm->n_ropes, K3 = 3 * mm->K;
    *found = 0;
    int status, any_slack = 0, any_taut = 0;
    for (ln_int r = 0; r < R; r++) {
        if (d->link_active[mm->rope_link[r]]) any_taut = 1;
        else any_slack = 1;
    }
    double *Xm = d->event_states + 10 * K3, *Um = Xm + K3;
    if (any_slack) {
        /* each slack rope's dips below -tol along the interpolant (3 at most per rope), confirmed in the order of
           (crossing, lowest, rope) */
        double *cross_all = d->rope_values, *low_all = d->rope_values + 3 * R, *rope_all = d->rope_values + 6 * R;
        uint8_t *tried = d->rope_flags + 8 * R;
        const double largest = FN(rope_largest_coordinate)(mm, X1);
        double best_cross = 0.0;
        ln_int best_rope = -1, n_dips = 0;
        for (ln_int r = 0; r < R; r++) {
            const ln_int l = mm->rope_link[r];
            if (d->link_active[l]) continue;
            const double Rl = mm->R[l], tol = mm->cross_tol * ln_fmax(Rl, largest);
            double depth = tol * (2.0 * Rl + tol);
            /* R^2 - |d(theta)|^2 along the Hermite of X: D_i the coefficients of d = X_k2 - X_k1; a contact's gap
               n . (X_k(theta) - p) itself, cubic (UnilateralDynamics.gap_polynomials) */
            double D[4][DIM], P[7] = {0};
            const ln_int a = mm->k1[l], b = mm->k2[l];
            const int contact = FN(is_contact)(mm, l);
            if (contact) {
                depth = tol;
                for (int e = 0; e < DIM; e++) {
                    const double y0 = X0[a * DIM + e], y1 = X1[a * DIM + e], d0 = U0[a * DIM + e], d1 = U1[a * DIM + e];
                    const double c[4] = {y0, h * d0, 3 * (y1 - y0) - h * (2 * d0 + d1), 2 * (y0 - y1) + h * (d0 + d1)};
                    for (int i = 0; i < 4; i++) P[i] += c[i] * mm->ground_normal[e];
                }
                double pn = 0.0;
                for (int e = 0; e < DIM; e++) pn += mm->ground_point[e] * mm->ground_normal[e];
                P[0] -= pn;
            }
            for (int e = 0; e < DIM && !contact; e++) {
                double c[2][4];
                for (int end = 0; end < 2; end++) {
                    const ln_int k = end ? b : a;
                    const double y0 = X0[k * DIM + e], y1 = X1[k * DIM + e], d0 = U0[k * DIM + e], d1 = U1[k * DIM + e];
                    c[end][0] = y0;
                    c[end][1] = h * d0;
                    c[end][2] = 3 * (y1 - y0) - h * (2 * d0 + d1);
                    c[end][3] = 2 * (y0 - y1) + h * (d0 + d1);
                }
                for (int i = 0; i < 4; i++) D[i][e] = c[1][i] - c[0][i];
            }
            for (int i = 0; i < 4 && !contact; i++)
                for (int j = 0; j < 4; j++) {
                    double s = 0.0;
                    for (int e = 0; e < DIM; e++) s += D[i][e] * D[j][e];
                    P[i + j] -= s;
                }
            if (!contact) P[0] += Rl * Rl;
            if (!rope_may_fall_below(P, depth)) continue;
            double cross[3], low[3];
            const int n = rope_gap_dips(P, depth, cross, low);
            for (int i = 0; i < n; i++) {
                cross_all[n_dips] = cross[i];
                low_all[n_dips] = low[i];
                rope_all[n_dips] = (double)r;
                tried[n_dips] = 0;
                n_dips++;
            }
        }
        for (ln_int k = 0; k < n_dips; k++) {
            ln_int next = -1;
            for (ln_int i = 0; i < n_dips; i++) {
                if (tried[i]) continue;
                if (next < 0 || cross_all[i] < cross_all[next]
                    || (cross_all[i] == cross_all[next]
                        && (low_all[i] < low_all[next] || (low_all[i] == low_all[next] && rope_all[i] < rope_all[next]))))
                    next = i;
            }
            tried[next] = 1;
            const ln_int r = (ln_int)rope_all[next], l = mm->rope_link[r];
            const double lowest = low_all[next];
            const double *Xc = X1;
            if (lowest == 0.0) {
                Xc = X0;
            } else if (lowest != 1.0) {
                if ((status = FN(rope_method_step)(mm, meth, d, X0, U0, F_base, t0, lowest * h, Xm, Um)) != LN_OK)
                    return status;
                Xc = Xm;
            }
            const double tol = mm->cross_tol * ln_fmax(mm->R[l], largest);
            if (FN(rope_gap)(mm, Xc, l) < -tol) {
                best_cross = cross_all[next];
                best_rope = r;
                break;
            }
        }
        if (best_rope >= 0) {
            *found = 1;
            *rope = best_rope;
            *theta = best_cross;
        }
    }
    if (any_taut) {
        double scale;
        if ((status = FN(rope_forces_at)(mm, d, t0 + h, X1, U1, F_base, &scale)) != LN_OK) return status;
        double *forces = d->link_values + 3 * mm->L;
        memcpy(forces, d->T, (size_t)mm->L * sizeof(double));
        const ln_int n_watched = R + (mm->n_grips ? mm->n_contacts : 0);
        double *friction = d->friction_values + 2 * mm->n_contacts;  /* the contacts' values and tolerances, kept */
        if (mm->n_grips) memcpy(friction, d->friction_values, (size_t)mm->n_contacts * sizeof(double));
        const double tol = mm->force_tol * scale;
        int dropped = 0;
        for (ln_int r = 0; r < R; r++) {
            const ln_int l = mm->rope_link[r];
            if (d->link_active[l] && forces[l] < -tol) dropped = 1;
        }
        for (ln_int c = 0; c < n_watched - R; c++)
            if (friction[c] < -d->friction_values[mm->n_contacts + c]) dropped = 1;
        double *friction_tol = d->friction_values + 4 * mm->n_contacts;
        if (mm->n_grips)
            memcpy(friction_tol, d->friction_values + mm->n_contacts, (size_t)mm->n_contacts * sizeof(double));
        if (dropped) {
            double *A0 = d->event_states + 8 * K3, *A1 = A0 + K3;
            double *Xa = d->event_states + 12 * K3, *Ua = Xa + K3;
            /* the accelerations at the step's ends, in the mode */
            const double *ends[2][2] = {{X0, U0}, {X1, U1}};
            for (int end = 0; end < 2; end++) {
                memcpy(Xa, ends[end][0], (size_t)(mm->K * DIM) * sizeof(double));
                memcpy(Ua, ends[end][1], (size_t)(mm->K * DIM) * sizeof(double));
                if ((status = FN(rope_drive)(mm, d, end ? t0 + h : t0, Xa, Ua)) != LN_OK) return status;
                if ((status = FN(rope_mode_tensions)(mm, d, Xa, Ua, F_base, end ? A1 : A0, d->T)) != LN_OK)
                    return status;
            }
            for (ln_int r = 0; r < n_watched; r++) {
                double f1;
                if (r < R) {
                    const ln_int l = mm->rope_link[r];
                    if (!(d->link_active[l] && forces[l] < -tol)) continue;
                    f1 = forces[l];
                } else {
                    if (!(friction[r - R] < -friction_tol[r - R])) continue;
                    f1 = friction[r - R];
                }
                struct FN(rope_event_ctx) c = {mm, meth, d, X0, U0, X1, U1, A0, A1, F_base, t0, h, r, LN_OK,
                                               Xm, Um, NULL, NULL, -1.0};
                const double f0 = FN(rope_force_on_interpolant)(&c, 0.0);
                double root = 0.0;
                if (!(f0 < 0)) {
                    double lo = 0.0, hi = 1.0;
                    rope_bracketed_root(FN(rope_force_on_interpolant), &c, &lo, &hi, f0, f1, 1e-6, 0, 0.0);
                    root = hi;  /* the order of the events only: the time is found on the method's steps */
                }
                if (c.status != LN_OK) return c.status;
                if (*found == 0 || root < *theta) {
                    *found = 2;
                    *rope = r;
                    *theta = root;
                }
            }
        }
    }
    return LN_OK;
}

/* The state at the event on the method's own trajectory, into (Xe, Ue), and the step h_e from t0 to it
   (EventHandling._to_gap_root, _to_force_root). */
static int FN(rope_locate)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X0, const double *U0,
                           double t0, double h_max, const double *X1, const double *U1, const double *F_base,
                           int kind, ln_int rope, double theta, double *Xe, double *Ue, double *h_e)
{
    const ln_int size = mm->K * DIM, l = rope < mm->n_ropes ? mm->rope_link[rope] : -1;
    const size_t bytes = (size_t)size * sizeof(double);
    int status;
    if (kind == 1) {
        /* Newton's method on the step's length until the gap at its end is zero to round-off */
        double h = theta * h_max;
        if (h > 0) {
            if ((status = FN(rope_method_step)(mm, meth, d, X0, U0, F_base, t0, h, Xe, Ue)) != LN_OK) return status;
        } else {
            memcpy(Xe, X0, bytes);
            memcpy(Ue, U0, bytes);
        }
        for (ln_int it = 0; it < mm->gap_newton_iterations; it++) {
            const double g = FN(rope_gap)(mm, Xe, l), rate = FN(rope_rate)(mm, Xe, Ue, l);
            if (fabs(g) <= 4 * ROPE_EPS * ln_fmax(mm->R[l], FN(rope_largest_coordinate)(mm, Xe)) || !(rate < 0)) break;
            const double h_new = ln_fmin(ln_fmax(h - g / rate, 0.0), h_max);
            if (h_new == h) break;
            h = h_new;
            if (h > 0) {
                if ((status = FN(rope_method_step)(mm, meth, d, X0, U0, F_base, t0, h, Xe, Ue)) != LN_OK) return status;
            } else {
                memcpy(Xe, X0, bytes);
                memcpy(Ue, U0, bytes);
            }
        }
        *h_e = h;
        return LN_OK;
    }
    /* the bracketing root find on the step's length, ending just past the zero of the force */
    double scale;
    if ((status = FN(rope_forces_at)(mm, d, t0, X0, U0, F_base, &scale)) != LN_OK) return status;
    const double f0 = FN(watched_value)(mm, d, rope);
    if ((status = FN(rope_forces_at)(mm, d, t0 + h_max, X1, U1, F_base, &scale)) != LN_OK) return status;
    const double f1 = FN(watched_value)(mm, d, rope);
    if (!(f0 >= 0)) {
        memcpy(Xe, X0, bytes);
        memcpy(Ue, U0, bytes);
        *h_e = 0.0;
        return LN_OK;
    }
    double *Xt = d->event_states + 10 * 3 * mm->K, *Ut = Xt + 3 * mm->K;
    struct FN(rope_event_ctx) c = {mm, meth, d, X0, U0, X1, U1, NULL, NULL, F_base, t0, h_max, rope, LN_OK,
                                   Xt, Ut, Xe, Ue, -1.0};
    memcpy(Xe, X1, bytes);
    memcpy(Ue, U1, bytes);
    c.hi_kept = h_max;
    double lo = 0.0, hi = h_max;
    rope_bracketed_root(FN(rope_force_on_step), &c, &lo, &hi, f0, f1, 1e-13, 1, theta * h_max);
    if (c.status != LN_OK) return c.status;
    if (c.hi_kept != hi) {  /* hi is always a point where the force was < 0: its state was kept; else take it again */
        if ((status = FN(rope_method_step)(mm, meth, d, X0, U0, F_base, t0, hi, Xe, Ue)) != LN_OK) return status;
    }
    *h_e = hi;
    return LN_OK;
}

/* ---- the event ------------------------------------------------------------------------------------------------- */
/* Projections of the mode of mask flags (positions along M^-1 C(X)^T from X itself: the closest point in the mass
   metric, as ln_project_state; or the velocities only). */
static int FN(rope_project)(const ln_model *mm, const ln_method *meth, ln_data *d, const uint8_t *flags, double *X,
                            double *U)
{
    FN(rope_mask_of)(mm, d, flags);
    int status;
    if (X && (status = FN(ln_contacts_project)(mm, meth, d, X, 1e-14)) != LN_OK) return status;
    if (U) {
        if (mm->n_contacts) FN(ln_contacts_place)(mm, X ? X : d->Xc, U);
        return project_velocities(mm, d, X ? X : d->Xc, U, d->E0);
    }
    return LN_OK;
}

/* An event into the data's log (what does not fit is counted), a jerk's impulse into its rope's sum. */
static void FN(rope_record)(ln_data *d, double t, int kind, ln_int link, double impulse, const ln_model *mm)
{
    if (kind == LN_EVENT_TAUT) d->rope_impulse[link] += impulse;
    if (FN(is_contact)(mm, link)) {  /* a contact's events name its mass */
        if (kind == LN_EVENT_TAUT || kind == LN_EVENT_SLACK)
            kind = kind == LN_EVENT_TAUT ? LN_EVENT_CONTACT : LN_EVENT_RELEASE;
        link = mm->k1[link];
    }
    if (d->n_events >= LN_EVENT_LOG) {
        d->events_lost++;
        return;
    }
    d->event_t[d->n_events] = t;
    d->event_kind[d->n_events] = kind;
    d->event_link[d->n_events] = link;
    d->event_impulse[d->n_events] = impulse;
    d->n_events++;
}

/* Moreau's impact law on the mode's rows at (X, U): the rods, the ropes touching and the grips in the mode
   (link_active), W Lambda + q >= 0 on the ropes, = 0 on the others, q = C U + e min(C U, 0) (Newton's restitution,
   0 below the rest speed) (UnilateralDynamics._impact_problem): Lambda into d->link_values + 2 L, the rows' rates C U
   into d->link_values, each row's restitution into d->link_values + 5 L, the final basis into d->rope_flags + 3 R. */
static int FN(rope_impact_lcp)(const ln_model *mm, ln_data *d, const double *X, const double *U,
                               const uint8_t *touching)
{
    const ln_int L = mm->L, R = mm->n_ropes;
    double *rates = d->link_values, *q = d->link_values + L, *lam = d->link_values + 2 * L;
    double *w = d->link_values + 4 * L, *e = d->link_values + 5 * L;
    uint8_t *basis = d->rope_flags + 3 * R;
    FN(rope_full_vectors)(mm, d, X);
    const double rest = FN(rope_rest_speed)(mm, U);
    /* C U of the impact's rows (the rods and the touching ropes), and each row's restitution */
    for (ln_int l = 0; l < L; l++) {
        const ln_int a = mm->k1[l], b = mm->k2[l];
        double s = 0.0;
        for (int k = 0; k < DIM; k++) s += d->E_full[l * DIM + k] * (U[a * DIM + k] - U[b * DIM + k]);
        rates[l] = s;
        e[l] = 0.0;
    }
    for (ln_int r = 0; r < R; r++) {
        const ln_int l = mm->rope_link[r];
        if (!touching[r]) continue;
        e[l] = mm->rope_restitution[r];
        if (e[l] * ln_fmax(-rates[l], 0.0) < rest) e[l] = 0.0;  /* the rest rule */
    }
    for (ln_int l = 0; l < L; l++) q[l] = -(rates[l] + e[l] * ln_fmin(rates[l], 0.0));  /* b = -q */
    for (ln_int r = 0; r < R; r++) basis[r] = touching[r] && rates[mm->rope_link[r]] < 0;
    struct FN(rope_lcp) p = {d->E_full, q, touching, basis, NULL, lam, w, d->Uh, 0, NULL, NULL};
    return FN(rope_solve_lcp)(mm, d, &p);
}

/* Whether each rope's impulse in an impact at (X, U) (velocities before it, unit vectors in d->E_full) is one: an
   impulse that changes its rope's own rate by less than impulse_roundoff of the velocity scale is the LCP's
   round-off (UnilateralDynamics.took_impulse): Lambda_l W_ll, W_ll = |E_l|^2 (1/M_k1 + 1/M_k2). */
static void FN(rope_took)(const ln_model *mm, ln_data *d, const double *U, const double *impulses, uint8_t *took)
{
    const double scale = FN(rope_velocity_scale)(mm, U);
    for (ln_int r = 0; r < mm->n_ropes; r++) {
        const ln_int l = mm->rope_link[r];
        double sq = 0.0;
        for (int k = 0; k < DIM; k++) sq += d->E_full[l * DIM + k] * d->E_full[l * DIM + k];
        took[r] = impulses[r] * (sq * (mm->inv_m[mm->k1[l]] + mm->inv_m[mm->k2[l]])) > mm->impulse_roundoff * scale;
    }
}

/* The impulse at (X, U) where the ropes touching are at their length (UnilateralDynamics.impact): U becomes the
   velocities after it, impulses (n_ropes) each rope's impulse, took whether it took one. */
static int FN(rope_impact)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X, double *U,
                           const uint8_t *touching, double *impulses, uint8_t *took)
{
    const ln_int L = mm->L, R = mm->n_ropes, size = mm->K * DIM;
    double *rates = d->link_values, *lam = d->link_values + 2 * L, *e = d->link_values + 5 * L;
    uint8_t *basis = d->rope_flags + 3 * R;
    int status = FN(rope_impact_lcp)(mm, d, X, U, touching);
    if (status != LN_OK) return status;
    const double scale = FN(rope_velocity_scale)(mm, U);
    int separating = 0;
    for (ln_int l = 0; l < L; l++)
        if (d->mask[l] && rates[l] > mm->touch_tol * scale) separating = 1;
    for (ln_int r = 0; r < R; r++) impulses[r] = touching[r] ? lam[mm->rope_link[r]] : 0.0;
    FN(rope_took)(mm, d, U, impulses, took);
    /* distinct restitutions among the approaching basis ropes */
    double first = 0.0;
    int distinct = 0;
    for (ln_int r = 0; r < R; r++) {
        const ln_int l = mm->rope_link[r];
        if (!(basis[r] && rates[l] < 0)) continue;
        if (distinct == 0) {
            first = e[l];
            distinct = 1;
        } else if (e[l] != first) {
            distinct = 2;
        }
    }
    if (distinct <= 1 && !separating) {
        double *U_before = d->event_states + 6 * 3 * mm->K;
        memcpy(U_before, U, (size_t)size * sizeof(double));
        memcpy(d->Xc, X, (size_t)size * sizeof(double));
        if ((status = FN(rope_project)(mm, meth, d, basis, NULL, U)) != LN_OK) return status;
        if (first != 0.0)
            for (ln_int i = 0; i < size; i++) U[i] = U_before[i] + (1.0 + first) * (U[i] - U_before[i]);
    } else {
        FN(ln_add_correction)(mm, d->E_full, lam, 1.0, U);  /* U + M^-1 C^T Lambda */
    }
    return LN_OK;
}

/* The rows' rates of the velocity M^-1 f, f a load `size` along v (3) at mass k alone, into shift (L): C M^-1 f,
   nonzero on the links at k (the impact's rate shift of a friction impulse). */
static void FN(friction_rate_shift)(const ln_model *mm, const ln_data *d, ln_int k, const double *v, double size,
                                    double *shift)
{
    for (ln_int l = 0; l < mm->L; l++) {
        shift[l] = 0.0;
        const ln_int a = mm->k1[l], b = mm->k2[l];
        if (a != k && b != k) continue;
        double s = 0.0;
        for (int e = 0; e < DIM; e++) s += d->E_full[l * DIM + e] * v[e];
        shift[l] = (a == k ? 1.0 : -1.0) * mm->inv_m[k] * size * s;
    }
}

/* The impact's response to a friction load (UnilateralDynamics._coulomb_impulses' response): in the impact's basis
   (its rows as equalities) the impulses for the rates shifted by the load, the sliding contacts' tangential
   velocities after the impact on t_1, t_2 and their normal impulses. */
struct FN(impact_ctx) {
    const ln_model *mm;
    ln_data *d;
    struct FN(friction_work) *w;
    const double *U;        /* the velocities before the impact */
    const uint8_t *touching, *basis;
    const ln_int *sliding;
    ln_int m;
};

static int FN(impact_response)(void *vctx, ln_int j, int i, double size, double *a, double *N)
{
    const struct FN(impact_ctx) *c = vctx;
    const ln_model *mm = c->mm;
    ln_data *d = c->d;
    struct FN(friction_work) *w = c->w;
    const ln_int L = mm->L, K3 = mm->K * DIM;
    const double *b = d->link_values + L;  /* -q */
    double *shifted = w->T0, *lam = w->Tf, *U_plus = w->Fa;
    ln_int k = -1;
    if (j >= 0) {
        k = mm->contact_mass[c->sliding[j]];
        FN(friction_rate_shift)(mm, d, k, mm->ground_tangent + 3 * i, size, shifted);
        for (ln_int l = 0; l < L; l++) shifted[l] = b[l] - shifted[l];
    } else {
        memcpy(shifted, b, (size_t)L * sizeof(double));
    }
    struct FN(rope_lcp) p = {d->E_full, shifted, c->touching, NULL, NULL, lam, NULL, NULL, 0, NULL, NULL};
    const int status = FN(rope_basis_solution)(mm, d, &p, c->basis);
    if (status != LN_OK) return status;
    memcpy(U_plus, c->U, (size_t)K3 * sizeof(double));
    FN(ln_add_correction)(mm, d->E_full, lam, 1.0, U_plus);
    if (k >= 0)
        for (int e = 0; e < DIM; e++) U_plus[k * DIM + e] += mm->inv_m[k] * size * mm->ground_tangent[3 * i + e];
    for (ln_int q = 0; q < c->m; q++) {
        const ln_int cc = c->sliding[q], kk = mm->contact_mass[cc];
        double normal = 0.0;
        for (int e = 0; e < 3; e++) normal += U_plus[kk * DIM + e] * mm->ground_normal[e];
        for (int t = 0; t < 2; t++) {
            double s = 0.0;
            for (int e = 0; e < 3; e++)
                s += (U_plus[kk * DIM + e] - normal * mm->ground_normal[e]) * mm->ground_tangent[3 * t + e];
            a[2 * q + t] = s;
        }
        N[q] = lam[FN(contact_link)(mm, cc)];
    }
    return LN_OK;
}

/* The impulses of the impact at (X, U) (velocities before it) with the grips of the contacts stuck in the mode
   (link_active) and the other touching contacts sliding (UnilateralDynamics._coulomb_impulses): Lambda into
   d->link_values + 2 L, each sliding contact's slip direction into w.dirs (zero on the others). The directions are
   found with the sliding contacts' friction as loads in the impact's basis (Coulomb's law one level down,
   coulomb_directions), then the impact solved with -mu P_n d carried into the columns of W (the rate shift of the
   friction impulse); where that changes the basis, the directions are found again in the new one. */
static int FN(friction_coulomb_impulses)(const ln_model *mm, ln_data *d, const double *X, const double *U,
                                         const uint8_t *touching)
{
    const ln_int L = mm->L, R = mm->n_ropes, n_c = mm->n_contacts, first_contact = R - n_c;
    struct FN(friction_work) w = FN(friction_scratch)(mm, d);
    int status = FN(rope_impact_lcp)(mm, d, X, U, touching);
    if (status != LN_OK) return status;
    for (ln_int i = 0; i < 3 * n_c; i++) w.dirs[i] = 0.0;
    ln_int m = 0;
    for (ln_int c = 0; c < n_c; c++)
        if (touching[first_contact + c] && !d->link_active[FN(grip_link)(mm, c, 0)]) w.impact_sliding[m++] = c;
    if (!m) return LN_OK;
    uint8_t *basis = d->rope_flags + 3 * R, *kept = d->rope_flags + 9 * R;
    for (ln_int round = 0; round < R + 1; round++) {
        memcpy(kept, basis, (size_t)R);
        struct FN(impact_ctx) ctx = {mm, d, &w, U, touching, kept, w.impact_sliding, m};
        if ((status = FN(coulomb_directions)(mm, &w, FN(impact_response), &ctx, m)) != LN_OK) return status;
        FN(friction_directions_3d)(mm, w.d2, w.impact_sliding, m, w.dirs);
        for (ln_int q = 0; q < m; q++) {
            const ln_int c = w.impact_sliding[q];
            FN(friction_rate_shift)(mm, d, mm->contact_mass[c], w.dirs + 3 * c, -mm->friction, w.cols + q * L);
            w.sliding[q] = FN(contact_link)(mm, c);
        }
        struct FN(rope_lcp) p = {d->E_full, d->link_values + L, touching, basis, NULL, d->link_values + 2 * L,
                                 d->link_values + 4 * L, d->Uh, m, w.sliding, w.cols};
        if ((status = FN(rope_solve_lcp)(mm, d, &p)) != LN_OK) return status;
        if (!memcmp(kept, basis, (size_t)R)) break;
    }
    return LN_OK;
}

/* The impact at (X, U) with Coulomb's friction on the ground (UnilateralDynamics.coulomb_impact): the frictionless
   impact (the grips out); where a contact took an impulse, every touching contact that took one or rests starts
   stuck (its grips equalities of the impact's LCP, their multipliers its tangential impulse P_t), the one furthest
   outside |P_t| <= mu P_n let slide, in turn; a sliding contact's friction impulse is -mu P_n d
   (friction_coulomb_impulses). U becomes the velocities after it, impulses and took as rope_impact's, into
   tangential (n_contacts) each contact's |P_t| and, with driven anchors, into d->event_ground_impulse (K, 3) the
   vectors P_t on the contacts' masses. The grips' link_active is the stuck set the impact ended with. */
static int FN(friction_impact)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X, double *U,
                               const uint8_t *touching, double *impulses, uint8_t *took, double *tangential)
{
    const ln_int L = mm->L, R = mm->n_ropes, n_c = mm->n_contacts, first_contact = R - n_c, size = mm->K * DIM;
    uint8_t *stuck = d->friction_flags + 5 * n_c, *resting = d->friction_flags;
    double *U_before = d->event_states + 7 * 3 * mm->K, *margins = d->friction_values + 3 * n_c;
    const double *lam = d->link_values + 2 * L, mu = mm->friction;
    double *ground = mm->n_driven ? d->event_ground_impulse : NULL;
    memcpy(U_before, U, (size_t)size * sizeof(double));
    for (ln_int c = 0; c < n_c; c++) {
        stuck[c] = 0;
        tangential[c] = 0.0;
    }
    for (ln_int i = 0; ground && i < size; i++) ground[i] = 0.0;
    FN(friction_set_stuck)(mm, d, stuck);
    int status = FN(rope_impact)(mm, meth, d, X, U, touching, impulses, took);
    if (status != LN_OK) return status;
    int any = 0;
    for (ln_int c = 0; c < n_c; c++) any |= took[first_contact + c];
    if (!any) return LN_OK;
    FN(friction_resting)(mm, U_before, resting);
    for (ln_int c = 0; c < n_c; c++) stuck[c] = touching[first_contact + c] && (took[first_contact + c] || resting[c]);
    for (;;) {
        FN(friction_set_stuck)(mm, d, stuck);
        if ((status = FN(friction_coulomb_impulses)(mm, d, X, U_before, touching)) != LN_OK) return status;
        double largest = 0.0;
        for (ln_int l = 0; l < L; l++)
            if (d->mask[l]) largest = ln_fmax(largest, fabs(lam[l]));
        ln_int worst = -1;
        for (ln_int c = 0; c < n_c; c++) {
            margins[c] = INFINITY;
            if (!stuck[c]) continue;
            double Pt = 0.0;
            for (int e = 0; e < 3; e++) {
                const double f = lam[FN(grip_link)(mm, c, 0)] * mm->ground_tangent[e]
                                 + lam[FN(grip_link)(mm, c, 1)] * mm->ground_tangent[3 + e];
                Pt += f * f;
                if (ground) ground[mm->contact_mass[c] * DIM + e] = f;
            }
            tangential[c] = ln_sqrt(Pt);
            margins[c] = mu * lam[FN(contact_link)(mm, c)] - tangential[c];
            if (worst < 0 || margins[c] < margins[worst]) worst = c;
        }
        if (worst < 0 || margins[worst] >= -mm->force_tol * largest) break;
        stuck[worst] = 0;
    }
    /* U- + M^-1 C^T Lambda + M^-1 of each sliding contact's friction impulse -mu P_n d */
    const double *dirs = FN(friction_scratch)(mm, d).dirs;
    memcpy(U, U_before, (size_t)size * sizeof(double));
    FN(ln_add_correction)(mm, d->E_full, lam, 1.0, U);
    for (ln_int c = 0; c < n_c; c++) {
        const ln_int l = FN(contact_link)(mm, c), k = mm->contact_mass[c];
        if (!touching[first_contact + c] || stuck[c]) continue;
        tangential[c] = mu * lam[l];
        for (int e = 0; e < 3; e++) {
            U[k * DIM + e] += mm->inv_m[k] * (-mu * lam[l] * dirs[3 * c + e]);
            if (ground) ground[k * DIM + e] = -mu * lam[l] * dirs[3 * c + e];
        }
    }
    for (ln_int r = 0; r < R; r++) impulses[r] = touching[r] ? lam[mm->rope_link[r]] : 0.0;
    FN(rope_took)(mm, d, U_before, impulses, took);
    return LN_OK;
}

/* What the links gave the driven anchors in an impulse that took the free masses from U_before to U_after at X
   (the anchors' rows at their motion), added into d->impulse: with M dU = C^T Lambda + P, P the ground's impulses
   along its plane (ground (K, 3) or NULL: a friction or grip impulse the impact solved, not the links'), the
   minimum-norm impulses Lambda = A^+ C M^-1 (M dU - P) of the links at their length (the rods, the ropes and
   contacts touching, and with grips the grips of the contacts stuck in link_active; any other Lambda gives the
   same forces, (31)), and C^T Lambda on the anchors' rows, +Lambda_l E_l on k1(l) and -Lambda_l E_l on k2(l)
   (UnilateralDynamics.anchor_impulses). The mask of the links at their length is left in use. */
static int FN(rope_anchor_impulses)(const ln_model *mm, ln_data *d, const double *X, const double *U_before,
                                    const double *U_after, const double *ground, int grips)
{
    const ln_int K = mm->K, L = mm->L;
    uint8_t *at_length = d->rope_flags + 2 * mm->n_ropes;
    double *dU = d->Uh, *rows = d->link_values, *lam = d->link_values + L;
    int moved = 0;
    for (ln_int k = 0; k < K; k++)
        for (int e = 0; e < DIM; e++) {
            const double change = U_after[DIM * k + e] - U_before[DIM * k + e];
            dU[DIM * k + e] = mm->is_fixed[k] ? 0.0 : ground ? change - mm->inv_m[k] * ground[DIM * k + e] : change;
            moved |= dU[DIM * k + e] != 0.0;
        }
    if (!moved) return LN_OK;
    FN(rope_touching)(mm, X, NULL, at_length);
    FN(rope_mask_of)(mm, d, at_length);
    if (!grips && mm->n_grips) {
        for (ln_int l = L - mm->n_grips; l < L; l++) d->mask[l] = 0;
        FN(rope_use_mask)(mm, d, d->mask);
    }
    FN(ln_unit_vectors)(mm, X, d->E0);
    const int status = FN(ln_factor_tension_matrix)(mm, d, d->E0);
    if (status != LN_OK) return status;
    for (ln_int l = 0; l < L; l++) {
        const ln_int a = mm->k1[l], b = mm->k2[l];
        double sum = 0.0;
        for (int e = 0; e < DIM; e++) sum += d->E0[DIM * l + e] * (dU[DIM * a + e] - dU[DIM * b + e]);
        rows[l] = sum;
    }
    FN(ln_solve_tension_system)(mm, d, rows, lam);
    for (ln_int l = 0; l < L; l++)
        for (ln_int a = 0; a < mm->n_driven; a++) {
            const ln_int k = mm->driven_idx[a];
            const double sign = mm->k1[l] == k ? 1.0 : mm->k2[l] == k ? -1.0 : 0.0;
            if (sign == 0.0 || !d->mask[l]) continue;
            for (int e = 0; e < DIM; e++) d->impulse[3 * a + e] += sign * lam[l] * d->E0[DIM * l + e];
        }
    return LN_OK;
}

/* At an event at t (state X, U of the old mode): positions onto the touching ropes, the impact, the next mode, the
   events recorded (EventHandling._apply_event). kind 1: rope trigger reached its length; 2: its tension fell to 0;
   3: the driven anchors' motion jumped (the ropes it stretched are put back with the touching ones, and every rope
   it jerked, taut already or not, is a taut event). What the links gave the driven anchors in it is added to
   d->impulse (EventHandling._apply_event's anchor impulses). */
static int FN(rope_apply_event)(const ln_model *mm, const ln_method *meth, ln_data *d, double *X, double *U,
                                const double *F_base, double t, int kind, ln_int trigger)
{
    const ln_int R = mm->n_ropes, n_c = mm->n_contacts, first_contact = R - n_c;
    uint8_t *touching = d->rope_flags, *took = d->rope_flags + R, *candidates = d->rope_flags + 2 * R;
    uint8_t *active = d->rope_flags + 4 * R, *release = d->rope_flags + 5 * R;
    double *impulses = d->rope_values + 9 * R;
    /* friction: the contact whose stick margin or slip speed fell through zero (a trigger past the ropes), the
       contacts stuck before, those that may stick after, each contact's tangential impulse */
    const ln_int friction_contact = kind == 2 && trigger >= R ? trigger - R : -1;
    uint8_t *stuck_before = d->friction_flags + 3 * n_c, *may_stick = d->friction_flags + 4 * n_c;
    double *tangential = d->friction_values + 5 * n_c;
    int status;
    if (mm->n_driven) memcpy(d->event_U_before, U, (size_t)(mm->K * DIM) * sizeof(double));
    for (ln_int c = 0; c < n_c && mm->n_grips; c++) stuck_before[c] = d->link_active[FN(grip_link)(mm, c, 0)];
    FN(rope_touching)(mm, X, NULL, touching);
    for (ln_int r = 0; r < R; r++) touching[r] |= d->link_active[mm->rope_link[r]];
    if (kind == 1) touching[trigger] = 1;
    if (kind == 3)
        for (ln_int r = 0; r < R; r++) touching[r] |= FN(rope_gap)(mm, X, mm->rope_link[r]) < 0.0;
    if (mm->n_grips) {  /* the touching constraints' mode has no grips (UnilateralDynamics.mode, stuck None) */
        for (ln_int c = 0; c < n_c; c++) may_stick[c] = 0;
        FN(friction_set_stuck)(mm, d, may_stick);
    }
    if ((status = FN(rope_project)(mm, meth, d, touching, X, NULL)) != LN_OK) return status;
    if (mm->n_contacts) FN(ln_contacts_place)(mm, X, U);
    status = mm->n_grips ? FN(friction_impact)(mm, meth, d, X, U, touching, impulses, took, tangential)
                         : FN(rope_impact)(mm, meth, d, X, U, touching, impulses, took);
    if (status != LN_OK) return status;
    if ((status = FN(rope_drive)(mm, d, t, X, U)) != LN_OK) return status;
    /* the touching ropes that do not separate, or separate slower than the rest speed (an inelastic collapse) */
    const double limit = ln_fmax(mm->touch_tol * FN(rope_velocity_scale)(mm, U), FN(rope_rest_speed)(mm, U));
    for (ln_int r = 0; r < R; r++) {
        candidates[r] = touching[r] && FN(rope_rate)(mm, X, U, mm->rope_link[r]) <= limit;
        release[r] = kind == 2 && r == trigger;
    }
    if (mm->n_grips) {
        /* the contacts that may stick: those at rest along the plane after the impact, one whose slip stopped; not
           one whose stick margin fell through zero; in the LCP's mode as equalities where candidates. One stuck
           before that the impact set moving is not held: its grip would take the velocity the impact gave it, a
           friction impulse beyond the cone mu P_n that friction_impact solved (EventHandling._apply_event) */
        FN(friction_resting)(mm, U, may_stick);
        if (friction_contact >= 0) may_stick[friction_contact] = !stuck_before[friction_contact];
        uint8_t *grips = d->friction_flags + 5 * n_c;
        for (ln_int c = 0; c < n_c; c++) grips[c] = may_stick[c] && candidates[first_contact + c];
        FN(friction_set_stuck)(mm, d, grips);
    }
    if ((status = FN(rope_select_mode)(mm, d, X, U, F_base, candidates, candidates, release, active)) != LN_OK)
        return status;
    if (kind == 2 && trigger < R && active[trigger]) {
        int changed = 0;
        for (ln_int r = 0; r < R; r++)
            if (active[r] != d->link_active[mm->rope_link[r]]) changed = 1;
        if (!changed) active[trigger] = 0;  /* its force is at zero to round-off and falling: it leaves */
    }
    if (mm->n_grips) {  /* which contacts the ground holds after the impact */
        if ((status = FN(friction_choose_stuck)(mm, d, X, U, F_base, active, may_stick)) != LN_OK) return status;
    }
    double *U_before_grip = d->event_states + 7 * 3 * mm->K;
    memcpy(U_before_grip, U, (size_t)(mm->K * DIM) * sizeof(double));
    memcpy(d->Xc, X, (size_t)(mm->K * DIM) * sizeof(double));
    if ((status = FN(rope_project)(mm, meth, d, active, NULL, U)) != LN_OK) return status;
    for (ln_int r = 0; r < R; r++) {
        const ln_int l = mm->rope_link[r];
        if ((took[r] || active[r]) && (!d->link_active[l] || (kind == 3 && took[r])))
            FN(rope_record)(d, t, LN_EVENT_TAUT, l, impulses[r], mm);
    }
    for (ln_int r = 0; r < R; r++) {
        const ln_int l = mm->rope_link[r];
        if (d->link_active[l] && !active[r]) FN(rope_record)(d, t, LN_EVENT_SLACK, l, 0.0, mm);
    }
    for (ln_int c = 0; c < n_c && mm->n_grips; c++) {
        const ln_int l = FN(contact_link)(mm, c), k = mm->contact_mass[c];
        const int stuck = d->link_active[FN(grip_link)(mm, c, 0)];
        if (!(d->link_active[l] && active[first_contact + c] && stuck != stuck_before[c])) continue;
        /* a stick's impulse: the tangential impulse of the impact and what the grips' projection took */
        double grip = 0.0;
        for (int e = 0; e < 3; e++) {
            const double dv = U[k * DIM + e] - U_before_grip[k * DIM + e];
            grip += dv * dv;
        }
        grip = ln_sqrt(grip) / mm->inv_m[k];
        FN(rope_record)(d, t, stuck ? LN_EVENT_STICK : LN_EVENT_SLIP, l, stuck ? tangential[c] + grip : 0.0, mm);
    }
    for (ln_int r = 0; r < R; r++) d->link_active[mm->rope_link[r]] = active[r];
    if (mm->n_driven) {
        /* the event's impulse on the driven anchors, added to the advance's (Jreact); with friction in two parts:
           the impact's, the ground's impulse along its plane taken out, then the projection's onto the next mode,
           its stuck contacts' grips in */
        const double *U_projected_from = mm->n_grips ? U_before_grip : d->event_U_before;
        status = mm->n_grips ? FN(rope_anchor_impulses)(mm, d, X, d->event_U_before, U_before_grip,
                                                        d->event_ground_impulse, 0)
                             : LN_OK;
        if (status == LN_OK) status = FN(rope_anchor_impulses)(mm, d, X, U_projected_from, U, NULL, 1);
        FN(rope_use_mask)(mm, d, d->link_active);
        if (status != LN_OK) return status;
    }
    if (mm->n_grips) {  /* the slip reference from the velocities after the event, or the accelerations at rest */
        FN(rope_use_mask)(mm, d, d->link_active);
        for (ln_int i = 0; i < 3 * n_c; i++) d->slip_reference[i] = 0.0;
        if ((status = FN(friction_set_reference)(mm, d, X, U, F_base)) != LN_OK) return status;
    }
    return LN_OK;
}

/* The ropes' tensions of stage i of the attempt being made (d->T after its evaluation), and the largest |T| of the
   mode's links over its stages so far (the first stage starts it). */
void FN(ln_rope_keep_stage)(const ln_model *mm, ln_data *d, ln_int i)
{
    double *kept = d->stage_tensions + (i - 1) * mm->n_ropes;
    for (ln_int r = 0; r < mm->n_ropes; r++) kept[r] = d->T[mm->rope_link[r]];
    double largest = i == 1 ? 0.0 : d->stage_force_scale;
    for (ln_int l = 0; l < mm->L; l++)
        if (d->link_active[l]) largest = ln_fmax(largest, fabs(d->T[l]));
    d->stage_force_scale = largest;
}

/* (x, y) of the vertex of the parabola through (x[j], y[j]), j = 0..2, x ascending and y[1] the lowest, clamped to
   [x[0], x[2]] (events._parabola_vertex). */
static void rope_parabola_vertex(const double *x, const double *y, double *xv_out, double *yv_out)
{
    const double d01 = (y[1] - y[0]) / (x[1] - x[0]), d12 = (y[2] - y[1]) / (x[2] - x[1]);
    const double a = (d12 - d01) / (x[2] - x[0]);
    if (!(a > 0.0)) {
        *xv_out = x[1];
        *yv_out = y[1];
        return;
    }
    const double b = d01 - a * (x[0] + x[1]);
    const double xv = ln_fmin(ln_fmax(-b / (2.0 * a), x[0]), x[2]);
    *xv_out = xv;
    *yv_out = y[1] + (xv - x[1]) * (d01 + a * (xv - x[0]));
}

/* The forces a step sampled inside itself: n samples, sample j at nodes[j * node_stride] (its fraction of the step)
   with the ropes' tensions at tensions + j * stride (n_ropes of them). An adaptive step's inner stages (the nodes c_i
   of the tableau, the tensions ln_rope_keep_stage kept), or a fixed step's RATTLE stages' midpoints (rows of
   d->stage_tensions: the node, then the tensions; rope_keep_midpoint). */
struct FN(force_samples) {
    const double *nodes, *tensions;
    ln_int node_stride, stride, n;
};

/* A force event inside a step whose end showed none (EventHandling._force_dip_at_stages): a taut rope's tension that
   falls through zero and rises again within the step. The samples inside the step (nodes in (0, 1)) are screened at
   each node against -force_tol of their largest |T| (d->stage_force_scale), and at the vertex of the parabola
   through three consecutive nodes (by node) whose middle one is lowest; the candidates, in the order of (theta,
   rope), are confirmed on the method's own step to theta h. Where one is, *rope is its rope, *h_dip the step to it
   and (Xc, Uc) the state there; else *rope = -1. */
static int FN(rope_force_dip_at_stages)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X0,
                                        const double *U0, const double *F_base, double t0, double h,
                                        const struct FN(force_samples) *samples, double *Xc, double *Uc,
                                        ln_int *rope, double *h_dip)
{
    const ln_int R = mm->n_ropes;
    *rope = -1;
    int any_taut = 0;
    for (ln_int r = 0; r < R; r++) any_taut |= d->link_active[mm->rope_link[r]] != 0;
    if (!any_taut || samples->n < 1) return LN_OK;
    /* the inner nodes, ascending (insertion sort of sample indices by node; a few dozen samples at most) */
    ln_int order[64], n = 0;
    for (ln_int i = 0; i < samples->n && n < 64; i++) {
        const double c = samples->nodes[i * samples->node_stride];
        if (!(c > 0.0 && c < 1.0)) continue;
        ln_int j = n++;
        while (j > 0 && samples->nodes[order[j - 1] * samples->node_stride] > c) {
            order[j] = order[j - 1];
            j--;
        }
        order[j] = i;
    }
    if (n < 1) return LN_OK;
    const double tol = mm->force_tol * d->stage_force_scale;
    double *theta_of = d->rope_values, *rope_of = d->rope_values + R;  /* the candidates */
    ln_int n_candidates = 0;
    for (ln_int r = 0; r < R; r++) {
        if (!d->link_active[mm->rope_link[r]]) continue;
        double nodes[64], f[64], theta = -1.0;
        for (ln_int j = 0; j < n; j++) {
            nodes[j] = samples->nodes[order[j] * samples->node_stride];
            f[j] = samples->tensions[order[j] * samples->stride + r];
        }
        for (ln_int j = 0; j < n && theta < 0.0; j++)
            if (f[j] < -tol) theta = nodes[j];
        for (ln_int j = 1; j + 1 < n && theta < 0.0; j++) {
            if (!(f[j] <= f[j - 1] && f[j] <= f[j + 1] && nodes[j - 1] < nodes[j] && nodes[j] < nodes[j + 1]))
                continue;
            double xv, yv;
            rope_parabola_vertex(nodes + j - 1, f + j - 1, &xv, &yv);
            if (yv < -tol) theta = xv;
        }
        if (theta < 0.0) continue;
        ln_int j = n_candidates++;  /* kept in the order of (theta, rope) */
        while (j > 0 && theta_of[j - 1] > theta) {
            theta_of[j] = theta_of[j - 1];
            rope_of[j] = rope_of[j - 1];
            j--;
        }
        theta_of[j] = theta;
        rope_of[j] = (double)r;
    }
    for (ln_int k = 0; k < n_candidates; k++) {
        const double theta = theta_of[k];
        const ln_int r = (ln_int)rope_of[k];
        double scale;
        int status = FN(rope_method_step)(mm, meth, d, X0, U0, F_base, t0, theta * h, Xc, Uc);
        if (status == LN_OK) status = FN(rope_forces_at)(mm, d, t0 + theta * h, Xc, Uc, F_base, &scale);
        if (status != LN_OK) return status;
        if (d->T[mm->rope_link[r]] < -mm->force_tol * scale) {
            *rope = r;
            *h_dip = theta * h;
            return LN_OK;
        }
    }
    return LN_OK;
}

/* The accepted step from (X0, U0) at t0 of length h to (X1, U1) at *t1 with no event, checked where a sliding
   contact started it at rest (AdaptiveEvents._young_slip_step): the friction's U_t / |U_t|, singular at rest,
   costs the method its order in the first step of a slip from rest (the step errs as h^3, unseen by the error
   estimate). The step is compared with two half steps of the method in the controller's norm; beyond the tolerance
   it is replaced by the method's step of the length where that error, taken as h^3, meets it: (X1, U1, *t1). */
static int FN(friction_young_slip)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X0,
                                   const double *U0, const double *F_base, double t0, double h, double *X1,
                                   double *U1, double *t1)
{
    const ln_int K3 = 3 * mm->K;
    const double scale = FN(rope_velocity_scale)(mm, U0), *n = mm->ground_normal;
    int young = 0;
    for (ln_int c = 0; c < mm->n_contacts && !young; c++) {
        if (!FN(contact_sliding)(mm, c)) continue;
        const ln_int k = mm->contact_mass[c];
        double normal = 0.0, speed = 0.0;
        for (int e = 0; e < 3; e++) normal += U0[k * DIM + e] * n[e];
        for (int e = 0; e < 3; e++) {
            const double v = U0[k * DIM + e] - normal * n[e];
            speed += v * v;
        }
        young = ln_sqrt(speed) <= mm->touch_tol * scale;
    }
    if (!young) return LN_OK;
    double *Xh = d->event_states + 4 * K3, *Uh = Xh + K3, *X2 = d->event_states + 10 * K3, *U2 = X2 + K3;
    int status = FN(rope_method_step)(mm, meth, d, X0, U0, F_base, t0, 0.5 * h, Xh, Uh);
    if (status == LN_OK) status = FN(rope_method_step)(mm, meth, d, Xh, Uh, F_base, t0 + 0.5 * h, 0.5 * h, X2, U2);
    if (status != LN_OK) return status;
    double sum = 0.0;
    for (int part = 0; part < 2; part++) {
        const double *Y0 = part ? U0 : X0, *Y1 = part ? U1 : X1, *Y2 = part ? U2 : X2;
        for (ln_int f = 0; f < mm->n_free; f++)
            for (int e = 0; e < DIM; e++) {
                const ln_int i = mm->free_idx[f] * DIM + e;
                const double sc = meth->atol + meth->rtol * ln_fmax(fabs(Y0[i]), fabs(Y1[i]));
                const double r = (Y2[i] - Y1[i]) / sc;
                sum += r * r;
            }
    }
    const double error = ln_sqrt(sum / (2.0 * DIM * (double)mm->n_free));
    if (error <= 1.0) return LN_OK;
    const double h_ok = h * ln_fmax(meth->safety * ln_pow(error, -1.0 / 3.0), meth->min_factor);
    if ((status = FN(rope_method_step)(mm, meth, d, X0, U0, F_base, t0, h_ok, X1, U1)) != LN_OK) return status;
    *t1 = t0 + h_ok;
    return LN_OK;
}

/* After the accepted step from (X0, U0) at t0 to (X1, U1) at *t1 (AdaptiveEvents._event_in_step): where an event lies
   within it, (X1, U1, *t1) become the state just past the event, in the new mode. The mode's mask is in use again
   on return. */
int FN(ln_rope_step_events)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X0, const double *U0,
                            const double *F_base, double t0, double *X1, double *U1, double *t1)
{
    const ln_int K3 = 3 * mm->K;
    const double h_max = *t1 - t0;
    int found = 0;
    ln_int rope = -1;
    double theta = 0.0;
    /* the step's start and end, kept: the step loop's own arrays are scratch of the method's steps */
    double *Xs0 = d->event_states, *Us0 = Xs0 + K3, *Xs1 = d->event_states + 2 * K3, *Us1 = Xs1 + K3;
    double *Xe = d->event_states + 4 * K3, *Ue = Xe + K3;
    const size_t bytes = (size_t)(mm->K * DIM) * sizeof(double);
    memcpy(Xs0, X0, bytes);
    memcpy(Us0, U0, bytes);
    memcpy(Xs1, X1, bytes);
    memcpy(Us1, U1, bytes);
    int status = FN(rope_first_event)(mm, meth, d, Xs0, Us0, t0, Xs1, Us1, h_max, F_base, &found, &rope, &theta);
    double h_to = h_max;  /* the step the event is located in: to the step's end, or to a dip inside it */
    if (status == LN_OK && !found) {
        /* a tension that fell through zero and rose again within the step: the event lies in the step to the
           confirmed dip, whose state takes the end's place (Xs1, Us1), its time found from the middle on */
        double h_dip = 0.0;
        const struct FN(force_samples) stages = {meth->C + 1, d->stage_tensions, 1, mm->n_ropes,
                                                 meth->n_stages - 1};
        status = FN(rope_force_dip_at_stages)(mm, meth, d, Xs0, Us0, F_base, t0, h_max, &stages, Xs1, Us1, &rope,
                                              &h_dip);
        if (status == LN_OK && rope >= 0) {
            found = 2;
            theta = 0.5;
            h_to = h_dip;
        }
    }
    if (status == LN_OK && found) {
        if (++d->events_this_step > mm->max_events_per_step) {
            status = LN_EVENT_CHATTER;
        } else {
            double h_e = 0.0;
            status = FN(rope_locate)(mm, meth, d, Xs0, Us0, t0, h_to, Xs1, Us1, F_base, found, rope, theta, Xe, Ue,
                                     &h_e);
            const double t_e = h_e >= h_to ? (h_to == h_max ? *t1 : t0 + h_to) : t0 + h_e;
            if (status == LN_OK) status = FN(rope_apply_event)(mm, meth, d, Xe, Ue, F_base, t_e, found, rope);
            if (status == LN_OK) {
                memcpy(X1, Xe, bytes);
                memcpy(U1, Ue, bytes);
                *t1 = t_e;
            }
        }
    } else if (status == LN_OK) {
        d->events_this_step = 0;
        if (mm->n_grips) {
            status = FN(friction_young_slip)(mm, meth, d, Xs0, Us0, F_base, t0, h_max, X1, U1, t1);
            /* the next step's slip reference, at its start */
            if (status == LN_OK) {
                memcpy(Xe, X1, bytes);
                memcpy(Ue, U1, bytes);
                status = FN(rope_drive)(mm, d, *t1, Xe, Ue);
            }
            if (status == LN_OK) status = FN(friction_set_reference)(mm, d, Xe, Ue, F_base);
        }
    }
    FN(rope_use_mask)(mm, d, d->link_active);
    return status;
}

/* One step of a fixed-step method from (X, U) at t0 to t1, in place (FixedStepEvents._step_with_events): a step
   that holds an event is taken to the event, the event applied, and the step finished from there in the new mode,
   so that the steps stay where they are. Besides its end, the forces at its RATTLE stages' midpoints are screened
   for a force that dips through zero within it (rope_force_dip_at_stages, as an adaptive step's stages are). */
int FN(ln_rope_fixed_step)(const ln_model *mm, const ln_method *meth, ln_data *d, double *X, double *U,
                           const double *F_base, double t0, double t1)
{
    const ln_int K3 = 3 * mm->K;
    const size_t bytes = (size_t)(mm->K * DIM) * sizeof(double);
    double *Xs0 = d->event_states, *Us0 = Xs0 + K3, *Xs1 = d->event_states + 2 * K3, *Us1 = Xs1 + K3;
    double *Xe = d->event_states + 4 * K3, *Ue = Xe + K3;
    int status = LN_OK;
    for (ln_int k = 0; k < mm->max_events_per_step; k++) {
        memcpy(Xs0, X, bytes);
        memcpy(Us0, U, bytes);
        if (mm->n_grips && FN(any_sliding)(mm)) {
            /* the sliding contacts' slip directions at the start of the step, or of its rest after an event: the
               reference of the friction's direction through it (EventHandling._slip_reference) */
            memcpy(Xe, X, bytes);
            memcpy(Ue, U, bytes);
            if ((status = FN(rope_drive)(mm, d, t0, Xe, Ue)) != LN_OK) break;
            if ((status = FN(friction_set_reference)(mm, d, Xe, Ue, F_base)) != LN_OK) break;
        }
        /* the forces inside the step are sampled at its RATTLE stages' midpoints where a rope or contact is taut
           (FixedStepEvents._midpoint_tensions), each a row of the node and the tensions in d->stage_tensions */
        int any_taut = 0;
        for (ln_int r = 0; r < mm->n_ropes; r++) any_taut |= d->link_active[mm->rope_link[r]] != 0;
        const int room = d->n_stages_allocated * mm->n_ropes >= meth->n_gammas * (mm->n_ropes + 1);
        ln_int n_samples = 0;
        status = FN(rope_plain_step)(mm, meth, d, Xs0, Us0, F_base, t0, t1, Xs1, Us1,
                                     any_taut && room ? &n_samples : NULL);
        if (status != LN_OK) break;
        int found = 0;
        ln_int rope = -1;
        double theta = 0.0, h_e = 0.0;
        status = FN(rope_first_event)(mm, meth, d, Xs0, Us0, t0, Xs1, Us1, t1 - t0, F_base, &found, &rope, &theta);
        if (status != LN_OK) break;
        double t_to = t1;  /* the step the event is located in: to the step's end, or to a dip inside it */
        if (!found && n_samples) {
            /* a force that fell through zero and rose again within the step: the event lies in the step to the
               confirmed dip, whose state takes the end's place (Xs1, Us1), its time found from the middle on */
            const struct FN(force_samples) midpoints = {d->stage_tensions, d->stage_tensions + 1, mm->n_ropes + 1,
                                                        mm->n_ropes + 1, n_samples};
            double h_dip = 0.0;
            status = FN(rope_force_dip_at_stages)(mm, meth, d, Xs0, Us0, F_base, t0, t1 - t0, &midpoints, Xs1, Us1,
                                                  &rope, &h_dip);
            if (status != LN_OK) break;
            if (rope >= 0) {
                found = 2;
                theta = 0.5;
                t_to = t0 + h_dip;
            }
        }
        if (!found) {
            memcpy(X, Xs1, bytes);
            memcpy(U, Us1, bytes);
            FN(rope_use_mask)(mm, d, d->link_active);
            return LN_OK;
        }
        const double h_max = t_to - t0;
        status = FN(rope_locate)(mm, meth, d, Xs0, Us0, t0, h_max, Xs1, Us1, F_base, found, rope, theta, Xe, Ue,
                                 &h_e);
        const double t_e = h_e >= h_max ? t_to : t0 + h_e;
        if (status == LN_OK) status = FN(rope_apply_event)(mm, meth, d, Xe, Ue, F_base, t_e, found, rope);
        FN(rope_use_mask)(mm, d, d->link_active);
        if (status != LN_OK) return status;
        memcpy(X, Xe, bytes);
        memcpy(U, Ue, bytes);
        if (t_e >= t1) return LN_OK;
        t0 = t_e;
    }
    FN(rope_use_mask)(mm, d, d->link_active);
    return status != LN_OK ? status : LN_EVENT_CHATTER;
}

#if DIM == 3
int ln_rope_anchor_jump(const ln_model *m, const ln_method *meth, ln_data *d, const double *P, const double *V)
{
    ln_model mode = *m;
    mode.inv_R = d->mode_inv_R;
    const ln_model *mm = &mode;
    double *X = d->X, *U = d->U;
    int status;
    if (m->n_contacts) FN(ln_contacts_place)(m, X, U);
    if (!d->mode_chosen) {  /* the mode of the state before the jump (its anchors' accelerations not in B) */
        uint8_t *active = d->rope_flags + 4 * m->n_ropes;
        if ((status = FN(rope_state_mode)(mm, d, X, U, d->F_base, active)) != LN_OK) return status;
        for (ln_int l = 0; l < m->L; l++) d->link_active[l] = l < m->L - m->n_grips;
        for (ln_int r = 0; r < m->n_ropes; r++) d->link_active[m->rope_link[r]] = active[r];
        d->mode_chosen = 1;
    }
    for (ln_int a = 0; a < m->n_driven; a++)
        for (int e = 0; e < 3; e++) {
            X[3 * m->driven_idx[a] + e] = P[3 * a + e];
            U[3 * m->driven_idx[a] + e] = V[3 * a + e];
        }
    status = FN(rope_apply_event)(mm, meth, d, X, U, d->F_base, d->t, 3, -1);
    FN(rope_use_mask)(mm, d, d->link_active);
    return status;
}

int ln_rope_initial_state(const ln_model *m, const ln_method *meth, ln_data *d, double *X, double *U, int project)
{
    const ln_int R = m->n_ropes, first_contact = R - m->n_contacts;
    ln_model mode = *m;
    mode.inv_R = d->mode_inv_R;
    double *no_restitution = d->rope_values;  /* the initial impact is inelastic, whatever the ropes' restitution */
    for (ln_int r = 0; r < R; r++) no_restitution[r] = 0.0;
    mode.rope_restitution = no_restitution;
    const ln_model *mm = &mode;
    uint8_t *flags = d->rope_flags, *took = d->rope_flags + R;
    double *impulses = d->rope_values + 9 * R;
    int status;
    for (ln_int l = 0; l < m->L; l++) d->link_active[l] = 0;  /* no grip: the initial impact is frictionless */
    if (m->n_contacts) FN(ln_contacts_place)(m, X, U);
    if (project) {  /* the rods and the ropes longer than their length, in the mass metric (the contacts not) */
        for (ln_int r = 0; r < R; r++) flags[r] = r < first_contact && FN(rope_gap)(mm, X, m->rope_link[r]) < 0.0;
        if ((status = FN(rope_project)(mm, meth, d, flags, X, NULL)) != LN_OK) return status;
        if (m->n_contacts) FN(ln_contacts_place)(m, X, U);
    }
    FN(rope_touching)(mm, X, NULL, flags);
    status = FN(rope_impact)(mm, meth, d, X, U, flags, impulses, took);
    d->mode_chosen = 0;  /* the first advance chooses the mode from this state */
    return status;
}

int ln_rope_evaluate(const ln_model *m, ln_data *d, const double *X, const double *U)
{
    ln_model mode = *m;
    mode.inv_R = d->mode_inv_R;
    if (m->n_contacts) {  /* the contacts' anchors placed on a copy of the state */
        double *Xp = d->event_states, *Up = Xp + 3 * m->K;
        memcpy(Xp, X, (size_t)(3 * m->K) * sizeof(double));
        memcpy(Up, U, (size_t)(3 * m->K) * sizeof(double));
        FN(ln_contacts_place)(m, Xp, Up);
        X = Xp;
        U = Up;
    }
    uint8_t *active = d->rope_flags + 4 * m->n_ropes, *stuck_kept = d->friction_flags + 2 * m->n_contacts;
    for (ln_int c = 0; c < m->n_contacts && m->n_grips; c++) stuck_kept[c] = d->link_active[FN(grip_link)(m, c, 0)];
    int status = FN(rope_state_mode)(&mode, d, X, U, d->F_base, active);
    if (status == LN_OK) {
        FN(rope_mask_of)(&mode, d, active);
        status = FN(rope_mode_tensions)(&mode, d, X, U, d->F_base, d->acc, d->T);
    }
    if (m->n_grips) FN(friction_set_stuck)(m, d, stuck_kept);  /* the integrator's mode, as it was */
    FN(rope_use_mask)(&mode, d, d->link_active);
    return status;
}

ln_int ln_rope_events_drained(ln_data *d)
{
    const ln_int n = d->n_events;
    d->n_events = 0;
    return n;
}
#endif

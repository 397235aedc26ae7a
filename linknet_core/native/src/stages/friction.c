/* Coulomb friction on the ground: a sliding contact's friction -mu N d and the direction d it slips in. The numpy
 * reference of every rule here is linknet_core.dynamics.unilateral (ModeDynamics.friction_and_tensions,
 * normal_system; UnilateralDynamics.slip_directions, starting_slip_directions, _coulomb_directions, _slip_direction).
 *
 * A contact slides in the mode in use when its contact link is in it and its grips are not (mm->inv_R, the mode's).
 * Its friction loads its mass, so its normal force depends on it: with B(F) of (26) affine in the forces, W N =
 * B(F - sum_c mu N_c d_c at k_c). With T0 the mode's tensions for F (W T0 = B(F)) and Y_c those for the load -mu d_c at
 * k_c alone at zero velocity (W Y_c = B's response to it, the reference's column c of D), N = T0 + sum_c Y_c N_c, and
 * on the sliding contacts' rows (I - Y_ss) N_s = T0_s: a dense system of the sliding contacts only, each column one
 * more solve with the mode's factorisation (the reference solves (W - D) N = B(F) by least squares; the two agree
 * wherever the sliding rows are determined). For a mass alone on the ground Y_c is zero on its row (its friction is
 * tangential, its normal row sees only its own normal load). The accelerations are then the mode's with F plus the
 * friction, as the reference's.
 */

/* The link of contact c, of grip i of contact c; contact c slides in the mode in use. */
static inline ln_int FN(contact_link)(const ln_model *m, ln_int c) { return m->L - m->n_grips - m->n_contacts + c; }
static inline ln_int FN(grip_link)(const ln_model *m, ln_int c, int i) { return m->L - m->n_grips + 2 * c + i; }
static inline int FN(contact_sliding)(const ln_model *mm, ln_int c)
{
    return mm->n_grips && mm->inv_R[FN(contact_link)(mm, c)] != 0.0 && mm->inv_R[FN(grip_link)(mm, c, 0)] == 0.0;
}

/* Whether any contact slides in the mode in use. */
static inline int FN(any_sliding)(const ln_model *mm)
{
    for (ln_int c = 0; c < mm->n_contacts; c++)
        if (FN(contact_sliding)(mm, c)) return 1;
    return 0;
}

static double FN(rope_velocity_scale)(const ln_model *m, const double *U);
static void rope_bracketed_root(double (*f)(void *ctx, double x), void *ctx, double *lo_io, double *hi_io, double f_lo,
                                double f_hi, double xtol, int has_guess, double guess);

/* The scratch of the friction (ln_data.friction_work), carved once per call. */
struct FN(friction_work) {
    ln_int *sliding, *starting, *impact_sliding;
    double *Fa, *Fb, *Fc, *zero, *acc, *T0, *Tf, *Y, *dirs, *matrix, *rhs, *a0, *N0, *G, *kk, *a, *N, *d2, *f, *others;
    double *cols, *ycols;  /* the complementarity problems' friction columns and their solves (ropes.c) */
};

static struct FN(friction_work) FN(friction_scratch)(const ln_model *m, ln_data *d)
{
    const ln_int K3 = 3 * m->K, L = m->L, n = m->n_contacts;
    double *p = d->friction_work;
    struct FN(friction_work) w;
    w.Fa = p; p += K3;
    w.Fb = p; p += K3;
    w.Fc = p; p += K3;
    w.zero = p; p += K3;
    w.acc = p; p += K3;
    w.T0 = p; p += L;
    w.Tf = p; p += L;
    w.Y = p; p += n * L;
    w.dirs = p; p += 3 * n;
    w.matrix = p; p += n * n;
    w.rhs = p; p += n;
    w.a0 = p; p += 2 * n;
    w.N0 = p; p += n;
    w.G = p; p += 4 * n * n;
    w.kk = p; p += 2 * n * n;
    w.a = p; p += 2 * n;
    w.N = p; p += n;
    w.d2 = p; p += 2 * n;
    w.f = p; p += 2 * n;
    w.others = p; p += 3 * n;
    w.cols = p; p += n * L;
    w.ycols = p;
    w.sliding = d->friction_index;
    w.starting = d->friction_index + n;
    w.impact_sliding = d->friction_index + 2 * n;
    return w;
}

/* Solves the n x n system A x = b in place (A row-major, destroyed; x into b) by Gaussian elimination with partial
   pivoting; 0, or -1 where A is singular. */
static int friction_dense_solve(ln_int n, double *A, double *b)
{
    for (ln_int col = 0; col < n; col++) {
        ln_int piv = col;
        for (ln_int r = col + 1; r < n; r++)
            if (fabs(A[r * n + col]) > fabs(A[piv * n + col])) piv = r;
        if (A[piv * n + col] == 0.0) return -1;
        if (piv != col) {
            for (ln_int j = 0; j < n; j++) {
                const double t = A[col * n + j];
                A[col * n + j] = A[piv * n + j];
                A[piv * n + j] = t;
            }
            const double t = b[col];
            b[col] = b[piv];
            b[piv] = t;
        }
        for (ln_int r = col + 1; r < n; r++) {
            const double factor = A[r * n + col] / A[col * n + col];
            if (factor == 0.0) continue;
            for (ln_int j = col; j < n; j++) A[r * n + j] -= factor * A[col * n + j];
            b[r] -= factor * b[col];
        }
    }
    for (ln_int r = n - 1; r >= 0; r--) {
        double s = b[r];
        for (ln_int j = r + 1; j < n; j++) s -= A[r * n + j] * b[j];
        b[r] = s / A[r * n + r];
    }
    return 0;
}

/* The sliding friction of the mode in use at (X, U) for the forces F (base forces; the force elements are added by
   the evaluation), the contacts slipping along dirs (n_contacts, 3; a zero row: no friction of that contact, as the
   reference's directions of the starting contacts): into friction (K, DIM) the loads -mu N_c d_c, into Tf (L) the
   mode's tensions that go with them (ModeDynamics.friction_and_tensions). A(X) is factored on return. */
static int FN(friction_loads)(const ln_model *mm, ln_data *d, struct FN(friction_work) *w, const double *X,
                              const double *U, const double *F, const double *dirs, double *friction, int refactor)
{
    const ln_int K3 = mm->K * DIM, L = mm->L, n = mm->n_contacts;
    const double mu = mm->friction;
    int status = accelerations(mm, d, X, U, F, w->acc, w->T0, refactor);
    if (status != LN_OK) return status;
    for (ln_int i = 0; i < K3; i++) friction[i] = 0.0;
    memcpy(w->Tf, w->T0, (size_t)L * sizeof(double));
    ln_int *sliding = w->sliding, n_s = 0;
    for (ln_int c = 0; c < n; c++) {
        double size = 0.0;
        for (int e = 0; e < DIM; e++) size += fabs(dirs[3 * c + e]);
        if (FN(contact_sliding)(mm, c) && size > 0.0) sliding[n_s++] = c;
    }
    if (!n_s) return LN_OK;
    /* each sliding contact's unit friction load alone at zero velocity, no force elements: B's response, its
       tensions Y_c (the mode's factorisation reused) */
    ln_model loads_only = *mm;
    loads_only.n_elements = 0;
    for (ln_int i = 0; i < K3; i++) w->zero[i] = 0.0;
    for (ln_int j = 0; j < n_s; j++) {
        const ln_int c = sliding[j], k = mm->contact_mass[c];
        for (ln_int i = 0; i < K3; i++) w->Fc[i] = 0.0;
        for (int e = 0; e < DIM; e++) w->Fc[k * DIM + e] = -mu * dirs[3 * c + e];
        if ((status = accelerations(&loads_only, d, X, w->zero, w->Fc, w->acc, w->Y + j * L, 0)) != LN_OK)
            return status;
    }
    for (ln_int i = 0; i < n_s; i++) {
        const ln_int row = FN(contact_link)(mm, sliding[i]);
        for (ln_int j = 0; j < n_s; j++) w->matrix[i * n_s + j] = (i == j) - w->Y[j * L + row];
        w->rhs[i] = w->T0[row];
    }
    if (friction_dense_solve(n_s, w->matrix, w->rhs)) return LN_SINGULAR;
    for (ln_int j = 0; j < n_s; j++) {
        const ln_int c = sliding[j], k = mm->contact_mass[c];
        for (ln_int l = 0; l < L; l++) w->Tf[l] += w->Y[j * L + l] * w->rhs[j];
        for (int e = 0; e < DIM; e++) friction[k * DIM + e] += -mu * w->rhs[j] * dirs[3 * c + e];
    }
    return LN_OK;
}

/* The accelerations (acc) and tensions (T) of the mode in use at (X, U) with the loads F plus the sliding friction
   along dirs, and the friction-aware tensions Tf of friction_loads in w->Tf. */
static int FN(friction_evaluate)(const ln_model *mm, ln_data *d, struct FN(friction_work) *w, const double *X,
                                 const double *U, const double *F, const double *dirs, double *acc, double *T,
                                 int refactor)
{
    const ln_int K3 = mm->K * DIM;
    double *friction = w->Fb;
    int status = FN(friction_loads)(mm, d, w, X, U, F, dirs, friction, refactor);
    if (status != LN_OK) return status;
    for (ln_int i = 0; i < K3; i++) friction[i] += F[i];
    return accelerations(mm, d, X, U, friction, acc, T, 0);
}

/* ---- the slip directions ---------------------------------------------------------------------------------------- */
struct friction_law {
    double a[2], N, G[4], k[2], mu;
    double c[2];  /* the unit direction angles are measured from (slip_direction's guess) */
};

/* The unit direction at angle theta from the unit vector c (2) on the plane's tangents: c turned by theta (ln_math's
   sine and cosine: the core calls no C math library). */
static void turned(const double *c, double theta, double *d)
{
    const double cs = ln_cos(theta), sn = ln_sin(theta);
    d[0] = c[0] * cs - c[1] * sn;
    d[1] = c[1] * cs + c[0] * sn;
}

/* (a - s G d) x d, (a - s G d) . d and s = mu N / (1 + mu k . d) at d, the direction at angle theta from the unit
   vector q->c (_slip_direction's law, whose angle is measured from the guess's direction). */
static void friction_law_at(const struct friction_law *q, double theta, double *cross, double *along, double *s_out)
{
    double d[2];
    turned(q->c, theta, d);
    const double d0 = d[0], d1 = d[1];
    const double s = q->mu * q->N / (1.0 + q->mu * (q->k[0] * d0 + q->k[1] * d1));
    const double acc0 = q->a[0] - s * (q->G[0] * d0 + q->G[1] * d1);
    const double acc1 = q->a[1] - s * (q->G[2] * d0 + q->G[3] * d1);
    *cross = acc1 * d0 - acc0 * d1;
    *along = acc0 * d0 + acc1 * d1;
    *s_out = s;
}

/* |remainder(theta, 2 pi)| for theta in [-2 pi, 2 pi]: how far an angle is from 0 around the circle. */
static double angle_distance(double theta)
{
    const double two_pi = 6.283185307179586;
    theta = fabs(theta);
    return theta > 0.5 * two_pi ? two_pi - theta : theta;
}

struct friction_law_sign {
    const struct friction_law *q;
    double sign;
};

static double friction_law_fn(void *ctx, double phi)
{
    const struct friction_law_sign *c = ctx;
    double cross, along, s;
    friction_law_at(c->q, phi, &cross, &along, &s);
    return c->sign * cross;
}

/* The slip direction from rest of one contact on the plane's tangents (UnilateralDynamics._slip_direction): guess
   where the law holds there to round-off, else the root of (a - s G d) x d = 0 with (a - s G d) . d >= 0 and s > 0
   nearest it (a scan at 64 angles, each sign change bracketed), else guess. In out (2). */
static void FN(slip_direction)(const struct friction_law *q, const double *guess, double *out)
{
    out[0] = guess[0];
    out[1] = guess[1];
    if (guess[0] == 0.0 && guess[1] == 0.0) return;
    double gmax = 0.0;
    for (int i = 0; i < 4; i++) gmax = ln_fmax(gmax, fabs(q->G[i]));
    const double slack = 64 * 2.220446049250313e-16 * ln_fmax(ln_sqrt(q->a[0] * q->a[0] + q->a[1] * q->a[1]),
                                                              q->mu * fabs(q->N) * gmax);
    /* angles from the guess's direction: the scan's grid and the distance of a root from the guess are the
       reference's (its angles are absolute, atan2 of the guess plus these) */
    const double size = ln_hypot(guess[0], guess[1]);
    struct friction_law law = *q;
    law.c[0] = guess[0] / size;
    law.c[1] = guess[1] / size;
    q = &law;
    double cross, along, s;
    friction_law_at(q, 0.0, &cross, &along, &s);
    if (fabs(cross) <= slack && along >= -slack && s > 0) return;
    const double pi = 3.141592653589793;
    double grid[65], values[65], best = 0.0, best_distance = INFINITY;
    int found = 0;
    for (int j = 0; j < 65; j++) {
        grid[j] = -pi + 2 * pi * ((double)j + 0.5) / 64;
        friction_law_at(q, grid[j], &values[j], &along, &s);
    }
    for (int j = 0; j < 65; j++) {  /* exact zeros first, as the reference lists them */
        if (values[j] != 0.0) continue;
        friction_law_at(q, grid[j], &cross, &along, &s);
        if (!(along >= -slack && s > 0)) continue;
        const double distance = angle_distance(grid[j]);
        if (!found || distance < best_distance) {
            best = grid[j];
            best_distance = distance;
            found = 1;
        }
    }
    for (int j = 0; j + 1 < 65; j++) {
        const double v_lo = values[j], v_hi = values[j + 1];
        if (!(v_lo * v_hi < 0)) continue;
        struct friction_law_sign ctx = {q, v_lo > 0 ? 1.0 : -1.0};
        double lo = grid[j], hi = grid[j + 1];
        rope_bracketed_root(friction_law_fn, &ctx, &lo, &hi, ctx.sign * v_lo, ctx.sign * v_hi, 4e-16, 0, 0.0);
        friction_law_at(q, hi, &cross, &along, &s);
        if (!(along >= -slack && s > 0)) continue;
        const double distance = angle_distance(hi);
        if (!found || distance < best_distance) {
            best = hi;
            best_distance = distance;
            found = 1;
        }
    }
    if (!found) return;
    turned(q->c, best, out);
}

/* A response of Coulomb's law at one level (the acceleration level from rest, or an impact): for a load of size
   `size` along tangent i at the law's contact j (j < 0: no load), the tangential quantities the law acts on at its
   m contacts on t_1, t_2 into a (2 m) and their normal forces or impulses into N (m). */
typedef int (*friction_response_fn)(void *ctx, ln_int j, int i, double size, double *a, double *N);

/* The slip directions d_j (on t_1, t_2, into w->d2, 2 m) of m contacts under Coulomb's law at one level
   (UnilateralDynamics._coulomb_directions): the response, affine in the load, measured by 1 + 2 m calls with loads
   of the friction's size, a_j = a0_j + sum_k G_jk f_k and N_j = N0_j + sum_k k_jk . f_k; each d_j the scalar law's
   root (slip_direction), taken in turn (Gauss-Seidel) until the directions settle. */
static int FN(coulomb_directions)(const ln_model *mm, struct FN(friction_work) *w, friction_response_fn response,
                                  void *ctx, ln_int m)
{
    const double mu = mm->friction;
    int status = response(ctx, -1, 0, 0.0, w->a0, w->N0);
    if (status != LN_OK) return status;
    double largest = 0.0;
    for (ln_int q = 0; q < m; q++) largest = ln_fmax(largest, fabs(w->N0[q]));
    /* loads of the size of the friction: a unit load on a heavy scene would be lost in the round-off of a0 */
    const double probe = mu * ln_fmax(largest, 2.2250738585072014e-308);
    /* G[(q, x), (j, i)] = w->G[((q * 2 + x) * m + j) * 2 + i]; kk[(q, j, i)] = w->kk[(q * m + j) * 2 + i] */
    for (ln_int j = 0; j < m; j++)
        for (int i = 0; i < 2; i++) {
            if ((status = response(ctx, j, i, probe, w->a, w->N)) != LN_OK) return status;
            for (ln_int q = 0; q < m; q++) {
                for (int x = 0; x < 2; x++)
                    w->G[((q * 2 + x) * m + j) * 2 + i] = (w->a[2 * q + x] - w->a0[2 * q + x]) / probe;
                w->kk[(q * m + j) * 2 + i] = (w->N[q] - w->N0[q]) / probe;
            }
        }
    for (ln_int q = 0; q < m; q++) {
        const double size = ln_sqrt(w->a0[2 * q] * w->a0[2 * q] + w->a0[2 * q + 1] * w->a0[2 * q + 1]);
        w->d2[2 * q] = size > 0 ? w->a0[2 * q] / size : 0.0;
        w->d2[2 * q + 1] = size > 0 ? w->a0[2 * q + 1] / size : 0.0;
        w->f[2 * q] = w->f[2 * q + 1] = 0.0;
    }
    for (int sweep = 0; sweep < (m > 1 ? 100 : 1); sweep++) {
        double moved = 0.0;
        for (ln_int j = 0; j < m; j++) {
            struct friction_law law;
            law.mu = mu;
            law.N = w->N0[j];
            for (int x = 0; x < 2; x++) law.a[x] = w->a0[2 * j + x];
            for (ln_int q = 0; q < m; q++) {
                if (q == j) continue;
                for (int x = 0; x < 2; x++)
                    for (int y = 0; y < 2; y++) law.a[x] += w->G[((j * 2 + x) * m + q) * 2 + y] * w->f[2 * q + y];
                for (int y = 0; y < 2; y++) law.N += w->kk[(j * m + q) * 2 + y] * w->f[2 * q + y];
            }
            for (int x = 0; x < 2; x++)
                for (int y = 0; y < 2; y++) law.G[2 * x + y] = w->G[((j * 2 + x) * m + j) * 2 + y];
            law.k[0] = w->kk[(j * m + j) * 2];
            law.k[1] = w->kk[(j * m + j) * 2 + 1];
            double dj[2];
            FN(slip_direction)(&law, w->d2 + 2 * j, dj);
            moved = ln_fmax(moved, ln_fmax(fabs(dj[0] - w->d2[2 * j]), fabs(dj[1] - w->d2[2 * j + 1])));
            w->d2[2 * j] = dj[0];
            w->d2[2 * j + 1] = dj[1];
            const double s = -mu * law.N / (1.0 + mu * (law.k[0] * dj[0] + law.k[1] * dj[1]));
            w->f[2 * j] = s * dj[0];
            w->f[2 * j + 1] = s * dj[1];
        }
        if (moved <= 1e-15) break;
    }
    return LN_OK;
}

/* The acceleration level's response (starting_slip_directions'): the starting contacts' tangential accelerations
   and normal forces with the load added to F, the other sliding contacts slipping along w->others. */
struct FN(starting_ctx) {
    const ln_model *mm;
    ln_data *d;
    struct FN(friction_work) *w;
    const double *X, *U, *F;
    const ln_int *starting;
    ln_int m;
};

static int FN(starting_response)(void *vctx, ln_int j, int i, double size, double *a, double *N)
{
    const struct FN(starting_ctx) *c = vctx;
    const ln_model *mm = c->mm;
    struct FN(friction_work) *w = c->w;
    const ln_int K3 = mm->K * DIM;
    memcpy(w->Fa, c->F, (size_t)K3 * sizeof(double));
    if (j >= 0)
        for (int e = 0; e < DIM; e++)
            w->Fa[mm->contact_mass[c->starting[j]] * DIM + e] += size * mm->ground_tangent[3 * i + e];
    int status = FN(friction_evaluate)(mm, c->d, w, c->X, c->U, w->Fa, w->others, w->acc, c->d->T, 0);
    if (status != LN_OK) return status;
    for (ln_int q = 0; q < c->m; q++) {
        const ln_int cc = c->starting[q], k = mm->contact_mass[cc];
        for (int t = 0; t < 2; t++) {
            double s = 0.0;
            for (int e = 0; e < DIM; e++) s += w->acc[k * DIM + e] * mm->ground_tangent[3 * t + e];
            a[2 * q + t] = s;
        }
        N[q] = w->Tf[FN(contact_link)(mm, cc)];
    }
    return LN_OK;
}

/* The directions d on t_1, t_2 (2 m) into 3-D rows of dirs (n_contacts, 3) of the contacts `which`. */
static void FN(friction_directions_3d)(const ln_model *mm, const double *d2, const ln_int *which, ln_int m,
                                       double *dirs)
{
    for (ln_int q = 0; q < m; q++)
        for (int e = 0; e < 3; e++)
            dirs[3 * which[q] + e] = d2[2 * q] * mm->ground_tangent[e] + d2[2 * q + 1] * mm->ground_tangent[3 + e];
}

/* The slip directions of the starting contacts (UnilateralDynamics.starting_slip_directions): Coulomb's law at the
   acceleration level at the first instant of a slip from rest, the starting contacts' friction taken as loads.
   dirs (n_contacts, 3): in, the other sliding contacts'; out, the starting ones' too. */
static int FN(starting_slip_directions)(const ln_model *mm, ln_data *d, struct FN(friction_work) *w,
                                        const double *X, const double *U, const double *F, const ln_int *starting,
                                        ln_int m, double *dirs)
{
    memcpy(w->others, dirs, (size_t)(3 * mm->n_contacts) * sizeof(double));
    for (ln_int q = 0; q < m; q++)
        for (int e = 0; e < 3; e++) w->others[3 * starting[q] + e] = 0.0;
    struct FN(starting_ctx) ctx = {mm, d, w, X, U, F, starting, m};
    const int status = FN(coulomb_directions)(mm, w, FN(starting_response), &ctx, m);
    if (status == LN_OK) FN(friction_directions_3d)(mm, w->d2, starting, m, dirs);
    return status;
}

/* The slip direction of every sliding contact of the mode in use at (X, U) into dirs (n_contacts, 3; zero on the
   others) (UnilateralDynamics.slip_directions): its tangential velocity's while that is above touch_tol of the
   velocity scale and not against the step's reference; else the reference; else, a contact starting to slip from
   rest, the direction of the tangential acceleration its friction leaves it. */
static int FN(slip_directions)(const ln_model *mm, ln_data *d, struct FN(friction_work) *w, const double *X,
                               const double *U, const double *F, double *dirs)
{
    const double *n = mm->ground_normal, scale = FN(rope_velocity_scale)(mm, U);
    ln_int *starting = w->starting, m = 0;
    for (ln_int c = 0; c < mm->n_contacts; c++) {
        double *out = dirs + 3 * c;
        out[0] = out[1] = out[2] = 0.0;
        if (!FN(contact_sliding)(mm, c)) continue;
        const ln_int k = mm->contact_mass[c];
        const double *ref = d->slip_reference + 3 * c;
        double v[3], normal = 0.0, speed = 0.0, along = 0.0, ref_size = 0.0;
        for (int e = 0; e < 3; e++) normal += U[k * DIM + e] * n[e];
        for (int e = 0; e < 3; e++) {
            v[e] = U[k * DIM + e] - normal * n[e];
            speed += v[e] * v[e];
            along += v[e] * ref[e];
            ref_size += ref[e] * ref[e];
        }
        speed = ln_sqrt(speed);
        if (speed > mm->touch_tol * scale && along >= 0) {
            for (int e = 0; e < 3; e++) out[e] = v[e] / speed;
        } else if (ref_size != 0.0) {
            for (int e = 0; e < 3; e++) out[e] = ref[e];
        } else {
            starting[m++] = c;
        }
    }
    return m ? FN(starting_slip_directions)(mm, d, w, X, U, F, starting, m, dirs) : LN_OK;
}

/* The slip directions of the mode in use at (X, U) into dirs (slip_directions), with the mode's A(X) factored first
   for the solves they take. */
static int FN(factored_slip_directions)(const ln_model *mm, ln_data *d, struct FN(friction_work) *w, const double *X,
                                        const double *U, const double *F, double *dirs)
{
    const int status = accelerations(mm, d, X, U, F, d->acc1, d->T, 1);
    return status == LN_OK ? FN(slip_directions)(mm, d, w, X, U, F, dirs) : status;
}

/* The forces RATTLE kicks with at (X, U) (the contacts' anchors placed) in the mode in use (ModeDynamics.forces):
   the base forces F and the force elements (ln_scene_forces), plus the sliding contacts' friction -mu N_c d_c
   (friction_loads, along slip_directions), into out (K, DIM). refactor 0: A(X) of the mode is factored at X already
   (its solves are reused); 1: it is factored here. */
static int FN(forces_with_friction)(const ln_model *mm, ln_data *d, const double *X, const double *U, const double *F,
                                    double *out, int refactor)
{
    struct FN(friction_work) w = FN(friction_scratch)(mm, d);
    int status = refactor ? FN(factored_slip_directions)(mm, d, &w, X, U, F, w.dirs)
                          : FN(slip_directions)(mm, d, &w, X, U, F, w.dirs);
    if (status == LN_OK) status = FN(friction_loads)(mm, d, &w, X, U, F, w.dirs, w.Fb, 0);
    if (status != LN_OK) return status;
    FN(ln_scene_forces)(mm, X, U, F, out);
    for (ln_int i = 0; i < mm->K * DIM; i++) out[i] += w.Fb[i];
    return LN_OK;
}

/* The accelerations and tensions of the mode in use at (X, U) (driven rows and the contacts' anchors placed), F the
   base forces: with friction on the ground, the sliding contacts' friction included (ModeDynamics.accelerations);
   without, accelerations() itself. */
static int FN(mode_accelerations)(const ln_model *mm, ln_data *d, const double *X, const double *U, const double *F,
                                  double *acc, double *T, int refactor)
{
    if (!FN(any_sliding)(mm)) return accelerations(mm, d, X, U, F, acc, T, refactor);
    struct FN(friction_work) w = FN(friction_scratch)(mm, d);
    if (refactor) {  /* the mode's factorisation at X, which every solve below reuses */
        const int status = accelerations(mm, d, X, U, F, acc, T, 1);
        if (status != LN_OK) return status;
    }
    int status = FN(slip_directions)(mm, d, &w, X, U, F, w.dirs);
    if (status != LN_OK) return status;
    return FN(friction_evaluate)(mm, d, &w, X, U, F, w.dirs, acc, T, 0);
}

/* The longest step an explicit method may take from (U, T: the velocities and the mode's tensions at the step's
   start) while contacts slide (the reference's AdaptiveEvents._step_cap). A sliding contact's friction -mu N v_t/|v_t|
   damps its velocity across the slip at the rate mu N w / |v_t| (w the inverse mass of the contact along the plane,
   taken as 1/M_k: the constraints of the mode only lower it, and it is exact for a mass alone and across a rod's
   end), a stiff mode where the slip is slow; an explicit method is stable on it while h times that rate is within
   its stability interval on the negative real axis. The speed counts from the slowest slip whose direction the step
   resolves: touch_tol of the velocity scale (below it the friction keeps the step's reference, slip_directions), and
   the error control's own scale atol + rtol |U_k|. A slip that does not turn (the sine of the angle between its
   velocity and its acceleration along the plane at most straight_slip) is spared: its motion across it is round-off
   that stays so (a slip in a plane). No contact sliding: INFINITY. */
static double FN(slip_step_cap)(const ln_model *mm, const ln_method *meth, const double *U, const double *acc,
                                const double *T)
{
    double cap = INFINITY;
    if (!mm->n_grips || !(meth->stiff_safety > 0.0)) return cap;
    const double *n = mm->ground_normal, slowest = mm->touch_tol * FN(rope_velocity_scale)(mm, U);
    for (ln_int c = 0; c < mm->n_contacts; c++) {
        if (!FN(contact_sliding)(mm, c)) continue;
        const ln_int k = mm->contact_mass[c];
        const double N = T[FN(contact_link)(mm, c)];
        if (!(N > 0.0)) continue;
        double normal = 0.0, normal_acc = 0.0, speed = 0.0, size = 0.0, along = 0.0;
        double v[3] = {0.0, 0.0, 0.0}, a[3] = {0.0, 0.0, 0.0};
        for (int e = 0; e < DIM; e++) {
            normal += U[k * DIM + e] * n[e];
            normal_acc += acc[k * DIM + e] * n[e];
        }
        for (int e = 0; e < DIM; e++) {
            v[e] = U[k * DIM + e] - normal * n[e];
            a[e] = acc[k * DIM + e] - normal_acc * n[e];
            speed += v[e] * v[e];
            along += a[e] * a[e];
            size += U[k * DIM + e] * U[k * DIM + e];
        }
        /* a slip its acceleration does not turn (in a plane, or turned by round-off) has no motion across it */
        const double turn = (v[1] * a[2] - v[2] * a[1]) * n[0] + (v[2] * a[0] - v[0] * a[2]) * n[1]
                            + (v[0] * a[1] - v[1] * a[0]) * n[2];
        if (!(fabs(turn) > meth->straight_slip * ln_sqrt(speed * along))) continue;
        const double resolved = meth->atol + meth->rtol * ln_sqrt(size);
        const double rate = mm->friction * N * mm->inv_m[k] / ln_fmax(ln_sqrt(speed), ln_fmax(slowest, resolved));
        cap = ln_fmin(cap, meth->stiff_safety * meth->real_stability / rate);
    }
    return cap;
}

/* What the step loops and the events evaluate: mode_accelerations where the model has friction, else
   accelerations() inlined. */
LN_ALWAYS_INLINE int FN(stage_accelerations)(const ln_model *mm, ln_data *d, const double *X, const double *U,
                                             const double *F, double *acc, double *T, int refactor)
{
    return mm->n_grips ? FN(mode_accelerations)(mm, d, X, U, F, acc, T, refactor)
                       : accelerations(mm, d, X, U, F, acc, T, refactor);
}

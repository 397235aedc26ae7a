/* The supernodal numeric LDL^T (engine_ldl.c), compiled there twice: portably, and for x86-64 processors
 * with AVX2, whose wider vectors the dense kernels use. No include guard: engine_ldl.c includes it once per
 * target with LDL_FN(name) naming that copy and LDL_TARGET its target attribute. Both copies perform the
 * same floating-point operations in the same order (no FMA contraction, no reassociation), so they give
 * bitwise the same factorisation.
 */

/* C(rows, 0:JB) -= A(0:R, 0:k) B^T with B packed as bp[4 c + j]: the tile's products accumulate in
   registers, each load of A feeding JB multiply-adds, and are subtracted from column jj of C at cp[jj],
   rows 0..R-1 there, or rows ri[0..R-1] if ri is given. R <= TILE_ROWS and JB <= 4 are constants where it
   is called. */
LDL_TARGET static inline void LDL_FN(tile)(const int R, const int JB, ln_int k, const double *restrict A,
                                           ln_int lda, const double *restrict bp, double *const *cp,
                                           const ln_int *ri)
{
    double acc[4][TILE_ROWS];
    for (int jj = 0; jj < JB; jj++)
        for (int ii = 0; ii < R; ii++) acc[jj][ii] = 0.0;
    for (ln_int c = 0; c < k; c++) {
        const double *a = A + c * lda, *b = bp + 4 * c;
        for (int jj = 0; jj < JB; jj++)
            for (int ii = 0; ii < R; ii++) acc[jj][ii] += a[ii] * b[jj];
    }
    for (int jj = 0; jj < JB; jj++) {
        double *c = cp[jj];
        if (ri)
            for (int ii = 0; ii < R; ii++) c[ri[ii]] -= acc[jj][ii];
        else
            for (int ii = 0; ii < R; ii++) c[ii] -= acc[jj][ii];
    }
}

/* One band of R rows starting at row i0 of syrk_lower_sub below, for the band's column count jb. */
LDL_TARGET static inline void LDL_FN(band)(const int R, int jb, ln_int k, const double *A, ln_int lda,
                                           const double *bp, double *const *cols, ln_int i0, const ln_int *rel)
{
    double *cp[4];
    const ln_int *ri = rel ? rel + i0 : NULL;
    for (int jj = 0; jj < 4; jj++) cp[jj] = rel ? cols[jj] : cols[jj] + i0;
    switch (jb) {
    case 1: LDL_FN(tile)(R, 1, k, A + i0, lda, bp, cp, ri); break;
    case 2: LDL_FN(tile)(R, 2, k, A + i0, lda, bp, cp, ri); break;
    case 3: LDL_FN(tile)(R, 3, k, A + i0, lda, bp, cp, ri); break;
    default: LDL_FN(tile)(R, 4, k, A + i0, lda, bp, cp, ri); break;
    }
}

/* C -= A D A(0:nc, :)^T on the lower part: for 0 <= j < nc, j <= i < m (A is m x k, column-major)
   entry (i, j) of C, at C[i + j ldc], or at C[rel[i] + rel[j] ldc] if rel is given (rows and columns of a
   supernode that receive a descendant's update), takes -sum_c A[i + c lda] D[c] A[j + c lda]. Four columns
   of D A^T at a time are packed into bp (4 k values), then swept down the rows in register tiles; tiles on
   the diagonal also update a few entries above it (i < j), which land in the upper triangle of the
   supernode's diagonal block, never read. */
LDL_TARGET static void LDL_FN(syrk_lower_sub)(ln_int m, ln_int nc, ln_int k, const double *A, ln_int lda,
                                              const double *D, double *C, ln_int ldc, const ln_int *rel,
                                              double *restrict bp)
{
    for (ln_int j0 = 0; j0 < nc; j0 += 4) {
        const int jb = nc - j0 < 4 ? (int) (nc - j0) : 4;
        for (ln_int c = 0; c < k; c++) {
            const double *a = A + c * lda + j0;
            for (int jj = 0; jj < 4; jj++) bp[4 * c + jj] = jj < jb ? a[jj] * D[c] : 0.0;
        }
        double *cols[4];
        for (int jj = 0; jj < 4; jj++) cols[jj] = C + (jj < jb ? (rel ? rel[j0 + jj] : j0 + jj) : 0) * ldc;
        ln_int i0 = j0;
        for (; i0 + TILE_ROWS <= m; i0 += TILE_ROWS) LDL_FN(band)(TILE_ROWS, jb, k, A, lda, bp, cols, i0, rel);
        if (TILE_ROWS > 4 && i0 + 4 <= m) {
            LDL_FN(band)(4, jb, k, A, lda, bp, cols, i0, rel);
            i0 += 4;
        }
        if (i0 + 2 <= m) {
            LDL_FN(band)(2, jb, k, A, lda, bp, cols, i0, rel);
            i0 += 2;
        }
        if (i0 < m) LDL_FN(band)(1, jb, k, A, lda, bp, cols, i0, rel);
    }
}

/* Subtract from supernode t's block (Xt, nrow rows, local row of each row index in map) the update of
   descendant d: rows rd[0..n2) of d's block Xd (leading dimension ldd, ncd columns, pivots Dd), of which the
   first n1 lie in t's columns. The update is L_d(rows, :) D_d L_d(rows in t, :)^T, subtracted in place
   through the local rows rel of d's rows in t (a local row in t's first ncol rows is also t's local
   column). */
LDL_TARGET static void LDL_FN(update_from)(const double *Xd, ln_int ldd, ln_int ncd, const double *Dd,
                                           const ln_int *rd, ln_int n1, ln_int n2, double *Xt, ln_int nrow,
                                           const ln_int *map, ln_int *rel, double *bp)
{
    int consecutive = 1;
    for (ln_int i = 0; i < n2; i++) {
        rel[i] = map[rd[i]];
        consecutive &= rel[i] == rel[0] + i;
    }
    if (consecutive) LDL_FN(syrk_lower_sub)(n2, n1, ncd, Xd, ldd, Dd, Xt + rel[0] * (nrow + 1), nrow, NULL, bp);
    else LDL_FN(syrk_lower_sub)(n2, n1, ncd, Xd, ldd, Dd, Xt, nrow, rel, bp);
}

/* LDL^T of a supernode's block in place (nrow x ncol, column-major), pivots into D, Dinv: panels of PANEL
   columns, each updated by the panels before it (syrk_lower_sub), then factored column by column. A zeroed
   pivot leaves a zero column below it, so it updates nothing after it. */
LDL_TARGET static ln_int LDL_FN(factor_block)(double *X, ln_int nrow, ln_int ncol, const double *Adiag,
                                              double pivot_tol, double *D, double *Dinv, double *bp)
{
    ln_int bad = -1;
    for (ln_int c0 = 0; c0 < ncol; c0 += PANEL) {
        const ln_int c1 = ncol - c0 < PANEL ? ncol : c0 + PANEL;
        if (c0 > 0)
            LDL_FN(syrk_lower_sub)(nrow - c0, c1 - c0, c0, X + c0, nrow, D, X + c0 + c0 * nrow, nrow, NULL, bp);
        /* within the panel, left-looking: column j takes the updates of the panel's columns before it,
           four at a time, then its pivot */
        for (ln_int j = c0; j < c1; j++) {
            double *cj = X + j * nrow;
            ln_int k = c0;
            for (; k + 4 <= j; k += 4) {
                const double *a0 = X + k * nrow, *a1 = a0 + nrow, *a2 = a1 + nrow, *a3 = a2 + nrow;
                const double u0 = a0[j] * D[k], u1 = a1[j] * D[k + 1], u2 = a2[j] * D[k + 2], u3 = a3[j] * D[k + 3];
                for (ln_int i = j; i < nrow; i++) cj[i] -= a0[i] * u0 + a1[i] * u1 + a2[i] * u2 + a3[i] * u3;
            }
            for (; k < j; k++) {
                const double *a = X + k * nrow;
                const double u = a[j] * D[k];
                for (ln_int i = j; i < nrow; i++) cj[i] -= a[i] * u;
            }
            const double dj = cj[j];
            double dinv;
            if (!(dj > pivot_tol * fabs(Adiag[j]))) {
                if (bad == -1) bad = j;
                dinv = 0.0;
            } else {
                dinv = 1.0 / dj;
            }
            D[j] = dj;
            Dinv[j] = dinv;
            for (ln_int i = j + 1; i < nrow; i++) cj[i] *= dinv;
        }
    }
    return bad;
}

/* Left-looking supernodal LDL^T: each supernode in elimination order is assembled from the pairs (its block
   is zeroed and the pair values added just before it is used), receives the updates of its descendants
   (kept in linked lists keyed by the next supernode each one updates, as in CHOLMOD), and is factored. */
LDL_TARGET static ln_int LDL_FN(factor_supernodal)(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f,
                                                   const double *pair_values, double pivot_tol)
{
    const ln_int ns = s->n_super;
    const ln_int *first = s->super_first, *row_ptr = s->row_ptr, *rows = s->rows, *x_ptr = s->x_ptr;
    const ln_int *pair_ptr = s->super_pair_ptr, *pair_index = s->super_pair_index, *pair_slot = s->pair_slot;
    double *Lx = f->Lx, *D = f->D, *Dinv = f->Dinv, *Adiag = f->Adiag;
    ln_int *head = f->head, *next = f->next, *lpos = f->lpos, *map = f->map;
    for (ln_int t = 0; t < ns; t++) head[t] = -1;
    ln_int bad = -1;
    for (ln_int t = 0; t < ns; t++) {
        const ln_int fc = first[t], lc = first[t + 1], ncol = lc - fc;
        const ln_int r0 = row_ptr[t], nrow = row_ptr[t + 1] - r0;
        double *Xt = Lx + x_ptr[t];
        memset(Xt, 0, (size_t) (nrow * ncol) * sizeof(double));
        for (ln_int q = pair_ptr[t]; q < pair_ptr[t + 1]; q++) Xt[pair_slot[q]] += pair_values[pair_index[q]];
        for (ln_int k = 0; k < ncol; k++) Adiag[fc + k] = Xt[k * (nrow + 1)];
        for (ln_int q = 0; q < nrow; q++) map[rows[r0 + q]] = q;
        for (ln_int d = head[t]; d >= 0;) {
            const ln_int dnext = next[d];
            const ln_int pd = lpos[d], pend = row_ptr[d + 1];
            ln_int p = pd;
            while (p < pend && rows[p] < lc) p++;
            const ln_int ldd = row_ptr[d + 1] - row_ptr[d], ncd = first[d + 1] - first[d];
            LDL_FN(update_from)(Lx + x_ptr[d] + (pd - row_ptr[d]), ldd, ncd, D + first[d], rows + pd, p - pd,
                                pend - pd, Xt, nrow, map, f->rel, f->pack);
            if (p < pend) {
                const ln_int owner = s->col_super[rows[p]];
                lpos[d] = p;
                next[d] = head[owner];
                head[owner] = d;
            }
            d = dnext;
        }
        const ln_int b = LDL_FN(factor_block)(Xt, nrow, ncol, Adiag + fc, pivot_tol, D + fc, Dinv + fc, f->pack);
        if (b >= 0 && bad == -1) bad = fc + b;
        if (ncol < nrow) {
            const ln_int owner = s->col_super[rows[r0 + ncol]];
            lpos[t] = r0 + ncol;
            next[t] = head[owner];
            head[owner] = t;
        }
    }
    return bad;
}

/* Sparse LDL^T: symbolic analysis once per scene, numeric factorisation and solves every step (ldl.h). */
#include <stdlib.h>

#include "ldl.h"

struct ln_ldl_symbolic {
    ln_int n, n_pairs;
    ln_int *ordering;               /* (n) elimination position -> index */
    ln_int *pair_slot;              /* (n_pairs) slot of each pair in the upper CSC values Ax */
    ln_int *Ap, *Ai;                /* upper triangle of P A P^T, CSC, diagonal included */
    ln_int nnz_A;
    ln_int *Lp, *Li;                /* strictly lower pattern of L, CSC */
    ln_int nnz_L;
    ln_int *row_start, *row_col, *row_slot;  /* for column k, the columns c updating it and the slot of L(k,c) */
};

struct ln_ldl_numeric {
    double *Ax, *Lx, *D, *Dinv, *y, *x;
};

static void *alloc(size_t count, size_t size) { return calloc(count ? count : 1, size); }

void ln_ldl_symbolic_free(struct ln_ldl_symbolic *s)
{
    if (!s) return;
    free(s->ordering); free(s->pair_slot); free(s->Ap); free(s->Ai); free(s->Lp); free(s->Li);
    free(s->row_start); free(s->row_col); free(s->row_slot);
    free(s);
}

/* Elimination tree and column counts of L for the upper CSC pattern (QDLDL's etree). */
static void elimination_tree(ln_int n, const ln_int *Ap, const ln_int *Ai, ln_int *etree, ln_int *Lnz,
                             ln_int *work)
{
    for (ln_int j = 0; j < n; j++) {
        work[j] = j;
        Lnz[j] = 0;
        etree[j] = -1;
    }
    for (ln_int j = 0; j < n; j++) {
        for (ln_int p = Ap[j]; p < Ap[j + 1]; p++) {
            ln_int i = Ai[p];
            while (work[i] != j) {
                if (etree[i] == -1) etree[i] = j;
                Lnz[i]++;
                work[i] = j;
                i = etree[i];
            }
        }
    }
}

/* Append to y_idx[nnz_y:] the unmarked columns on the elimination-tree path from bidx towards k, marking
   them, in the order column k's factorisation takes them (QDLDL's symbolic step). */
static ln_int reach(ln_int bidx, ln_int k, const ln_int *etree, ln_int *marker, ln_int *buffer, ln_int *y_idx,
                    ln_int nnz_y)
{
    marker[bidx] = 1;
    buffer[0] = bidx;
    ln_int nnz_e = 1;
    ln_int next = etree[bidx];
    while (next != -1 && next < k) {
        if (marker[next]) break;
        marker[next] = 1;
        buffer[nnz_e++] = next;
        next = etree[next];
    }
    while (nnz_e > 0) y_idx[nnz_y++] = buffer[--nnz_e];
    return nnz_y;
}

/* The pattern of the upper triangle of P A P^T in CSC form and the slot of every pair in it. */
static int permuted_pattern(struct ln_ldl_symbolic *s, const ln_int *pair_first, const ln_int *pair_second)
{
    const ln_int n = s->n, np = s->n_pairs;
    ln_int *position = alloc(n, sizeof(ln_int));
    ln_int *count = alloc(n + 1, sizeof(ln_int));
    ln_int *row = alloc(np, sizeof(ln_int)), *col = alloc(np, sizeof(ln_int));
    ln_int *by_col = alloc(np, sizeof(ln_int));
    ln_int *mark = alloc(n, sizeof(ln_int));
    int ok = position && count && row && col && by_col && mark;
    if (ok) {
        for (ln_int i = 0; i < n; i++) position[s->ordering[i]] = i;
        for (ln_int p = 0; p < np; p++) {
            ln_int a = position[pair_first[p]], b = position[pair_second[p]];
            row[p] = a < b ? a : b;
            col[p] = a < b ? b : a;
            count[col[p] + 1]++;
        }
        for (ln_int j = 0; j < n; j++) count[j + 1] += count[j];
        for (ln_int p = 0; p < np; p++) by_col[count[col[p]]++] = p;  /* pairs grouped by column */
        for (ln_int j = n; j > 0; j--) count[j] = count[j - 1];
        count[0] = 0;
        /* unique rows per column, ascending: mark[row] = slot + 1 while the column is being built */
        s->Ap = alloc(n + 1, sizeof(ln_int));
        s->Ai = alloc(np, sizeof(ln_int));
        ok = s->Ap && s->Ai;
        ln_int nnz = 0;
        for (ln_int j = 0; ok && j < n; j++) {
            s->Ap[j] = nnz;
            ln_int first = nnz;
            for (ln_int q = count[j]; q < count[j + 1]; q++) {
                ln_int r = row[by_col[q]];
                if (mark[r] == 0) {
                    /* insertion into the sorted rows of this column (columns hold few entries) */
                    ln_int at = nnz++;
                    while (at > first && s->Ai[at - 1] > r) {
                        s->Ai[at] = s->Ai[at - 1];
                        mark[s->Ai[at]] = at + 1;
                        at--;
                    }
                    s->Ai[at] = r;
                    mark[r] = at + 1;
                }
            }
            for (ln_int q = count[j]; q < count[j + 1]; q++) s->pair_slot[by_col[q]] = mark[row[by_col[q]]] - 1;
            for (ln_int q = first; q < nnz; q++) mark[s->Ai[q]] = 0;
        }
        if (ok) {
            s->Ap[n] = nnz;
            s->nnz_A = nnz;
        }
    }
    free(position); free(count); free(row); free(col); free(by_col); free(mark);
    return ok;
}

static int schedule(struct ln_ldl_symbolic *s)
{
    const ln_int n = s->n;
    ln_int *etree = alloc(n, sizeof(ln_int)), *Lnz = alloc(n, sizeof(ln_int)), *work = alloc(4 * n, sizeof(ln_int));
    int ok = etree && Lnz && work;
    if (ok) {
        elimination_tree(n, s->Ap, s->Ai, etree, Lnz, work);
        s->Lp = alloc(n + 1, sizeof(ln_int));
        ok = s->Lp != NULL;
    }
    if (ok) {
        for (ln_int j = 0; j < n; j++) s->Lp[j + 1] = s->Lp[j] + Lnz[j];
        s->nnz_L = s->Lp[n];
        s->Li = alloc(s->nnz_L, sizeof(ln_int));
        s->row_start = alloc(n + 1, sizeof(ln_int));
        s->row_col = alloc(s->nnz_L, sizeof(ln_int));
        s->row_slot = alloc(s->nnz_L, sizeof(ln_int));
        ok = s->Li && s->row_start && s->row_col && s->row_slot;
    }
    if (ok) {
        ln_int *marker = work, *y_idx = work + n, *buffer = work + 2 * n, *next = work + 3 * n;
        for (ln_int k = 0; k < n; k++) {
            marker[k] = 0;
            next[k] = s->Lp[k];  /* next free slot of each column of L */
        }
        ln_int q = 0;
        for (ln_int k = 0; k < n; k++) {
            ln_int nnz_y = 0;
            for (ln_int p = s->Ap[k]; p < s->Ap[k + 1]; p++) {
                ln_int bidx = s->Ai[p];
                if (bidx == k || marker[bidx]) continue;
                nnz_y = reach(bidx, k, etree, marker, buffer, y_idx, nnz_y);
            }
            for (ln_int i = nnz_y - 1; i >= 0; i--) {
                ln_int c = y_idx[i];
                ln_int slot = next[c]++;
                s->row_col[q] = c;
                s->row_slot[q] = slot;
                s->Li[slot] = k;
                marker[c] = 0;
                q++;
            }
            s->row_start[k + 1] = q;
        }
    }
    free(etree); free(Lnz); free(work);
    return ok;
}

struct ln_ldl_symbolic *ln_ldl_analyse(ln_int n, ln_int n_pairs, const ln_int *pair_first, const ln_int *pair_second,
                                       const ln_int *ordering)
{
    struct ln_ldl_symbolic *s = alloc(1, sizeof *s);
    if (!s) return NULL;
    s->n = n;
    s->n_pairs = n_pairs;
    s->ordering = alloc(n, sizeof(ln_int));
    s->pair_slot = alloc(n_pairs, sizeof(ln_int));
    ln_int *seen = alloc(n, sizeof(ln_int));
    int ok = s->ordering && s->pair_slot && seen && ordering != NULL;
    for (ln_int i = 0; ok && i < n; i++) {
        ln_int k = ordering[i];
        if (k < 0 || k >= n || seen[k]) ok = 0;
        else seen[k] = 1, s->ordering[i] = k;
    }
    for (ln_int p = 0; ok && p < n_pairs; p++)
        if (pair_first[p] < 0 || pair_first[p] >= n || pair_second[p] < 0 || pair_second[p] >= n) ok = 0;
    free(seen);
    if (ok) ok = permuted_pattern(s, pair_first, pair_second) && schedule(s);
    if (!ok) {
        ln_ldl_symbolic_free(s);
        return NULL;
    }
    return s;
}

ln_int ln_ldl_nnz_L(const struct ln_ldl_symbolic *s) { return s->nnz_L; }

void ln_ldl_get_ordering(const struct ln_ldl_symbolic *s, ln_int *ordering)
{
    for (ln_int i = 0; i < s->n; i++) ordering[i] = s->ordering[i];
}

struct ln_ldl_numeric *ln_ldl_numeric_new(const struct ln_ldl_symbolic *s)
{
    struct ln_ldl_numeric *f = alloc(1, sizeof *f);
    if (!f) return NULL;
    f->Ax = alloc(s->nnz_A, sizeof(double));
    f->Lx = alloc(s->nnz_L, sizeof(double));
    f->D = alloc(s->n, sizeof(double));
    f->Dinv = alloc(s->n, sizeof(double));
    f->y = alloc(s->n, sizeof(double));
    f->x = alloc(s->n, sizeof(double));
    if (!(f->Ax && f->Lx && f->D && f->Dinv && f->y && f->x)) {
        ln_ldl_numeric_free(f);
        return NULL;
    }
    return f;
}

void ln_ldl_numeric_free(struct ln_ldl_numeric *f)
{
    if (!f) return;
    free(f->Ax); free(f->Lx); free(f->D); free(f->Dinv); free(f->y); free(f->x);
    free(f);
}

ln_int ln_ldl_factor(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *pair_values,
                     double pivot_tol)
{
    const ln_int n = s->n;
    const ln_int *Ap = s->Ap, *Ai = s->Ai, *Lp = s->Lp, *Li = s->Li;
    const ln_int *row_start = s->row_start, *row_col = s->row_col, *row_slot = s->row_slot;
    double *Ax = f->Ax, *Lx = f->Lx, *D = f->D, *Dinv = f->Dinv, *y = f->y;
    for (ln_int p = 0; p < s->nnz_A; p++) Ax[p] = 0.0;
    for (ln_int p = 0; p < s->n_pairs; p++) Ax[s->pair_slot[p]] += pair_values[p];
    ln_int bad = -1;
    for (ln_int k = 0; k < n; k++) {
        double diag = 0.0;
        for (ln_int p = Ap[k]; p < Ap[k + 1]; p++) {
            ln_int i = Ai[p];
            if (i == k) diag = Ax[p];
            else y[i] = Ax[p];
        }
        double dk = diag;
        for (ln_int q = row_start[k]; q < row_start[k + 1]; q++) {
            ln_int c = row_col[q], slot = row_slot[q];
            double yc = y[c];
            for (ln_int j = Lp[c]; j < slot; j++) y[Li[j]] -= Lx[j] * yc;
            double lx = yc * Dinv[c];
            Lx[slot] = lx;
            dk -= yc * lx;
            y[c] = 0.0;
        }
        D[k] = dk;
        if (!(dk > pivot_tol * (diag < 0 ? -diag : diag))) {
            if (bad == -1) bad = k;
            Dinv[k] = 0.0;
        } else {
            Dinv[k] = 1.0 / dk;
        }
    }
    return bad;
}

void ln_ldl_solve(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *b, double *out)
{
    const ln_int n = s->n;
    const ln_int *Lp = s->Lp, *Li = s->Li, *ordering = s->ordering;
    const double *Lx = f->Lx, *Dinv = f->Dinv;
    double *x = f->x;
    for (ln_int i = 0; i < n; i++) x[i] = b[ordering[i]];
    for (ln_int i = 0; i < n; i++) {
        double xi = x[i];
        for (ln_int j = Lp[i]; j < Lp[i + 1]; j++) x[Li[j]] -= Lx[j] * xi;
    }
    for (ln_int i = 0; i < n; i++) x[i] *= Dinv[i];
    for (ln_int i = n - 1; i >= 0; i--) {
        double sum = x[i];
        for (ln_int j = Lp[i]; j < Lp[i + 1]; j++) sum -= Lx[j] * x[Li[j]];
        x[i] = sum;
    }
    for (ln_int i = 0; i < n; i++) out[ordering[i]] = x[i];
}

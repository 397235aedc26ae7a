/* Sparse LDL^T of the tension matrix A (25): symbolic analysis once per scene, numeric factorisation and
 * solves every step (ldl.h).
 *
 * Two numeric algorithms share one symbolic front end (ordering, pattern of P A P^T, elimination tree,
 * column counts of L); the analysis picks one from the counts:
 *
 * - columns: QDLDL's up-looking algorithm (Stellato, Banjac et al., Apache-2.0) with its symbolic part
 *   replayed once into a schedule. It touches only the non-zeros of L and has almost no overhead per
 *   column, so it is the choice where L has few entries per column: chains and trees in a leaves-first
 *   order (no fill, O(L)) and small general scenes.
 * - supernodal: where a fill-reducing ordering still leaves dense blocks in L (large nets), columns with
 *   the same pattern below their diagonal block are grouped into supernodes (fundamental supernodes,
 *   then a light relaxed amalgamation), stored as dense column-major blocks and factored
 *   left-looking: every supernode receives the dense updates of the supernodes below it in the
 *   elimination tree, then factors its own block. The inner loops run over contiguous memory with few
 *   index loads, and the solves work per block.
 *
 * Both produce the same factorisation up to round-off, with the same pivot rule: a pivot d_k that is not
 * above pivot_tol |A_kk| is zeroed (D^-1 = 0 and the column of L below it is zero), which is what lets the
 * caller detect a singular configuration of (25) and switch to minimum-norm tensions.
 *
 * Without a given ordering the analysis orders the pattern with AMD (vendored in amd/, BSD-3-Clause).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ldl.h"
#include "amd/amd.h"

/* On x86 with GCC or Clang the supernodal factorisation is also compiled for AVX2 and chosen at run time
   when the processor has it (bitwise the same results, its factorisation of a 100 x 100 net about 25 %
   faster). */
#if !defined(LN_LDL_PORTABLE) && (defined(__x86_64__) || defined(__i386__)) && \
    ((defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 6) || (defined(__clang__) && __clang_major__ >= 7))
#define LN_LDL_AVX2 1
#else
#define LN_LDL_AVX2 0
#endif

/* Average entries per column of L below the diagonal from which the supernodal algorithm pays for its
   per-block overhead. Chains and trees have at most a few. In the AMD order (factor + 2 solves, measured):
   net_10x10 has 7.9 and a 15 x 15 net 10.2 (columns 40 % and 10 % faster), a 20 x 20 net 12.1 (supernodal
   12 % faster), a 100 x 100 net 24 (supernodal 3x faster). */
#define SUPERNODAL_MIN_MEAN_COUNT 11.0

/* Relaxed amalgamation: a supernode merges with its parent (when the parent starts right after it) if the
   merged block has at most this many columns, or if merging adds no explicit zero. CHOLMOD's larger
   thresholds (up to 48 columns with 5-80 % zeros) measured slower here, in the factorisation and more in
   the solves, which read every stored zero. */
#define RELAX_COLUMNS 4

/* Columns of a supernode factored at once before the rest of the supernode is updated with them. */
#define PANEL 16

struct ln_ldl_symbolic {
    ln_int n, n_pairs;
    ln_int *ordering;               /* (n) elimination position -> index */
    ln_int nnz_L;                   /* structural entries of L below the diagonal */
    double flops;                   /* multiply-adds of one numeric factorisation (column counts) */
    int supernodal;
    int vector_kernels;             /* the supernodal factorisation's AVX2 copy */
    /* the numeric algorithm, called through pointers: inlined into one entry point together, the column
       algorithm measured 5-10 % slower */
    ln_int (*factor)(const struct ln_ldl_symbolic *, struct ln_ldl_numeric *, const double *, double);
    void (*solve)(const struct ln_ldl_symbolic *, const struct ln_ldl_numeric *, double *);
    ln_int *pair_slot;              /* (n_pairs) slot of each pair: in Ax (columns) or in Lx (supernodal) */

    /* columns */
    ln_int *Ap, *Ai;                /* upper triangle of P A P^T, CSC, diagonal included */
    ln_int nnz_A;
    ln_int *Lp, *Li;                /* strictly lower pattern of L, CSC */
    ln_int *row_start, *row_col, *row_slot;  /* for column k, the columns c updating it and the slot of L(k,c) */

    /* supernodal */
    ln_int n_super;
    ln_int *super_first;            /* (n_super + 1) first column of each supernode */
    ln_int *row_ptr;                /* (n_super + 1) rows of supernode s: rows[row_ptr[s] .. row_ptr[s+1]) */
    ln_int *rows;                   /* the supernode's own columns first, then the rows below, ascending */
    ln_int *x_ptr;                  /* (n_super + 1) block of s in Lx: nrow x ncol, column-major */
    ln_int *col_super;              /* (n) supernode of each column */
    ln_int *super_pair_ptr;         /* (n_super + 1) the pairs of supernode s: super_pair_ptr[s] .. [s+1] */
    ln_int *super_pair_index;       /* (n_pairs) pairs grouped by supernode; pair_slot (same order) is the
                                       slot in the supernode's block */
    ln_int nnz_stored;              /* Lx entries, diagonal blocks' upper triangles and amalgamation zeros included */
    ln_int max_nrow, max_ncol;
};

struct ln_ldl_numeric {
    double *Ax, *Lx, *D, *Dinv, *x;
    double *w;                      /* columns: the row being factored; supernodal: solve buffer */
    double *Adiag;                  /* supernodal: A's diagonal (pivot test) */
    ln_int *head, *next, *lpos, *map, *rel;  /* supernodal: descendant lists, relative row positions */
    double *pack;                   /* supernodal: 4 packed columns of the dense kernels */
};

static ln_int factor_columns(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *pair_values,
                             double pivot_tol);
static void solve_columns(const struct ln_ldl_symbolic *s, const struct ln_ldl_numeric *f, double *x);
static void solve_supernodal(const struct ln_ldl_symbolic *s, const struct ln_ldl_numeric *f, double *x);

static void *alloc(size_t count, size_t size) { return calloc(count ? count : 1, size); }

void ln_ldl_symbolic_free(struct ln_ldl_symbolic *s)
{
    if (!s) return;
    free(s->ordering); free(s->pair_slot);
    free(s->Ap); free(s->Ai); free(s->Lp); free(s->Li);
    free(s->row_start); free(s->row_col); free(s->row_slot);
    free(s->super_first); free(s->row_ptr); free(s->rows); free(s->x_ptr); free(s->col_super);
    free(s->super_pair_ptr); free(s->super_pair_index);
    free(s);
}

/* ---- the supernodal numeric factorisation, portable and AVX2 ---------------------------------------- */

/* TILE_ROWS: rows of one register tile of the dense kernels (columns: 4), enough independent sums to hide
   the latency of the additions: 8 two-double vectors (SSE2), or 8 four-double vectors (AVX2). */
#define LDL_FN(name) name##_generic
#define LDL_TARGET
#define TILE_ROWS 4
#include "engine_ldl_supernodal.h"
#undef LDL_FN
#undef LDL_TARGET
#undef TILE_ROWS

#if LN_LDL_AVX2
#define LDL_FN(name) name##_avx2
#define LDL_TARGET __attribute__((target("avx2")))
#define TILE_ROWS 8
#include "engine_ldl_supernodal.h"
#undef LDL_FN
#undef LDL_TARGET
#undef TILE_ROWS
#endif

static int use_vector_kernels = 1;

int ln_ldl_vector_kernels(int enable)
{
    if (enable >= 0) use_vector_kernels = enable != 0;
#if LN_LDL_AVX2
    __builtin_cpu_init();
    return use_vector_kernels && __builtin_cpu_supports("avx2");
#else
    return 0;
#endif
}

/* ---- symbolic front end -------------------------------------------------------------------------- */

/* AMD on the pattern of the pairs (both triangles, no diagonal, no duplicates, rows ascending). */
static int amd_ordering(ln_int n, ln_int np, const ln_int *first, const ln_int *second, ln_int *ordering)
{
    ln_int *count = alloc(n + 1, sizeof(ln_int)), *Ap = alloc(n + 1, sizeof(ln_int));
    ln_int *Ai = alloc(2 * np, sizeof(ln_int)), *mark = alloc(n, sizeof(ln_int));
    int ok = count && Ap && Ai && mark;
    if (ok) {
        for (ln_int p = 0; p < np; p++)
            if (first[p] != second[p]) count[first[p]]++, count[second[p]]++;
        for (ln_int j = 0; j < n; j++) Ap[j + 1] = Ap[j] + count[j];
        for (ln_int j = 0; j < n; j++) count[j] = Ap[j];
        for (ln_int p = 0; p < np; p++) {
            ln_int a = first[p], b = second[p];
            if (a == b) continue;
            Ai[count[a]++] = b;
            Ai[count[b]++] = a;
        }
        /* sort and deduplicate each column in place (columns hold few entries) */
        ln_int nnz = 0;
        for (ln_int j = 0; j < n; j++) mark[j] = -1;
        for (ln_int j = 0; j < n; j++) {
            ln_int start = nnz, begin = Ap[j], end = Ap[j + 1];
            for (ln_int q = begin; q < end; q++) {
                ln_int r = Ai[q];
                if (mark[r] == j) continue;
                mark[r] = j;
                ln_int at = nnz++;
                while (at > start && Ai[at - 1] > r) {
                    Ai[at] = Ai[at - 1];
                    at--;
                }
                Ai[at] = r;
            }
            Ap[j] = start;
        }
        Ap[n] = nnz;
        int status = amd_l_order(n, Ap, Ai, ordering, NULL, NULL);
        ok = status == AMD_OK || status == AMD_OK_BUT_JUMBLED;
    }
    free(count); free(Ap); free(Ai); free(mark);
    return ok;
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

/* Elimination tree and column counts of L (below the diagonal) for the upper CSC pattern (QDLDL's etree). */
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

/* ---- columns: the schedule of the up-looking factorisation --------------------------------------- */

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

static int column_schedule(struct ln_ldl_symbolic *s, const ln_int *etree, const ln_int *Lnz)
{
    const ln_int n = s->n;
    ln_int *work = alloc(3 * n, sizeof(ln_int));
    s->Lp = alloc(n + 1, sizeof(ln_int));
    int ok = work && s->Lp;
    if (ok) {
        for (ln_int j = 0; j < n; j++) s->Lp[j + 1] = s->Lp[j] + Lnz[j];
        s->Li = alloc(s->nnz_L, sizeof(ln_int));
        s->row_start = alloc(n + 1, sizeof(ln_int));
        s->row_col = alloc(s->nnz_L, sizeof(ln_int));
        s->row_slot = alloc(s->nnz_L, sizeof(ln_int));
        ok = s->Li && s->row_start && s->row_col && s->row_slot;
    }
    if (ok) {
        ln_int *marker = work, *y_idx = work + n, *buffer = work + 2 * n;
        ln_int *next_slot = alloc(n, sizeof(ln_int));  /* next free slot of each column of L */
        ok = next_slot != NULL;
        for (ln_int k = 0; ok && k < n; k++) {
            marker[k] = 0;
            next_slot[k] = s->Lp[k];
        }
        ln_int q = 0;
        for (ln_int k = 0; ok && k < n; k++) {
            ln_int nnz_y = 0;
            for (ln_int p = s->Ap[k]; p < s->Ap[k + 1]; p++) {
                ln_int bidx = s->Ai[p];
                if (bidx == k || marker[bidx]) continue;
                nnz_y = reach(bidx, k, etree, marker, buffer, y_idx, nnz_y);
            }
            for (ln_int i = nnz_y - 1; i >= 0; i--) {
                ln_int c = y_idx[i];
                ln_int slot = next_slot[c]++;
                s->row_col[q] = c;
                s->row_slot[q] = slot;
                s->Li[slot] = k;
                marker[c] = 0;
                q++;
            }
            s->row_start[k + 1] = q;
        }
        free(next_slot);
    }
    free(work);
    return ok;
}

/* ---- supernodal: partition, row patterns, block layout ------------------------------------------- */

static int compare_int(const void *a, const void *b)
{
    ln_int x = *(const ln_int *) a, y = *(const ln_int *) b;
    return (x > y) - (x < y);
}

/* Fundamental supernodes (a column joins the previous one when it is its only child in the elimination
   tree and has the same pattern below), then relaxed amalgamation of each supernode with its parent when
   that parent starts right after it. On return super_first (n_super + 1) describes the partition. */
static int supernode_partition(struct ln_ldl_symbolic *s, const ln_int *etree, const ln_int *Lnz)
{
    const ln_int n = s->n;
    ln_int *children = alloc(n, sizeof(ln_int)), *fs = alloc(n + 1, sizeof(ln_int));
    ln_int *fparent = alloc(n, sizeof(ln_int)), *col_fs = alloc(n, sizeof(ln_int));
    ln_int *ncol = alloc(n, sizeof(ln_int)), *lnz = alloc(n, sizeof(ln_int)), *merged_into = alloc(n, sizeof(ln_int));
    int ok = children && fs && fparent && col_fs && ncol && lnz && merged_into;
    if (!ok) goto done;
    for (ln_int j = 0; j < n; j++)
        if (etree[j] >= 0) children[etree[j]]++;
    ln_int nf = 0;
    for (ln_int j = 0; j < n; j++) {
        int joins = j > 0 && etree[j - 1] == j && children[j] == 1 && Lnz[j - 1] == Lnz[j] + 1;
        if (!joins) fs[nf++] = j;
        col_fs[j] = nf - 1;
    }
    fs[nf] = n;
    for (ln_int f = 0; f < nf; f++) {
        ln_int last = fs[f + 1] - 1;
        fparent[f] = etree[last] >= 0 ? col_fs[etree[last]] : -1;
        ncol[f] = fs[f + 1] - fs[f];
        lnz[f] = Lnz[fs[f]] + 1;  /* rows of the supernode's first column, diagonal included */
        merged_into[f] = -1;
    }
    /* from the top of the elimination order down, so that a merged supernode can merge again with its child */
    for (ln_int j = nf - 2; j >= 0; j--) {
        ln_int parent = fparent[j];
        if (parent < 0) continue;
        ln_int t = j + 1;  /* the supernode that starts right after j, as merged so far (only j merges it) */
        /* parent must be t itself, or a fundamental supernode already merged into t */
        ln_int r = parent;
        while (merged_into[r] >= 0) r = merged_into[r];
        if (parent != r) merged_into[parent] = r;  /* shortcut for the next lookups */
        if (r != t) continue;
        ln_int nscol0 = ncol[j], ns = nscol0 + ncol[t];
        /* j's columns gain the rows of t's first column that they lack */
        int merge = ns <= RELAX_COLUMNS || lnz[t] + nscol0 == lnz[j];
        if (merge) {
            /* j absorbs t: j is now the representative, starting where j starts */
            merged_into[t] = j;
            ncol[j] = ns;
            lnz[j] = lnz[t] + nscol0;
            fparent[j] = fparent[t];
        }
    }
    ln_int ns_final = 0;
    for (ln_int f = 0; f < nf; f++)
        if (merged_into[f] < 0) ns_final++;
    s->n_super = ns_final;
    s->super_first = alloc(ns_final + 1, sizeof(ln_int));
    ok = s->super_first != NULL;
    if (!ok) goto done;
    ln_int k = 0;
    for (ln_int f = 0; f < nf; f++)
        if (merged_into[f] < 0) s->super_first[k++] = fs[f];
    s->super_first[ns_final] = n;
done:
    free(children); free(fs); free(fparent); free(col_fs); free(ncol); free(lnz); free(merged_into);
    return ok;
}

/* Row patterns of the supernodes, their block layout in Lx, and where each pair and diagonal entry goes. */
static int supernode_layout(struct ln_ldl_symbolic *s, const ln_int *etree)
{
    const ln_int n = s->n, ns = s->n_super;
    const ln_int *first = s->super_first;
    /* lower CSC of P A P^T (rows below the diagonal), the transpose of the upper pattern */
    ln_int *Lap = alloc(n + 1, sizeof(ln_int)), *Lai = alloc(s->nnz_A, sizeof(ln_int));
    ln_int *child_head = alloc(ns, sizeof(ln_int)), *child_next = alloc(ns, sizeof(ln_int));
    ln_int *marker = alloc(n, sizeof(ln_int)), *below = alloc(n, sizeof(ln_int));
    ln_int *sparent = alloc(ns, sizeof(ln_int));
    s->col_super = alloc(n, sizeof(ln_int));
    s->row_ptr = alloc(ns + 1, sizeof(ln_int));
    s->x_ptr = alloc(ns + 1, sizeof(ln_int));
    s->super_pair_ptr = alloc(ns + 1, sizeof(ln_int));
    s->super_pair_index = alloc(s->n_pairs, sizeof(ln_int));
    int ok = Lap && Lai && child_head && child_next && marker && below && sparent && s->col_super && s->row_ptr
             && s->x_ptr && s->super_pair_ptr && s->super_pair_index;
    ln_int capacity = 0, used = 0;
    if (!ok) goto done;
    for (ln_int j = 0; j < n; j++)
        for (ln_int p = s->Ap[j]; p < s->Ap[j + 1]; p++)
            if (s->Ai[p] != j) Lap[s->Ai[p] + 1]++;
    for (ln_int j = 0; j < n; j++) Lap[j + 1] += Lap[j];
    {
        ln_int *fill = below;  /* borrowed as insertion pointers */
        for (ln_int j = 0; j < n; j++) fill[j] = Lap[j];
        for (ln_int j = 0; j < n; j++)
            for (ln_int p = s->Ap[j]; p < s->Ap[j + 1]; p++)
                if (s->Ai[p] != j) Lai[fill[s->Ai[p]]++] = j;
    }
    for (ln_int t = 0; t < ns; t++) {
        for (ln_int j = first[t]; j < first[t + 1]; j++) s->col_super[j] = t;
        child_head[t] = -1;
    }
    for (ln_int t = ns - 1; t >= 0; t--) {
        ln_int last = first[t + 1] - 1;
        sparent[t] = etree[last] >= 0 ? s->col_super[etree[last]] : -1;
        if (sparent[t] >= 0) {
            child_next[t] = child_head[sparent[t]];
            child_head[sparent[t]] = t;
        }
    }
    for (ln_int j = 0; j < n; j++) marker[j] = -1;
    capacity = s->nnz_L + n + 16;
    s->rows = malloc((size_t) capacity * sizeof(ln_int));
    ok = s->rows != NULL;
    s->max_nrow = s->max_ncol = 0;
    for (ln_int t = 0; ok && t < ns; t++) {
        ln_int f = first[t], l = first[t + 1], nb = 0;
        for (ln_int j = f; j < l; j++)
            for (ln_int p = Lap[j]; p < Lap[j + 1]; p++) {
                ln_int i = Lai[p];
                if (i >= l && marker[i] != t) marker[i] = t, below[nb++] = i;
            }
        for (ln_int c = child_head[t]; c >= 0; c = child_next[c]) {
            ln_int cl = first[c + 1] - first[c];
            for (ln_int p = s->row_ptr[c] + cl; p < s->row_ptr[c + 1]; p++) {
                ln_int i = s->rows[p];
                if (i >= l && marker[i] != t) marker[i] = t, below[nb++] = i;
            }
        }
        qsort(below, (size_t) nb, sizeof(ln_int), compare_int);
        ln_int nrow = (l - f) + nb;
        if (used + nrow > capacity) {
            ln_int grown = 2 * capacity + nrow;
            ln_int *bigger = realloc(s->rows, (size_t) grown * sizeof(ln_int));
            if (!bigger) {
                ok = 0;
                break;
            }
            s->rows = bigger;
            capacity = grown;
        }
        s->row_ptr[t] = used;
        for (ln_int j = f; j < l; j++) s->rows[used++] = j;
        for (ln_int q = 0; q < nb; q++) s->rows[used++] = below[q];
        s->row_ptr[t + 1] = used;
        s->x_ptr[t + 1] = s->x_ptr[t] + nrow * (l - f);
        if (nrow > s->max_nrow) s->max_nrow = nrow;
        if (l - f > s->max_ncol) s->max_ncol = l - f;
    }
    if (!ok) goto done;
    s->nnz_stored = s->x_ptr[ns];
    /* each pair's upper CSC entry (i, j), i <= j, is L's entry in column i, row j: find row j in the
       (ascending) rows of the supernode holding column i; then group the pairs by supernode, each with
       its slot in that supernode's block */
    {
        ln_int *col_of = alloc(s->nnz_A, sizeof(ln_int));  /* column of each upper CSC slot */
        ln_int *slot_of_upper = Lai;  /* borrowed (as long as the upper pattern): block slot of each upper slot */
        ln_int *count = s->super_pair_ptr;
        ok = col_of != NULL;
        if (!ok) goto done;
        for (ln_int j = 0; j < n; j++)
            for (ln_int p = s->Ap[j]; p < s->Ap[j + 1]; p++) col_of[p] = j;
        for (ln_int p = 0; p < s->nnz_A; p++) {
            ln_int i = s->Ai[p], j = col_of[p], t = s->col_super[i];
            const ln_int *r = s->rows + s->row_ptr[t];
            ln_int lo = 0, hi = s->row_ptr[t + 1] - s->row_ptr[t] - 1;
            while (lo < hi) {
                ln_int mid = (lo + hi) / 2;
                if (r[mid] < j) lo = mid + 1;
                else hi = mid;
            }
            slot_of_upper[p] = (i - first[t]) * (s->row_ptr[t + 1] - s->row_ptr[t]) + lo;
        }
        for (ln_int p = 0; p < s->n_pairs; p++) count[s->col_super[s->Ai[s->pair_slot[p]]] + 1]++;
        for (ln_int t = 0; t < ns; t++) count[t + 1] += count[t];
        ln_int *fill = below;  /* borrowed: n >= ns insertion pointers */
        for (ln_int t = 0; t < ns; t++) fill[t] = count[t];
        ln_int *slot = malloc((size_t) (s->n_pairs ? s->n_pairs : 1) * sizeof(ln_int));
        ok = slot != NULL;
        if (ok) {
            for (ln_int p = 0; p < s->n_pairs; p++) {
                ln_int q = s->pair_slot[p], t = s->col_super[s->Ai[q]], at = fill[t]++;
                s->super_pair_index[at] = p;
                slot[at] = slot_of_upper[q];
            }
            free(s->pair_slot);
            s->pair_slot = slot;
        }
        free(col_of);
    }
done:
    free(Lap); free(Lai); free(child_head); free(child_next); free(marker); free(below); free(sparent);
    return ok;
}

/* ---- analysis ------------------------------------------------------------------------------------ */

struct ln_ldl_symbolic *ln_ldl_analyse(ln_int n, ln_int n_pairs, const ln_int *pair_first, const ln_int *pair_second,
                                       const ln_int *ordering)
{
    if (n < 0 || n_pairs < 0) return NULL;
    struct ln_ldl_symbolic *s = alloc(1, sizeof *s);
    if (!s) return NULL;
    s->n = n;
    s->n_pairs = n_pairs;
    s->ordering = alloc(n, sizeof(ln_int));
    s->pair_slot = alloc(n_pairs, sizeof(ln_int));
    ln_int *seen = alloc(n, sizeof(ln_int));
    ln_int *etree = alloc(n, sizeof(ln_int)), *Lnz = alloc(n, sizeof(ln_int)), *work = alloc(n, sizeof(ln_int));
    int ok = s->ordering && s->pair_slot && seen && etree && Lnz && work;
    for (ln_int p = 0; ok && p < n_pairs; p++)
        if (pair_first[p] < 0 || pair_first[p] >= n || pair_second[p] < 0 || pair_second[p] >= n) ok = 0;
    if (ok && ordering == NULL) ok = amd_ordering(n, n_pairs, pair_first, pair_second, s->ordering);
    else if (ok) {
        for (ln_int i = 0; ok && i < n; i++) {
            ln_int k = ordering[i];
            if (k < 0 || k >= n || seen[k]) ok = 0;
            else seen[k] = 1, s->ordering[i] = k;
        }
    }
    if (ok) ok = permuted_pattern(s, pair_first, pair_second);
    if (ok) {
        elimination_tree(n, s->Ap, s->Ai, etree, Lnz, work);
        s->nnz_L = 0;
        s->flops = 0.0;
        for (ln_int j = 0; j < n; j++) {
            s->nnz_L += Lnz[j];
            s->flops += (double) Lnz[j] * (double) (Lnz[j] + 3) / 2.0;
        }
        s->supernodal = n > 0 && (double) s->nnz_L >= SUPERNODAL_MIN_MEAN_COUNT * (double) n;
        s->vector_kernels = s->supernodal && ln_ldl_vector_kernels(-1);
#if LN_LDL_AVX2
        s->factor = !s->supernodal ? factor_columns
                    : s->vector_kernels ? factor_supernodal_avx2 : factor_supernodal_generic;
#else
        s->factor = s->supernodal ? factor_supernodal_generic : factor_columns;
#endif
        s->solve = s->supernodal ? solve_supernodal : solve_columns;
        if (s->supernodal) {
            ok = supernode_partition(s, etree, Lnz) && supernode_layout(s, etree);
            /* the numeric phase needs only the blocks: the column algorithm's pattern goes */
            free(s->Ap); free(s->Ai);
            s->Ap = s->Ai = NULL;
        } else {
            ok = column_schedule(s, etree, Lnz);
        }
    }
    free(seen); free(etree); free(Lnz); free(work);
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

void ln_ldl_info(const struct ln_ldl_symbolic *s, double info[6])
{
    info[0] = (double) s->supernodal;
    info[1] = (double) s->nnz_L;
    info[2] = s->supernodal ? (double) s->n_super : (double) s->n;
    info[3] = s->supernodal ? (double) s->nnz_stored : (double) s->nnz_L;
    info[4] = s->flops;
    info[5] = (double) s->vector_kernels;
}

struct ln_ldl_numeric *ln_ldl_numeric_new(const struct ln_ldl_symbolic *s)
{
    struct ln_ldl_numeric *f = alloc(1, sizeof *f);
    if (!f) return NULL;
    const ln_int n = s->n;
    f->D = alloc(n, sizeof(double));
    f->Dinv = alloc(n, sizeof(double));
    f->x = alloc(n, sizeof(double));
    int ok = f->D && f->Dinv && f->x;
    if (s->supernodal) {
        const ln_int ns = s->n_super;
        f->Lx = alloc(s->nnz_stored, sizeof(double));
        f->Adiag = alloc(n, sizeof(double));
        f->w = alloc(s->max_nrow, sizeof(double));
        f->head = alloc(ns, sizeof(ln_int));
        f->next = alloc(ns, sizeof(ln_int));
        f->lpos = alloc(ns, sizeof(ln_int));
        f->map = alloc(n, sizeof(ln_int));
        f->rel = alloc(s->max_nrow, sizeof(ln_int));
        f->pack = alloc(4 * s->max_ncol, sizeof(double));
        ok = ok && f->Lx && f->Adiag && f->w && f->head && f->next && f->lpos && f->map && f->rel && f->pack;
    } else {
        f->Ax = alloc(s->nnz_A, sizeof(double));
        f->Lx = alloc(s->nnz_L, sizeof(double));
        f->w = alloc(n, sizeof(double));
        ok = ok && f->Ax && f->Lx && f->w;
    }
    if (!ok) {
        ln_ldl_numeric_free(f);
        return NULL;
    }
    return f;
}

void ln_ldl_numeric_free(struct ln_ldl_numeric *f)
{
    if (!f) return;
    free(f->Ax); free(f->Lx); free(f->D); free(f->Dinv); free(f->x);
    free(f->Adiag); free(f->w); free(f->head); free(f->next); free(f->lpos); free(f->map); free(f->rel);
    free(f->pack);
    free(f);
}

/* ---- numeric factorisation ----------------------------------------------------------------------- */

static ln_int factor_columns(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *pair_values,
                             double pivot_tol)
{
    const ln_int n = s->n;
    const ln_int *Ap = s->Ap, *Ai = s->Ai, *Lp = s->Lp, *Li = s->Li;
    const ln_int *row_start = s->row_start, *row_col = s->row_col, *row_slot = s->row_slot;
    double *Ax = f->Ax, *Lx = f->Lx, *D = f->D, *Dinv = f->Dinv, *y = f->w;  /* y: zero on entry and exit */
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
        if (!(dk > pivot_tol * fabs(diag))) {
            if (bad == -1) bad = k;
            Dinv[k] = 0.0;
        } else {
            Dinv[k] = 1.0 / dk;
        }
    }
    return bad;
}

ln_int ln_ldl_factor(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *pair_values,
                     double pivot_tol)
{
    return s->factor(s, f, pair_values, pivot_tol);
}

ln_int ln_ldl_get_pivots(const struct ln_ldl_symbolic *s, const struct ln_ldl_numeric *f, double *D)
{
    ln_int zeroed = 0;
    for (ln_int k = 0; k < s->n; k++) {
        if (D) D[k] = f->D[k];
        if (f->Dinv[k] == 0.0) zeroed++;
    }
    return zeroed;
}

/* ---- solves -------------------------------------------------------------------------------------- */

static void solve_columns(const struct ln_ldl_symbolic *s, const struct ln_ldl_numeric *f, double *x)
{
    const ln_int n = s->n;
    const ln_int *Lp = s->Lp, *Li = s->Li;
    const double *Lx = f->Lx, *Dinv = f->Dinv;
    for (ln_int i = 0; i < n; i++) {
        const double xi = x[i];
        for (ln_int j = Lp[i]; j < Lp[i + 1]; j++) x[Li[j]] -= Lx[j] * xi;
    }
    for (ln_int i = 0; i < n; i++) x[i] *= Dinv[i];
    for (ln_int i = n - 1; i >= 0; i--) {
        double sum = x[i];
        for (ln_int j = Lp[i]; j < Lp[i + 1]; j++) sum -= Lx[j] * x[Li[j]];
        x[i] = sum;
    }
}

/* w[0..m) -= A(0:m, 0:nk) x, A column-major: four columns per pass over w. */
static void gemv_sub(ln_int m, ln_int nk, const double *restrict A, ln_int lda, const double *restrict x,
                     double *restrict w)
{
    ln_int k = 0;
    for (; k + 4 <= nk; k += 4) {
        const double *a0 = A + k * lda, *a1 = a0 + lda, *a2 = a1 + lda, *a3 = a2 + lda;
        const double x0 = x[k], x1 = x[k + 1], x2 = x[k + 2], x3 = x[k + 3];
        for (ln_int i = 0; i < m; i++) w[i] -= a0[i] * x0 + a1[i] * x1 + a2[i] * x2 + a3[i] * x3;
    }
    for (; k < nk; k++) {
        const double *a = A + k * lda;
        const double xk = x[k];
        for (ln_int i = 0; i < m; i++) w[i] -= a[i] * xk;
    }
}

/* y[0..nk) -= A(0:m, 0:nk)^T w, A column-major: four columns per pass over w, each dot product summed in
   two interleaved partial sums (even and odd rows). */
static void gemv_t_sub(ln_int m, ln_int nk, const double *restrict A, ln_int lda, const double *restrict w,
                       double *restrict y)
{
    const ln_int m2 = m - m % 2;
    ln_int k = 0;
    for (; k + 4 <= nk; k += 4) {
        const double *a0 = A + k * lda, *a1 = a0 + lda, *a2 = a1 + lda, *a3 = a2 + lda;
        double s00 = 0, s01 = 0, s10 = 0, s11 = 0, s20 = 0, s21 = 0, s30 = 0, s31 = 0;
        for (ln_int i = 0; i < m2; i += 2) {
            const double w0 = w[i], w1 = w[i + 1];
            s00 += a0[i] * w0; s01 += a0[i + 1] * w1;
            s10 += a1[i] * w0; s11 += a1[i + 1] * w1;
            s20 += a2[i] * w0; s21 += a2[i + 1] * w1;
            s30 += a3[i] * w0; s31 += a3[i + 1] * w1;
        }
        if (m2 < m) {
            const double wl = w[m2];
            s00 += a0[m2] * wl; s10 += a1[m2] * wl; s20 += a2[m2] * wl; s30 += a3[m2] * wl;
        }
        y[k] -= s00 + s01;
        y[k + 1] -= s10 + s11;
        y[k + 2] -= s20 + s21;
        y[k + 3] -= s30 + s31;
    }
    for (; k < nk; k++) {
        const double *a = A + k * lda;
        double s0 = 0, s1 = 0;
        for (ln_int i = 0; i < m2; i += 2) {
            s0 += a[i] * w[i];
            s1 += a[i + 1] * w[i + 1];
        }
        if (m2 < m) s0 += a[m2] * w[m2];
        y[k] -= s0 + s1;
    }
}

/* Columns of a supernode's diagonal block solved together in the triangular solves. */
#define SOLVE_GROUP 4

/* The supernodal solves work on w = the supernode's rows of x (its own columns, then the rows below): one
   gemv per group of columns over the whole rest of the block, instead of one short loop per column. */
static void solve_supernodal(const struct ln_ldl_symbolic *s, const struct ln_ldl_numeric *f, double *x)
{
    const ln_int n = s->n, ns = s->n_super;
    const ln_int *first = s->super_first, *row_ptr = s->row_ptr, *rows = s->rows, *x_ptr = s->x_ptr;
    const double *Lx = f->Lx, *Dinv = f->Dinv;
    double *w = f->w;
    for (ln_int t = 0; t < ns; t++) {
        const ln_int fc = first[t], ncol = first[t + 1] - fc;
        const ln_int r0 = row_ptr[t], nrow = row_ptr[t + 1] - r0;
        const double *X = Lx + x_ptr[t];
        const ln_int *rb = rows + r0;
        for (ln_int i = 0; i < ncol; i++) w[i] = x[fc + i];
        for (ln_int i = ncol; i < nrow; i++) w[i] = 0.0;
        for (ln_int k = 0; k < ncol; k += SOLVE_GROUP) {
            const ln_int kend = ncol - k < SOLVE_GROUP ? ncol : k + SOLVE_GROUP;
            if (kend - k == 4) {  /* the group's triangle in registers */
                const double *c0 = X + k + k * nrow, *c1 = c0 + nrow, *c2 = c1 + nrow;
                const double w0 = w[k], w1 = w[k + 1] - c0[1] * w0;
                const double w2 = w[k + 2] - c0[2] * w0 - c1[2] * w1;
                w[k + 1] = w1;
                w[k + 2] = w2;
                w[k + 3] = w[k + 3] - c0[3] * w0 - c1[3] * w1 - c2[3] * w2;
            } else {
                for (ln_int kk = k; kk < kend; kk++)
                    for (ln_int i = kk + 1; i < kend; i++) w[i] -= X[i + kk * nrow] * w[kk];
            }
            gemv_sub(nrow - kend, kend - k, X + kend + k * nrow, nrow, w + k, w + kend);
        }
        for (ln_int i = 0; i < ncol; i++) x[fc + i] = w[i];
        for (ln_int i = ncol; i < nrow; i++) x[rb[i]] += w[i];
    }
    for (ln_int i = 0; i < n; i++) x[i] *= Dinv[i];
    for (ln_int t = ns - 1; t >= 0; t--) {
        const ln_int fc = first[t], ncol = first[t + 1] - fc;
        const ln_int r0 = row_ptr[t], nrow = row_ptr[t + 1] - r0;
        const double *X = Lx + x_ptr[t];
        const ln_int *rb = rows + r0;
        for (ln_int i = 0; i < ncol; i++) w[i] = x[fc + i];
        for (ln_int i = ncol; i < nrow; i++) w[i] = x[rb[i]];
        for (ln_int k = ((ncol - 1) / SOLVE_GROUP) * SOLVE_GROUP; k >= 0; k -= SOLVE_GROUP) {
            const ln_int kend = ncol - k < SOLVE_GROUP ? ncol : k + SOLVE_GROUP;
            gemv_t_sub(nrow - kend, kend - k, X + kend + k * nrow, nrow, w + kend, w + k);
            if (kend - k == 4) {
                const double *c0 = X + k + k * nrow, *c1 = c0 + nrow, *c2 = c1 + nrow;
                const double w3 = w[k + 3], w2 = w[k + 2] - c2[3] * w3;
                const double w1 = w[k + 1] - (c1[2] * w2 + c1[3] * w3);
                w[k + 2] = w2;
                w[k + 1] = w1;
                w[k] -= c0[1] * w1 + c0[2] * w2 + c0[3] * w3;
            } else {
                for (ln_int kk = kend - 1; kk >= k; kk--) {
                    double sum = 0.0;
                    for (ln_int i = kk + 1; i < kend; i++) sum += X[i + kk * nrow] * w[i];
                    w[kk] -= sum;
                }
            }
        }
        for (ln_int i = 0; i < ncol; i++) x[fc + i] = w[i];
    }
}

void ln_ldl_solve(const struct ln_ldl_symbolic *s, struct ln_ldl_numeric *f, const double *b, double *out)
{
    const ln_int n = s->n;
    const ln_int *ordering = s->ordering;
    double *x = f->x;
    for (ln_int i = 0; i < n; i++) x[i] = b[ordering[i]];
    s->solve(s, f, x);
    for (ln_int i = 0; i < n; i++) out[ordering[i]] = x[i];
}

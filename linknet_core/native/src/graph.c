/* Graph routines of the structure analysis (graph.h): linear in nodes and edges, no allocation left behind. */
#include <stdlib.h>

#include "graph.h"

static int edges_in_range(ln_int n_nodes, ln_int n_edges, const ln_int *a, const ln_int *b)
{
    for (ln_int e = 0; e < n_edges; e++)
        if (a[e] < 0 || a[e] >= n_nodes || b[e] < 0 || b[e] >= n_nodes) return 0;
    return 1;
}

static ln_int find_root(ln_int *parent, ln_int i)
{
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];  /* path halving */
        i = parent[i];
    }
    return i;
}

LN_API ln_int ln_graph_components(ln_int n_nodes, ln_int n_edges, const ln_int *a, const ln_int *b, ln_int *label)
{
    if (n_nodes < 0 || n_edges < 0 || !edges_in_range(n_nodes, n_edges, a, b)) return -1;
    if (n_nodes == 0) return 0;
    ln_int *parent = malloc((size_t)n_nodes * sizeof *parent);
    if (!parent) return -1;
    for (ln_int i = 0; i < n_nodes; i++) parent[i] = i;
    for (ln_int e = 0; e < n_edges; e++) {
        ln_int ra = find_root(parent, a[e]), rb = find_root(parent, b[e]);
        if (ra < rb) parent[rb] = ra;  /* the smaller node becomes the root: roots are their component's minimum */
        else if (rb < ra) parent[ra] = rb;
    }
    /* nodes in increasing order meet their component's root (its smallest node) first */
    ln_int count = 0;
    for (ln_int i = 0; i < n_nodes; i++) {
        ln_int r = find_root(parent, i);
        label[i] = r == i ? count++ : label[r];
    }
    free(parent);
    return count;
}

LN_API int ln_forest_depth(ln_int n_nodes, ln_int n_edges, const ln_int *a, const ln_int *b, ln_int *depth)
{
    if (n_nodes < 0 || n_edges < 0 || !edges_in_range(n_nodes, n_edges, a, b)) return -1;
    if (n_nodes == 0) return 0;
    /* adjacency lists (CSR) and a queue for the breadth-first walks */
    ln_int *start = calloc((size_t)n_nodes + 1, sizeof *start);
    ln_int *next = malloc(((size_t)2 * (size_t)n_edges + 1) * sizeof *next);
    ln_int *queue = malloc((size_t)n_nodes * sizeof *queue);
    if (!start || !next || !queue) {
        free(start);
        free(next);
        free(queue);
        return -1;
    }
    for (ln_int e = 0; e < n_edges; e++) {
        start[a[e] + 1]++;
        start[b[e] + 1]++;
    }
    for (ln_int i = 0; i < n_nodes; i++) start[i + 1] += start[i];
    for (ln_int i = 0; i < n_nodes; i++) queue[i] = start[i];  /* fill positions */
    for (ln_int e = 0; e < n_edges; e++) {
        next[queue[a[e]]++] = b[e];
        next[queue[b[e]]++] = a[e];
    }
    for (ln_int i = 0; i < n_nodes; i++) depth[i] = -1;
    /* in increasing node order, the first leaf met in a tree not yet walked is that tree's smallest leaf */
    for (ln_int root = 0; root < n_nodes; root++) {
        if (depth[root] >= 0 || start[root + 1] - start[root] > 1) continue;
        ln_int head = 0, tail = 0;
        depth[root] = 0;
        queue[tail++] = root;
        while (head < tail) {
            ln_int u = queue[head++];
            for (ln_int p = start[u]; p < start[u + 1]; p++) {
                ln_int v = next[p];
                if (depth[v] < 0) {
                    depth[v] = depth[u] + 1;
                    queue[tail++] = v;
                }
            }
        }
    }
    int status = 0;
    for (ln_int i = 0; i < n_nodes; i++)
        if (depth[i] < 0) status = -1;  /* a tree with no node of degree <= 1: the graph has a cycle */
    free(start);
    free(next);
    free(queue);
    return status;
}

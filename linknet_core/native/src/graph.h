/* Graph routines of the structure analysis (graph.c), run once per scene before anything else is built:
 * the connected components of the link graph and the leaves-first order of a forest's links. Nodes are
 * 0 .. n_nodes - 1, each edge e joins a[e] and b[e]. */
#ifndef LINKNET_GRAPH_H
#define LINKNET_GRAPH_H

#include "linknet.h"

/* The connected components: label (n_nodes) numbers them 0, 1, ... in the order of their smallest node (node
   0's component is 0, the component of the smallest node outside it is 1, ...). Returns how many there are,
   -1 on an edge end out of range or out of memory. */
LN_API ln_int ln_graph_components(ln_int n_nodes, ln_int n_edges, const ln_int *a, const ln_int *b, ln_int *label);

/* For a forest (no cycle): depth (n_nodes) of every node below the root of its tree, each tree rooted at its
   smallest node of degree <= 1 (a leaf; a tree has one). Returns 0, -1 on an edge end out of range, a tree
   without such a node (the graph has a cycle) or out of memory. */
LN_API int ln_forest_depth(ln_int n_nodes, ln_int n_edges, const ln_int *a, const ln_int *b, ln_int *depth);

#endif

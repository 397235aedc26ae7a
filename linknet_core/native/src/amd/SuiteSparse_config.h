/* Stand-in for SuiteSparse_config.h, written for linknet (not part of SuiteSparse).
 *
 * linknet compiles AMD alone, without the rest of SuiteSparse, for one call: amd_l_order with default
 * controls and no statistics printed. AMD needs from SuiteSparse_config only the standard headers (sqrt, memset), the
 * version macros its amd.h checks, an allocator (libc's, with SuiteSparse_malloc's rules: at least one
 * item, NULL on overflow) and a printf macro, which prints nothing here (no library output on stdout).
 */
#ifndef SUITESPARSE_CONFIG_H
#define SUITESPARSE_CONFIG_H

#include <inttypes.h>
#include <limits.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* the release AMD 3.3.4 was written against (amd.h refuses anything older) */
#define SUITESPARSE__VERCODE(main, sub, patch) ((((main) * 1000ULL) + (sub)) * 1000ULL + (patch))
#define SUITESPARSE__VERSION SUITESPARSE__VERCODE(7, 11, 0)
#define SUITESPARSE_VER_CODE(main, sub) ((main) * 1000 + (sub))

#define SUITESPARSE_PRINTF(params) ((void) 0)

static inline void *SuiteSparse_malloc(size_t nitems, size_t size_of_item)
{
    if (nitems < 1) nitems = 1;
    if (size_of_item < 1) size_of_item = 1;
    if (nitems > SIZE_MAX / size_of_item) return NULL;
    return malloc(nitems * size_of_item);
}

static inline void *SuiteSparse_free(void *p)
{
    free(p);
    return NULL;
}

#endif

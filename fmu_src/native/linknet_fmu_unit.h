/* Included first by every translation unit of the native FMU: each .c file at the top of sources/ is two lines, this
 * header and one file of sources/linknet/ (the core, linknet_core/native/src as it is, the FMI glue and the scene's
 * data), so that a plain build of every .c file at the top of sources/ (cc -shared -fPIC, those files, -lm), the
 * sources' CMakeLists.txt and a tool's own build of the <SourceFiles> all give the same binary.
 *
 * Only the fmi2 functions leave that binary, however it is compiled and linked: fmi2_api.h marks them visible
 * (dllexport on Windows, where nothing else is exported), and everything after this header is hidden. An exported
 * internal symbol could bind to another copy of the core in the host's process (another linknet FMU, the Python
 * library) or clash with a host's own names.
 *
 * The C library's headers that the sources use come first, declared as they are: a C library function declared
 * hidden would be taken as defined in this binary and fail to link. fmu_src/native/build.py refuses sources that
 * include a system header not listed here.
 */
#ifndef LINKNET_FMU_UNIT_H
#define LINKNET_FMU_UNIT_H

#include <assert.h>
#include <float.h>
#include <inttypes.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define LN_API /* the core's interface (linknet.h) stays inside the FMU */

#if (defined __GNUC__ || defined __clang__) && !defined _WIN32 && !defined __CYGWIN__
#pragma GCC visibility push(hidden)
#endif

#endif

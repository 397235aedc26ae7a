/* The core's elementary functions, the same bits on every platform: no call into the C library's libm.
 *
 * A C library's sin, cos, pow and hypot are not correctly rounded, and each platform has its own (glibc's on
 * x86-64 and on aarch64 differ on 12 % of hypot's arguments, the Universal C Runtime's on 13 % of hypot's, 3 % of
 * sin's and cos's): the same source then gives different motions on different platforms once a motion amplifies
 * the last bit. ln_math.c computes them itself with +, -, *, /, sqrt and integer operations only, each rounded as
 * IEEE 754 double wherever FLT_EVAL_METHOD is 0 (x86-64's SSE2, aarch64) and nothing is contracted into a fused
 * multiply-add (-ffp-contract=off, and the pragma in ln_math.c). The exact ones below (min, max, next, round,
 * ceil, powers of two) are here so that no libm symbol is needed at all: a binary of the core then loads in a
 * process without libm (an FMU built by a tool that links none).
 *
 * sqrt and fabs are the IEEE operations themselves (correctly rounded, exact) and stay the compiler's: fabs is
 * always inline; sqrt goes through ln_sqrt, which is the instruction even where the build keeps errno (see there).
 */
#ifndef LN_MATH_H
#define LN_MATH_H

#include <math.h>
#include <stdint.h>

/* Errors in units in the last place of the exact result (ln_math.c has the measured figures): */
double ln_sin(double x);             /* < 1 (fdlibm's bound; 0.77 measured); arguments of any size reduced exactly */
double ln_cos(double x);             /* < 1 (0.77 measured) */
double ln_pow(double x, double y);   /* < 0.54 (Arm's bound), C99's special cases */
double ln_hypot(double x, double y); /* < 0.501, < 0.75 for a subnormal result; no overflow or underflow inside */
double ln_round(double x);           /* round(): to the nearest integer, halfway cases away from zero; exact */
double ln_ceil(double x);            /* ceil(): the least integer not below x; exact */

static inline uint64_t ln_bits(double x)
{
    union { double f; uint64_t i; } u;
    u.f = x;
    return u.i;
}

static inline double ln_from_bits(uint64_t i)
{
    union { uint64_t i; double f; } u;
    u.i = i;
    return u.f;
}

/* C99's fmax and fmin: a NaN argument is ignored (NaN only if both are). */
static inline double ln_fmax(double x, double y) { return (x > y || y != y) ? x : y; }
static inline double ln_fmin(double x, double y) { return (x < y || y != y) ? x : y; }

/* nextafter(x, +infinity): the least double above x (x itself if +infinity or NaN). */
static inline double ln_next_up(double x)
{
    const uint64_t i = ln_bits(x);
    if (x != x || i == UINT64_C(0x7ff0000000000000)) return x;
    if (x == 0.0) return ln_from_bits(1);                             /* the least subnormal, from +0 or -0 */
    return ln_from_bits((i >> 63) ? i - 1 : i + 1);                   /* away from zero above, towards it below */
}

/* 2^n exactly, for a normal result (-1022 <= n <= 1023): ldexp(1.0, n). */
static inline double ln_pow2(int n) { return ln_from_bits((uint64_t)(n + 1023) << 52); }

/* sqrt, always the instruction. GCC and clang keep errno for sqrt unless built with -fno-math-errno (ours are):
   then a negative argument goes to the C library's sqrt, to set errno, and the binary needs libm. A tool's own build
   of the sources (fmpy's CMake, a plain cc) does not pass the flag, so there the instruction is written out on the
   two targets that have no other way to it; elsewhere a tool's build without the flag may still link libm's sqrt,
   with the same result (sqrt is correctly rounded everywhere). */
static inline double ln_sqrt(double x)
{
#if (defined(__GNUC__) || defined(__clang__)) && !defined(__NO_MATH_ERRNO__) && defined(__x86_64__)
    double r;
    __asm__("sqrtsd %1, %0" : "=x"(r) : "x"(x));
    return r;
#elif (defined(__GNUC__) || defined(__clang__)) && !defined(__NO_MATH_ERRNO__) && defined(__aarch64__)
    double r;
    __asm__("fsqrt %d0, %d1" : "=w"(r) : "w"(x));
    return r;
#else
    return sqrt(x);
#endif
}

#endif

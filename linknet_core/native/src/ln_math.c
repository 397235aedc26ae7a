/* The core's deterministic elementary functions (ln_math.h says why): sin, cos, pow and hypot in plain C99 with
 * +, -, *, /, sqrt and integer operations only, so that every conforming compiler gives the same bits on every
 * target whose doubles are IEEE 754 binary64 evaluated as such (FLT_EVAL_METHOD 0: x86-64, aarch64) when nothing is
 * contracted into a fused multiply-add (the pragma below, and -ffp-contract=off in every build of ours).
 *
 * The algorithms, constants and tables are musl libc's (src/math of musl 1.2, as Zig's ziglang package ships it):
 *   - sin, cos: fdlibm's kernels on [-pi/4, pi/4] (musl's __sin.c, __cos.c) after the argument is reduced modulo
 *     pi/2 (__rem_pio2.c: Cody-Waite in two or three parts up to 2^20 pi/2, __rem_pio2_large.c: Payne-Hanek with
 *     396 bits of 2/pi beyond): Copyright (C) 1993 by Sun Microsystems, Inc. All rights reserved. Developed at
 *     SunSoft, a Sun Microsystems, Inc. business. Permission to use, copy, modify, and distribute this software is
 *     freely granted, provided that this notice is preserved. (Reduction optimized by Bruce D. Evans.)
 *   - pow: Arm's optimized-routines (musl's pow.c, pow_data.c, exp_data.c): log(x) to ~68 bits from a 128-entry
 *     table and a polynomial, y log(x) in two parts, exp of it from a 128-entry table. Copyright (c) 2018, Arm
 *     Limited. SPDX-License-Identifier: MIT.
 *   - hypot: musl's hypot.c: the squares split exactly (Dekker's product), the arguments scaled so that nothing
 *     overflows or underflows; here the squares' sum is kept to ~2^-100 and the root refined by one Newton step.
 * musl is distributed under the MIT license:
 *
 *   Copyright (c) 2005-2020 Rich Felker, et al.
 *
 *   Permission is hereby granted, free of charge, to any person obtaining a copy of this software and associated
 *   documentation files (the "Software"), to deal in the Software without restriction, including without
 *   limitation the rights to use, copy, modify, merge, publish, distribute, sublicense, and/or sell copies of the
 *   Software, and to permit persons to whom the Software is furnished to do so, subject to the following
 *   conditions:
 *
 *   The above copyright notice and this permission notice shall be included in all copies or substantial portions
 *   of the Software.
 *
 *   THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR IMPLIED, INCLUDING BUT NOT LIMITED TO
 *   THE WARRANTIES OF MERCHANTABILITY, FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
 *   AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER LIABILITY, WHETHER IN AN ACTION OF
 *   CONTRACT, TORT OR OTHERWISE, ARISING FROM, OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER
 *   DEALINGS IN THE SOFTWARE.
 *
 * Changed from musl: only what is deterministic everywhere is kept. pow's fused multiply-add branches (taken where
 * the compiler defines __FP_FAST_FMA, as on aarch64) and its rounding intrinsics are gone, leaving the branch that
 * splits products exactly without FMA (Arm's bound: 0.54 ulp); floor and scalbn are this file's own (exact, bit
 * operations and additions); double_t is double; floating-point exception flags and errno are not raised (the core
 * tests results with isfinite); the reduction keeps double precision only.
 *
 * Measured (python3 -m benchmarks.ln_math_accuracy: gcc 12 -O3, 1,000,000 random arguments per family, against
 * mpmath at 160 bits), the largest error in units in the last place of the exact result:
 *   sin 0.766 (x in [-100, 100]), 0.774 (|x| log-uniform in [2^-30, 2^1000]); cos 0.767, 0.770;
 *   pow 0.507 (x in [2^-40, 2^40], y in [-8, 8]), 0.506 (x in [2^-1000, 2^1000], |y| <= 1);
 *   hypot 0.500 where the result is normal; 0.727 where it is subnormal (rounded twice there: below 0.75).
 * glibc 2.36 over the same arguments: 0.515, 0.506, 0.571 and 0.727, and other bits on 3.1 % of sin's and cos's
 * arguments, 0.07 % of pow's, 0.6 % of hypot's.
 */

#include "ln_math.h"

#include <float.h>
#include <math.h>
#include <stdint.h>

/* No fused multiply-add here, however the file is compiled: GCC contracts in its GNU C modes (a tool's build with
   -std=gnu99 on a target with FMA: aarch64, x86-64 with -mfma), clang by default; each obeys its own pragma. */
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#elif defined(__GNUC__)
#pragma GCC optimize("fp-contract=off")
#elif defined(_MSC_VER)
#pragma fp_contract(off)
#endif

/* ---------------------------------------------------------------------------- exact roundings and scalings */
static const double TO_INTEGER = 0x1p52;  /* x + 2^52 - 2^52 is x rounded to an integer, for 0 <= x < 2^52 */

/* floor(x): the greatest integer not above x (musl's floor). */
static double floor_exact(double x)
{
    const uint64_t i = ln_bits(x);
    const int e = (int)(i >> 52 & 0x7ff);
    if (e >= 0x3ff + 52 || x == 0.0) return x;  /* an integer already (zero, large, inf) or NaN */
    if (e < 0x3ff) return (i >> 63) ? -1.0 : 0.0;  /* 0 < |x| < 1 */
    /* y = x's nearest integer - x, exact */
    const double y = (i >> 63) ? x - TO_INTEGER + TO_INTEGER - x : x + TO_INTEGER - TO_INTEGER - x;
    return y > 0.0 ? x + y - 1.0 : x + y;
}

double ln_ceil(double x)
{
    const uint64_t i = ln_bits(x);
    const int e = (int)(i >> 52 & 0x7ff);
    if (e >= 0x3ff + 52 || x == 0.0) return x;
    if (e < 0x3ff) return (i >> 63) ? -0.0 : 1.0;
    const double y = (i >> 63) ? x - TO_INTEGER + TO_INTEGER - x : x + TO_INTEGER - TO_INTEGER - x;
    return y < 0.0 ? x + y + 1.0 : x + y;
}

double ln_round(double x)
{
    const uint64_t i = ln_bits(x);
    const int e = (int)(i >> 52 & 0x7ff);
    if (e >= 0x3ff + 52) return x;  /* an integer already, inf or NaN */
    if (e < 0x3ff - 1) return 0.0 * x;  /* |x| < 1/2: zero of x's sign */
    const double a = (i >> 63) ? -x : x;
    double y = a + TO_INTEGER - TO_INTEGER - a;  /* a's nearest integer (halfway cases to even) - a, exact */
    if (y > 0.5) y = y + a - 1.0;
    else if (y <= -0.5) y = y + a + 1.0;  /* halfway, rounded down to even: away from zero instead */
    else y = y + a;
    return (i >> 63) ? -y : y;
}

/* x 2^n (musl's scalbn): in steps that keep every intermediate normal, one rounding at most at the end. */
static double scale_by_power_of_2(double x, int n)
{
    double y = x;
    if (n > 1023) {
        y *= 0x1p1023;
        n -= 1023;
        if (n > 1023) {
            y *= 0x1p1023;
            n -= 1023;
            if (n > 1023) n = 1023;
        }
    } else if (n < -1022) {  /* the last step's n stays below -53: no double rounding into the subnormals */
        y *= 0x1p-1022 * 0x1p53;
        n += 1022 - 53;
        if (n < -1022) {
            y *= 0x1p-1022 * 0x1p53;
            n += 1022 - 53;
            if (n < -1022) n = -1022;
        }
    }
    return y * ln_pow2(n);
}

/* ---------------------------------------------------------------------------- sin and cos */
/* sin on [-pi/4, pi/4] of x + tail (|tail| tiny; tail_is_zero when it is 0): an odd polynomial of degree 13,
   |sin(x)/x - poly| <= 2^-58 (fdlibm's k_sin.c) */
static const double
S1 = -1.66666666666666324348e-01, /* 0xBFC55555, 0x55555549 */
S2 = 8.33333333332248946124e-03,  /* 0x3F811111, 0x1110F8A6 */
S3 = -1.98412698298579493134e-04, /* 0xBF2A01A0, 0x19C161D5 */
S4 = 2.75573137070700676789e-06,  /* 0x3EC71DE3, 0x57B1FE7D */
S5 = -2.50507602534068634195e-08, /* 0xBE5AE5E6, 0x8A2B9CEB */
S6 = 1.58969099521155010221e-10;  /* 0x3DE5D93A, 0x5ACFD57C */

static double sin_kernel(double x, double tail, int tail_is_zero)
{
    const double z = x * x, w = z * z;
    const double r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
    const double v = z * x;
    if (tail_is_zero) return x + v * (S1 + z * r);
    return x - ((z * (0.5 * tail - v * r) - tail) - v * S1);  /* sin(x + y) ~ sin(x) + (1 - x^2/2) y */
}

/* cos on [-pi/4, pi/4] of x + tail: 1 - x^2/2 + an even polynomial of degree 14, remez error <= 2^-58 (fdlibm's
   k_cos.c); 1 - x^2/2 is summed as w + ((1 - w) - x^2/2), w = 1 - x^2/2 rounded, for its last bits */
static const double
C1 = 4.16666666666666019037e-02,  /* 0x3FA55555, 0x5555554C */
C2 = -1.38888888888741095749e-03, /* 0xBF56C16C, 0x16C15177 */
C3 = 2.48015872894767294178e-05,  /* 0x3EFA01A0, 0x19CB1590 */
C4 = -2.75573143513906633035e-07, /* 0xBE927E4F, 0x809C52AD */
C5 = 2.08757232129817482790e-09,  /* 0x3E21EE9E, 0xBDB4B1C4 */
C6 = -1.13596475577881948265e-11; /* 0xBDA8FAE9, 0xBE8838D4 */

static double cos_kernel(double x, double tail)
{
    const double z = x * x, w4 = z * z;
    const double r = z * (C1 + z * (C2 + z * C3)) + w4 * w4 * (C4 + z * (C5 + z * C6));
    const double hz = 0.5 * z, w = 1.0 - hz;
    return w + (((1.0 - w) - hz) + (z * r - x * tail));
}

/* 2/pi in 24-bit pieces: piece i holds bits 24i+1 .. 24i+24 after the binary point (fdlibm's ipio2, 396 hex
   digits: enough for every double) */
static const int32_t two_over_pi[66] = {
    0xA2F983, 0x6E4E44, 0x1529FC, 0x2757D1, 0xF534DD, 0xC0DB62,
    0x95993C, 0x439041, 0xFE5163, 0xABDEBB, 0xC561B7, 0x246E3A,
    0x424DD2, 0xE00649, 0x2EEA09, 0xD1921C, 0xFE1DEB, 0x1CB129,
    0xA73EE8, 0x8235F5, 0x2EBB44, 0x84E99C, 0x7026B4, 0x5F7E41,
    0x3991D6, 0x398353, 0x39F49C, 0x845F8B, 0xBDF928, 0x3B1FF8,
    0x97FFDE, 0x05980F, 0xEF2F11, 0x8B5A0A, 0x6D1F6D, 0x367ECF,
    0x27CB09, 0xB74F46, 0x3F669E, 0x5FEA2D, 0x7527BA, 0xC7EBE5,
    0xF17B3D, 0x0739F7, 0x8A5292, 0xEA6BFB, 0x5FB11F, 0x8D5D08,
    0x560330, 0x46FC7B, 0x6BABF0, 0xCFBC20, 0x9AF436, 0x1DA9E3,
    0x91615E, 0xE61B08, 0x659985, 0x5F14A0, 0x68408D, 0xFFD880,
    0x4D7327, 0x310606, 0x1556CA, 0x73A8C9, 0x60E27B, 0xC08C6B,
};

/* pi/2 in 24-bit pieces (fdlibm's PIo2) */
static const double PI_2_PIECES[] = {
    1.57079625129699707031e+00, /* 0x3FF921FB, 0x40000000 */
    7.54978941586159635335e-08, /* 0x3E74442D, 0x00000000 */
    5.39030252995776476554e-15, /* 0x3CF84698, 0x80000000 */
    3.28200341580791294123e-22, /* 0x3B78CC51, 0x60000000 */
    1.27065575308067607349e-29, /* 0x39F01B83, 0x80000000 */
    1.22933308981111328932e-36, /* 0x387A2520, 0x40000000 */
    2.73370053816464559624e-44, /* 0x36E38222, 0x80000000 */
    2.16741683877804819444e-51, /* 0x3569F31D, 0x00000000 */
};

/* Payne-Hanek reduction (fdlibm's k_rem_pio2.c at double precision): x = x[0] 2^e0 + x[1] 2^(e0-24) + ... (nx
   24-bit integer pieces, x > 0) = n pi/2 + y[0] + y[1] with |y| <= pi/4; returns n mod 8. Only the bits of 2/pi
   that matter modulo 8 are multiplied; pieces are added until the fraction's leading bits are known. */
static int reduce_large(const double *x, double *y, int e0, int nx)
{
    enum { JK = 4 };  /* JK + 1 pieces of 2/pi at first: the double-precision choice */
    int32_t jz, jx, jv, jp, carry, n, iq[20], i, j, k, m, q0, ih;
    double z, fw, f[20], q[20], fq[20] = {0.0};  /* fq: set before use (jz >= 0), zeroed for flow analysis */

    jp = JK;
    jx = nx - 1;
    jv = (e0 - 3) / 24;
    if (jv < 0) jv = 0;
    q0 = e0 - 24 * (jv + 1);

    /* f[0] .. f[jx + JK]: the pieces of 2/pi that meet x's, f[jx + JK] = two_over_pi[jv + JK] */
    j = jv - jx;
    m = jx + JK;
    for (i = 0; i <= m; i++, j++) f[i] = j < 0 ? 0.0 : (double)two_over_pi[j];
    for (i = 0; i <= JK; i++) {
        for (j = 0, fw = 0.0; j <= jx; j++) fw += x[j] * f[jx + i - j];
        q[i] = fw;
    }
    jz = JK;
recompute:
    /* q[] into 24-bit integers iq[], last first */
    for (i = 0, j = jz, z = q[jz]; j > 0; i++, j--) {
        fw = (double)(int32_t)(0x1p-24 * z);
        iq[i] = (int32_t)(z - 0x1p24 * fw);
        z = q[j - 1] + fw;
    }
    /* n */
    z = scale_by_power_of_2(z, q0);
    z -= 8.0 * floor_exact(z * 0.125);  /* the integer part modulo 8 */
    n = (int32_t)z;
    z -= (double)n;
    ih = 0;
    if (q0 > 0) {  /* iq[jz - 1] holds the last bits of n */
        i = iq[jz - 1] >> (24 - q0);
        n += i;
        iq[jz - 1] -= i << (24 - q0);
        ih = iq[jz - 1] >> (23 - q0);
    } else if (q0 == 0) {
        ih = iq[jz - 1] >> 23;
    } else if (z >= 0.5) {
        ih = 2;
    }
    if (ih > 0) {  /* fraction >= 1/2: n + 1 and the fraction 1 - q, negative */
        n += 1;
        carry = 0;
        for (i = 0; i < jz; i++) {
            j = iq[i];
            if (carry == 0) {
                if (j != 0) {
                    carry = 1;
                    iq[i] = 0x1000000 - j;
                }
            } else {
                iq[i] = 0xffffff - j;
            }
        }
        if (q0 > 0) {
            switch (q0) {
            case 1: iq[jz - 1] &= 0x7fffff; break;
            case 2: iq[jz - 1] &= 0x3fffff; break;
            }
        }
        if (ih == 2) {
            z = 1.0 - z;
            if (carry != 0) z -= scale_by_power_of_2(1.0, q0);
        }
    }
    /* a fraction whose known pieces cancel: more pieces of 2/pi */
    if (z == 0.0) {
        j = 0;
        for (i = jz - 1; i >= JK; i--) j |= iq[i];
        if (j == 0) {
            for (k = 1; iq[JK - k] == 0; k++) {}
            for (i = jz + 1; i <= jz + k; i++) {
                f[jx + i] = (double)two_over_pi[jv + i];
                for (j = 0, fw = 0.0; j <= jx; j++) fw += x[j] * f[jx + i - j];
                q[i] = fw;
            }
            jz += k;
            goto recompute;
        }
    }
    /* drop zero pieces, or split z into 24-bit pieces */
    if (z == 0.0) {
        jz -= 1;
        q0 -= 24;
        while (iq[jz] == 0) {
            jz--;
            q0 -= 24;
        }
    } else {
        z = scale_by_power_of_2(z, -q0);
        if (z >= 0x1p24) {
            fw = (double)(int32_t)(0x1p-24 * z);
            iq[jz] = (int32_t)(z - 0x1p24 * fw);
            jz += 1;
            q0 += 24;
            iq[jz] = (int32_t)fw;
        } else {
            iq[jz] = (int32_t)z;
        }
    }
    /* the fraction's pieces as doubles, times pi/2 */
    fw = scale_by_power_of_2(1.0, q0);
    for (i = jz; i >= 0; i--) {
        q[i] = fw * (double)iq[i];
        fw *= 0x1p-24;
    }
    for (i = jz; i >= 0; i--) {
        for (fw = 0.0, k = 0; k <= jp && k <= jz - i; k++) fw += PI_2_PIECES[k] * q[i + k];
        fq[jz - i] = fw;
    }
    /* into y[0] + y[1] */
    fw = 0.0;
    for (i = jz; i >= 0; i--) fw += fq[i];
    y[0] = ih == 0 ? fw : -fw;
    fw = fq[0] - fw;
    for (i = 1; i <= jz; i++) fw += fq[i];
    y[1] = ih == 0 ? fw : -fw;
    return n & 7;
}

/* x = n pi/2 + y[0] + y[1], |y[0] + y[1]| <= pi/4 (about); returns n (fdlibm's e_rem_pio2.c, Bruce D. Evans's
   version). The caller handles |x| <= pi/4, where no reduction is needed. */
static const double
TO_INTEGER_SIGNED = 0x1.8p52,         /* t + 1.5 2^52 - 1.5 2^52 rounds t to an integer, |t| < 2^51 */
PI_4 = 0x1.921fb54442d18p-1,
INV_PI_2 = 6.36619772367581382433e-01, /* 0x3FE45F30, 0x6DC9C883: 53 bits of 2/pi */
PI_2_1 = 1.57079632673412561417e+00,  /* 0x3FF921FB, 0x54400000: the first 33 bits of pi/2 */
PI_2_1T = 6.07710050650619224932e-11, /* 0x3DD0B461, 0x1A626331: pi/2 - PI_2_1 */
PI_2_2 = 6.07710050630396597660e-11,  /* 0x3DD0B461, 0x1A600000: the second 33 bits */
PI_2_2T = 2.02226624879595063154e-21, /* 0x3BA3198A, 0x2E037073: pi/2 - (PI_2_1 + PI_2_2) */
PI_2_3 = 2.02226624871116645580e-21,  /* 0x3BA3198A, 0x2E000000: the third 33 bits */
PI_2_3T = 8.47842766036889956997e-32; /* 0x397B839A, 0x252049C1: pi/2 - (PI_2_1 + PI_2_2 + PI_2_3) */

static int reduce(double x, double *y)
{
    const uint64_t bits = ln_bits(x);
    const int sign = (int)(bits >> 63);
    const uint32_t ix = (uint32_t)(bits >> 32) & 0x7fffffff;
    double z, w, t, r, fn, tx[3], ty[2];
    int n, ex, ey, i;

    if (ix <= 0x400f6a7a) {  /* |x| ~<= 5pi/4 */
        if ((ix & 0xfffff) == 0x921fb) goto medium;  /* |x| ~= pi/2 or 2pi/2: cancellation, the medium case */
        if (ix <= 0x4002d97c) {  /* |x| ~<= 3pi/4 */
            if (!sign) {
                z = x - PI_2_1;  /* one rounding, good to 85 bits */
                y[0] = z - PI_2_1T;
                y[1] = (z - y[0]) - PI_2_1T;
                return 1;
            }
            z = x + PI_2_1;
            y[0] = z + PI_2_1T;
            y[1] = (z - y[0]) + PI_2_1T;
            return -1;
        }
        if (!sign) {
            z = x - 2 * PI_2_1;
            y[0] = z - 2 * PI_2_1T;
            y[1] = (z - y[0]) - 2 * PI_2_1T;
            return 2;
        }
        z = x + 2 * PI_2_1;
        y[0] = z + 2 * PI_2_1T;
        y[1] = (z - y[0]) + 2 * PI_2_1T;
        return -2;
    }
    if (ix <= 0x401c463b) {  /* |x| ~<= 9pi/4 */
        if (ix <= 0x4015fdbc) {  /* |x| ~<= 7pi/4 */
            if (ix == 0x4012d97c) goto medium;  /* |x| ~= 3pi/2 */
            if (!sign) {
                z = x - 3 * PI_2_1;
                y[0] = z - 3 * PI_2_1T;
                y[1] = (z - y[0]) - 3 * PI_2_1T;
                return 3;
            }
            z = x + 3 * PI_2_1;
            y[0] = z + 3 * PI_2_1T;
            y[1] = (z - y[0]) + 3 * PI_2_1T;
            return -3;
        }
        if (ix == 0x401921fb) goto medium;  /* |x| ~= 4pi/2 */
        if (!sign) {
            z = x - 4 * PI_2_1;
            y[0] = z - 4 * PI_2_1T;
            y[1] = (z - y[0]) - 4 * PI_2_1T;
            return 4;
        }
        z = x + 4 * PI_2_1;
        y[0] = z + 4 * PI_2_1T;
        y[1] = (z - y[0]) + 4 * PI_2_1T;
        return -4;
    }
    if (ix < 0x413921fb) {  /* |x| ~< 2^20 pi/2 */
medium:
        fn = x * INV_PI_2 + TO_INTEGER_SIGNED - TO_INTEGER_SIGNED;  /* x / (pi/2) rounded to an integer */
        n = (int32_t)fn;
        r = x - fn * PI_2_1;
        w = fn * PI_2_1T;  /* first round, good to 85 bits */
        if (r - w < -PI_4) {  /* only under directed rounding */
            n--;
            fn--;
            r = x - fn * PI_2_1;
            w = fn * PI_2_1T;
        } else if (r - w > PI_4) {
            n++;
            fn++;
            r = x - fn * PI_2_1;
            w = fn * PI_2_1T;
        }
        y[0] = r - w;
        ey = (int)(ln_bits(y[0]) >> 52 & 0x7ff);
        ex = (int)(ix >> 20);
        if (ex - ey > 16) {  /* second round, good to 118 bits */
            t = r;
            w = fn * PI_2_2;
            r = t - w;
            w = fn * PI_2_2T - ((t - r) - w);
            y[0] = r - w;
            ey = (int)(ln_bits(y[0]) >> 52 & 0x7ff);
            if (ex - ey > 49) {  /* third round, good to 151 bits: every case */
                t = r;
                w = fn * PI_2_3;
                r = t - w;
                w = fn * PI_2_3T - ((t - r) - w);
                y[0] = r - w;
            }
        }
        y[1] = (r - y[0]) - w;
        return n;
    }
    /* large: |x| in 24-bit pieces, z = |x| 2^(23 - exponent(x)) */
    z = ln_from_bits((bits & (UINT64_MAX >> 12)) | (uint64_t)(0x3ff + 23) << 52);
    for (i = 0; i < 2; i++) {
        tx[i] = (double)(int32_t)z;
        z = (z - tx[i]) * 0x1p24;
    }
    tx[i] = z;
    while (tx[i] == 0.0) i--;  /* the first piece is never zero */
    n = reduce_large(tx, ty, (int)(ix >> 20) - (0x3ff + 23), i + 1);
    if (sign) {
        y[0] = -ty[0];
        y[1] = -ty[1];
        return -n;
    }
    y[0] = ty[0];
    y[1] = ty[1];
    return n;
}

double ln_sin(double x)
{
    const uint32_t ix = (uint32_t)(ln_bits(x) >> 32) & 0x7fffffff;
    double y[2];
    if (ix <= 0x3fe921fb) {  /* |x| ~<= pi/4 */
        if (ix < 0x3e500000) return x;  /* |x| < 2^-26: sin x = x to the last bit (and -0 stays -0) */
        return sin_kernel(x, 0.0, 1);
    }
    if (ix >= 0x7ff00000) return x != x ? x : NAN;  /* sin(+-inf) is NaN */
    switch (reduce(x, y) & 3) {
    case 0: return sin_kernel(y[0], y[1], 0);
    case 1: return cos_kernel(y[0], y[1]);
    case 2: return -sin_kernel(y[0], y[1], 0);
    default: return -cos_kernel(y[0], y[1]);
    }
}

double ln_cos(double x)
{
    const uint32_t ix = (uint32_t)(ln_bits(x) >> 32) & 0x7fffffff;
    double y[2];
    if (ix <= 0x3fe921fb) {  /* |x| ~<= pi/4 */
        if (ix < 0x3e46a09e) return 1.0;  /* |x| < 2^-27 sqrt(2): cos x = 1 to the last bit */
        return cos_kernel(x, 0.0);
    }
    if (ix >= 0x7ff00000) return x != x ? x : NAN;
    switch (reduce(x, y) & 3) {
    case 0: return cos_kernel(y[0], y[1]);
    case 1: return -sin_kernel(y[0], y[1], 0);
    case 2: return -cos_kernel(y[0], y[1]);
    default: return sin_kernel(y[0], y[1], 0);
    }
}

/* ---------------------------------------------------------------------------- hypot */
/* x^2 = hi + lo exactly (Dekker's product: x split into 26- and 27-bit halves by Veltkamp's constant). */
static void square(double x, double *hi, double *lo)
{
    const double xc = x * (0x1p27 + 1);
    const double xh = x - xc + xc, xl = x - xh;
    *hi = x * x;
    *lo = xh * xh - *hi + 2 * xh * xl + xl * xl;
}

double ln_hypot(double x, double y)
{
    uint64_t ix = ln_bits(x) & (UINT64_MAX >> 1), iy = ln_bits(y) & (UINT64_MAX >> 1);
    if (ix < iy) {  /* |x| >= |y| */
        const uint64_t t = ix;
        ix = iy;
        iy = t;
    }
    const int ex = (int)(ix >> 52), ey = (int)(iy >> 52);
    double a = ln_from_bits(ix), b = ln_from_bits(iy), scale = 1.0, ha, la, hb, lb;
    if (ey == 0x7ff) return b;                 /* both inf or NaN: inf wins (its bits are below a NaN's), else NaN */
    if (ex == 0x7ff || iy == 0) return a;      /* inf, NaN, or hypot(x, 0) = |x| */
    if (ex - ey > 64) return a + b;            /* b^2 below a's last bit */
    if (ex > 0x3ff + 510) {                    /* the squares would overflow, */
        scale = 0x1p700;
        a *= 0x1p-700;
        b *= 0x1p-700;
    } else if (ey < 0x3ff - 450) {             /* or the low parts underflow */
        scale = 0x1p-700;
        a *= 0x1p700;
        b *= 0x1p700;
    }
    square(a, &ha, &la);
    square(b, &hb, &lb);
    /* a^2 + b^2 = s + t to about 2^-100 of it: the high parts' sum, its rounding error (Knuth's two-sum), the low
       parts */
    const double s = ha + hb, hb_in_s = s - ha;
    const double t = ((ha - (s - hb_in_s)) + (hb - hb_in_s)) + (la + lb);
    /* sqrt(s + t) = r + (s + t - r^2) / (2 r) to second order in the residual, r = sqrt(s): one Newton step from
       the rounded root, r^2 exact, s - r^2's high part exact (r^2 is within a few ulps of s). Without it (musl's
       sqrt of the rounded sum) the error reaches 0.92 ulp; with it, the final rounding's half ulp and a little. */
    double hr, lr;
    const double r = ln_sqrt(s);
    square(r, &hr, &lr);
    return scale * (r + (((s - hr) - lr) + t) / (2.0 * r));
}

/* ---------------------------------------------------------------------------- pow */
/* log(x) = k ln2 + log(c) + log1p(z/c - 1), x = 2^k z, z in [OFF, 2 OFF) split into 128 intervals, c near an
   interval's centre, 1/c with few bits so that z/c - 1 is exact; logc rounded to 43 bits so that k ln2hi + logc
   is exact, |log(c) - logc - logctail| < 2^-97 (Arm's pow_data.c) */
static const struct { double invc, logc, logctail; } log_table[128] = {
    {0x1.6a00000000000p+0, -0x1.62c82f2b9c800p-2, 0x1.ab42428375680p-48},
    {0x1.6800000000000p+0, -0x1.5d1bdbf580800p-2, -0x1.ca508d8e0f720p-46},
    {0x1.6600000000000p+0, -0x1.5767717455800p-2, -0x1.362a4d5b6506dp-45},
    {0x1.6400000000000p+0, -0x1.51aad872df800p-2, -0x1.684e49eb067d5p-49},
    {0x1.6200000000000p+0, -0x1.4be5f95777800p-2, -0x1.41b6993293ee0p-47},
    {0x1.6000000000000p+0, -0x1.4618bc21c6000p-2, 0x1.3d82f484c84ccp-46},
    {0x1.5e00000000000p+0, -0x1.404308686a800p-2, 0x1.c42f3ed820b3ap-50},
    {0x1.5c00000000000p+0, -0x1.3a64c55694800p-2, 0x1.0b1c686519460p-45},
    {0x1.5a00000000000p+0, -0x1.347dd9a988000p-2, 0x1.5594dd4c58092p-45},
    {0x1.5800000000000p+0, -0x1.2e8e2bae12000p-2, 0x1.67b1e99b72bd8p-45},
    {0x1.5600000000000p+0, -0x1.2895a13de8800p-2, 0x1.5ca14b6cfb03fp-46},
    {0x1.5600000000000p+0, -0x1.2895a13de8800p-2, 0x1.5ca14b6cfb03fp-46},
    {0x1.5400000000000p+0, -0x1.22941fbcf7800p-2, -0x1.65a242853da76p-46},
    {0x1.5200000000000p+0, -0x1.1c898c1699800p-2, -0x1.fafbc68e75404p-46},
    {0x1.5000000000000p+0, -0x1.1675cababa800p-2, 0x1.f1fc63382a8f0p-46},
    {0x1.4e00000000000p+0, -0x1.1058bf9ae4800p-2, -0x1.6a8c4fd055a66p-45},
    {0x1.4c00000000000p+0, -0x1.0a324e2739000p-2, -0x1.c6bee7ef4030ep-47},
    {0x1.4a00000000000p+0, -0x1.0402594b4d000p-2, -0x1.036b89ef42d7fp-48},
    {0x1.4a00000000000p+0, -0x1.0402594b4d000p-2, -0x1.036b89ef42d7fp-48},
    {0x1.4800000000000p+0, -0x1.fb9186d5e4000p-3, 0x1.d572aab993c87p-47},
    {0x1.4600000000000p+0, -0x1.ef0adcbdc6000p-3, 0x1.b26b79c86af24p-45},
    {0x1.4400000000000p+0, -0x1.e27076e2af000p-3, -0x1.72f4f543fff10p-46},
    {0x1.4200000000000p+0, -0x1.d5c216b4fc000p-3, 0x1.1ba91bbca681bp-45},
    {0x1.4000000000000p+0, -0x1.c8ff7c79aa000p-3, 0x1.7794f689f8434p-45},
    {0x1.4000000000000p+0, -0x1.c8ff7c79aa000p-3, 0x1.7794f689f8434p-45},
    {0x1.3e00000000000p+0, -0x1.bc286742d9000p-3, 0x1.94eb0318bb78fp-46},
    {0x1.3c00000000000p+0, -0x1.af3c94e80c000p-3, 0x1.a4e633fcd9066p-52},
    {0x1.3a00000000000p+0, -0x1.a23bc1fe2b000p-3, -0x1.58c64dc46c1eap-45},
    {0x1.3a00000000000p+0, -0x1.a23bc1fe2b000p-3, -0x1.58c64dc46c1eap-45},
    {0x1.3800000000000p+0, -0x1.9525a9cf45000p-3, -0x1.ad1d904c1d4e3p-45},
    {0x1.3600000000000p+0, -0x1.87fa06520d000p-3, 0x1.bbdbf7fdbfa09p-45},
    {0x1.3400000000000p+0, -0x1.7ab890210e000p-3, 0x1.bdb9072534a58p-45},
    {0x1.3400000000000p+0, -0x1.7ab890210e000p-3, 0x1.bdb9072534a58p-45},
    {0x1.3200000000000p+0, -0x1.6d60fe719d000p-3, -0x1.0e46aa3b2e266p-46},
    {0x1.3000000000000p+0, -0x1.5ff3070a79000p-3, -0x1.e9e439f105039p-46},
    {0x1.3000000000000p+0, -0x1.5ff3070a79000p-3, -0x1.e9e439f105039p-46},
    {0x1.2e00000000000p+0, -0x1.526e5e3a1b000p-3, -0x1.0de8b90075b8fp-45},
    {0x1.2c00000000000p+0, -0x1.44d2b6ccb8000p-3, 0x1.70cc16135783cp-46},
    {0x1.2c00000000000p+0, -0x1.44d2b6ccb8000p-3, 0x1.70cc16135783cp-46},
    {0x1.2a00000000000p+0, -0x1.371fc201e9000p-3, 0x1.178864d27543ap-48},
    {0x1.2800000000000p+0, -0x1.29552f81ff000p-3, -0x1.48d301771c408p-45},
    {0x1.2600000000000p+0, -0x1.1b72ad52f6000p-3, -0x1.e80a41811a396p-45},
    {0x1.2600000000000p+0, -0x1.1b72ad52f6000p-3, -0x1.e80a41811a396p-45},
    {0x1.2400000000000p+0, -0x1.0d77e7cd09000p-3, 0x1.a699688e85bf4p-47},
    {0x1.2400000000000p+0, -0x1.0d77e7cd09000p-3, 0x1.a699688e85bf4p-47},
    {0x1.2200000000000p+0, -0x1.fec9131dbe000p-4, -0x1.575545ca333f2p-45},
    {0x1.2000000000000p+0, -0x1.e27076e2b0000p-4, 0x1.a342c2af0003cp-45},
    {0x1.2000000000000p+0, -0x1.e27076e2b0000p-4, 0x1.a342c2af0003cp-45},
    {0x1.1e00000000000p+0, -0x1.c5e548f5bc000p-4, -0x1.d0c57585fbe06p-46},
    {0x1.1c00000000000p+0, -0x1.a926d3a4ae000p-4, 0x1.53935e85baac8p-45},
    {0x1.1c00000000000p+0, -0x1.a926d3a4ae000p-4, 0x1.53935e85baac8p-45},
    {0x1.1a00000000000p+0, -0x1.8c345d631a000p-4, 0x1.37c294d2f5668p-46},
    {0x1.1a00000000000p+0, -0x1.8c345d631a000p-4, 0x1.37c294d2f5668p-46},
    {0x1.1800000000000p+0, -0x1.6f0d28ae56000p-4, -0x1.69737c93373dap-45},
    {0x1.1600000000000p+0, -0x1.51b073f062000p-4, 0x1.f025b61c65e57p-46},
    {0x1.1600000000000p+0, -0x1.51b073f062000p-4, 0x1.f025b61c65e57p-46},
    {0x1.1400000000000p+0, -0x1.341d7961be000p-4, 0x1.c5edaccf913dfp-45},
    {0x1.1400000000000p+0, -0x1.341d7961be000p-4, 0x1.c5edaccf913dfp-45},
    {0x1.1200000000000p+0, -0x1.16536eea38000p-4, 0x1.47c5e768fa309p-46},
    {0x1.1000000000000p+0, -0x1.f0a30c0118000p-5, 0x1.d599e83368e91p-45},
    {0x1.1000000000000p+0, -0x1.f0a30c0118000p-5, 0x1.d599e83368e91p-45},
    {0x1.0e00000000000p+0, -0x1.b42dd71198000p-5, 0x1.c827ae5d6704cp-46},
    {0x1.0e00000000000p+0, -0x1.b42dd71198000p-5, 0x1.c827ae5d6704cp-46},
    {0x1.0c00000000000p+0, -0x1.77458f632c000p-5, -0x1.cfc4634f2a1eep-45},
    {0x1.0c00000000000p+0, -0x1.77458f632c000p-5, -0x1.cfc4634f2a1eep-45},
    {0x1.0a00000000000p+0, -0x1.39e87b9fec000p-5, 0x1.502b7f526feaap-48},
    {0x1.0a00000000000p+0, -0x1.39e87b9fec000p-5, 0x1.502b7f526feaap-48},
    {0x1.0800000000000p+0, -0x1.f829b0e780000p-6, -0x1.980267c7e09e4p-45},
    {0x1.0800000000000p+0, -0x1.f829b0e780000p-6, -0x1.980267c7e09e4p-45},
    {0x1.0600000000000p+0, -0x1.7b91b07d58000p-6, -0x1.88d5493faa639p-45},
    {0x1.0400000000000p+0, -0x1.fc0a8b0fc0000p-7, -0x1.f1e7cf6d3a69cp-50},
    {0x1.0400000000000p+0, -0x1.fc0a8b0fc0000p-7, -0x1.f1e7cf6d3a69cp-50},
    {0x1.0200000000000p+0, -0x1.fe02a6b100000p-8, -0x1.9e23f0dda40e4p-46},
    {0x1.0200000000000p+0, -0x1.fe02a6b100000p-8, -0x1.9e23f0dda40e4p-46},
    {0x1.0000000000000p+0, 0x0.0000000000000p+0, 0x0.0000000000000p+0},
    {0x1.0000000000000p+0, 0x0.0000000000000p+0, 0x0.0000000000000p+0},
    {0x1.fc00000000000p-1, 0x1.0101575890000p-7, -0x1.0c76b999d2be8p-46},
    {0x1.f800000000000p-1, 0x1.0205658938000p-6, -0x1.3dc5b06e2f7d2p-45},
    {0x1.f400000000000p-1, 0x1.8492528c90000p-6, -0x1.aa0ba325a0c34p-45},
    {0x1.f000000000000p-1, 0x1.0415d89e74000p-5, 0x1.111c05cf1d753p-47},
    {0x1.ec00000000000p-1, 0x1.466aed42e0000p-5, -0x1.c167375bdfd28p-45},
    {0x1.e800000000000p-1, 0x1.894aa149fc000p-5, -0x1.97995d05a267dp-46},
    {0x1.e400000000000p-1, 0x1.ccb73cdddc000p-5, -0x1.a68f247d82807p-46},
    {0x1.e200000000000p-1, 0x1.eea31c006c000p-5, -0x1.e113e4fc93b7bp-47},
    {0x1.de00000000000p-1, 0x1.1973bd1466000p-4, -0x1.5325d560d9e9bp-45},
    {0x1.da00000000000p-1, 0x1.3bdf5a7d1e000p-4, 0x1.cc85ea5db4ed7p-45},
    {0x1.d600000000000p-1, 0x1.5e95a4d97a000p-4, -0x1.c69063c5d1d1ep-45},
    {0x1.d400000000000p-1, 0x1.700d30aeac000p-4, 0x1.c1e8da99ded32p-49},
    {0x1.d000000000000p-1, 0x1.9335e5d594000p-4, 0x1.3115c3abd47dap-45},
    {0x1.cc00000000000p-1, 0x1.b6ac88dad6000p-4, -0x1.390802bf768e5p-46},
    {0x1.ca00000000000p-1, 0x1.c885801bc4000p-4, 0x1.646d1c65aacd3p-45},
    {0x1.c600000000000p-1, 0x1.ec739830a2000p-4, -0x1.dc068afe645e0p-45},
    {0x1.c400000000000p-1, 0x1.fe89139dbe000p-4, -0x1.534d64fa10afdp-45},
    {0x1.c000000000000p-1, 0x1.1178e8227e000p-3, 0x1.1ef78ce2d07f2p-45},
    {0x1.be00000000000p-1, 0x1.1aa2b7e23f000p-3, 0x1.ca78e44389934p-45},
    {0x1.ba00000000000p-1, 0x1.2d1610c868000p-3, 0x1.39d6ccb81b4a1p-47},
    {0x1.b800000000000p-1, 0x1.365fcb0159000p-3, 0x1.62fa8234b7289p-51},
    {0x1.b400000000000p-1, 0x1.4913d8333b000p-3, 0x1.5837954fdb678p-45},
    {0x1.b200000000000p-1, 0x1.527e5e4a1b000p-3, 0x1.633e8e5697dc7p-45},
    {0x1.ae00000000000p-1, 0x1.6574ebe8c1000p-3, 0x1.9cf8b2c3c2e78p-46},
    {0x1.ac00000000000p-1, 0x1.6f0128b757000p-3, -0x1.5118de59c21e1p-45},
    {0x1.aa00000000000p-1, 0x1.7898d85445000p-3, -0x1.c661070914305p-46},
    {0x1.a600000000000p-1, 0x1.8beafeb390000p-3, -0x1.73d54aae92cd1p-47},
    {0x1.a400000000000p-1, 0x1.95a5adcf70000p-3, 0x1.7f22858a0ff6fp-47},
    {0x1.a000000000000p-1, 0x1.a93ed3c8ae000p-3, -0x1.8724350562169p-45},
    {0x1.9e00000000000p-1, 0x1.b31d8575bd000p-3, -0x1.c358d4eace1aap-47},
    {0x1.9c00000000000p-1, 0x1.bd087383be000p-3, -0x1.d4bc4595412b6p-45},
    {0x1.9a00000000000p-1, 0x1.c6ffbc6f01000p-3, -0x1.1ec72c5962bd2p-48},
    {0x1.9600000000000p-1, 0x1.db13db0d49000p-3, -0x1.aff2af715b035p-45},
    {0x1.9400000000000p-1, 0x1.e530effe71000p-3, 0x1.212276041f430p-51},
    {0x1.9200000000000p-1, 0x1.ef5ade4dd0000p-3, -0x1.a211565bb8e11p-51},
    {0x1.9000000000000p-1, 0x1.f991c6cb3b000p-3, 0x1.bcbecca0cdf30p-46},
    {0x1.8c00000000000p-1, 0x1.07138604d5800p-2, 0x1.89cdb16ed4e91p-48},
    {0x1.8a00000000000p-1, 0x1.0c42d67616000p-2, 0x1.7188b163ceae9p-45},
    {0x1.8800000000000p-1, 0x1.1178e8227e800p-2, -0x1.c210e63a5f01cp-45},
    {0x1.8600000000000p-1, 0x1.16b5ccbacf800p-2, 0x1.b9acdf7a51681p-45},
    {0x1.8400000000000p-1, 0x1.1bf99635a6800p-2, 0x1.ca6ed5147bdb7p-45},
    {0x1.8200000000000p-1, 0x1.214456d0eb800p-2, 0x1.a87deba46baeap-47},
    {0x1.7e00000000000p-1, 0x1.2bef07cdc9000p-2, 0x1.a9cfa4a5004f4p-45},
    {0x1.7c00000000000p-1, 0x1.314f1e1d36000p-2, -0x1.8e27ad3213cb8p-45},
    {0x1.7a00000000000p-1, 0x1.36b6776be1000p-2, 0x1.16ecdb0f177c8p-46},
    {0x1.7800000000000p-1, 0x1.3c25277333000p-2, 0x1.83b54b606bd5cp-46},
    {0x1.7600000000000p-1, 0x1.419b423d5e800p-2, 0x1.8e436ec90e09dp-47},
    {0x1.7400000000000p-1, 0x1.4718dc271c800p-2, -0x1.f27ce0967d675p-45},
    {0x1.7200000000000p-1, 0x1.4c9e09e173000p-2, -0x1.e20891b0ad8a4p-45},
    {0x1.7000000000000p-1, 0x1.522ae0738a000p-2, 0x1.ebe708164c759p-45},
    {0x1.6e00000000000p-1, 0x1.57bf753c8d000p-2, 0x1.fadedee5d40efp-46},
    {0x1.6c00000000000p-1, 0x1.5d5bddf596000p-2, -0x1.a0b2a08a465dcp-47},
};
static const double
LN2_HI = 0x1.62e42fefa3800p-1, LN2_LO = 0x1.ef35793c76730p-45,
/* log1p(r) - r ~ r^2 (A0 + r A1 + ...), relative error 2^-70 on |r| < 0x1.6bp-8, scaled as evaluated below */
A0 = -0x1p-1, A1 = 0x1.555555555556p-2 * -2, A2 = -0x1.0000000000006p-2 * -2, A3 = 0x1.999999959554ep-3 * 4,
A4 = -0x1.555555529a47ap-3 * 4, A5 = 0x1.2495b9b4845e9p-3 * -8, A6 = -0x1.0002b8b263fc3p-3 * -8;
#define LOG_OFF UINT64_C(0x3fe6955500000000)

/* hi + tail = log(x) with about 15 more bits than a double; ix is x's bits, a subnormal normalized with the
   exponent's sign bit. Without fused multiply-add: the products are split so that they stay exact. */
static double log_extended(uint64_t ix, double *tail)
{
    const uint64_t tmp = ix - LOG_OFF;
    const int i = (int)((tmp >> (52 - 7)) % 128);
    const int k = (int)(tmp >> 52) - ((tmp >> 63) ? 4096 : 0);  /* the top 12 bits, signed */
    const uint64_t iz = ix - (tmp & UINT64_C(0xfff) << 52);
    const double z = ln_from_bits(iz), kd = (double)k;
    const double invc = log_table[i].invc, logc = log_table[i].logc, logctail = log_table[i].logctail;
    /* r = z/c - 1 = rhi + rlo, with rhi, rlo and rhi*rhi exact and |rlo| <= |r| */
    const double zhi = ln_from_bits((iz + (UINT64_C(1) << 31)) & UINT64_C(0xffffffff00000000));
    const double zlo = z - zhi;
    const double rhi = zhi * invc - 1.0, rlo = zlo * invc, r = rhi + rlo;
    /* k ln2 + log(c) + r */
    const double t1 = kd * LN2_HI + logc, t2 = t1 + r;
    const double lo1 = kd * LN2_LO + logctail, lo2 = t1 - t2 + r;
    /* + A0 r^2 */
    const double ar = A0 * r, ar2 = r * ar, ar3 = r * ar2;
    const double arhi = A0 * rhi, arhi2 = rhi * arhi;
    const double hi = t2 + arhi2;
    const double lo3 = rlo * (ar + arhi), lo4 = t2 - hi + arhi2;
    /* + the rest of log1p(r) */
    const double p = ar3 * (A1 + r * A2 + ar2 * (A3 + r * A4 + ar2 * (A5 + r * A6)));
    const double lo = lo1 + lo2 + lo3 + lo4 + p, y = hi + lo;
    *tail = hi - y + lo;
    return y;
}

/* exp(x) = 2^(k/128) exp(r), |r| <= ln2/256; 2^(k/128) ~ scale (1 + tail) from a table of 128 pairs (tab[2j]: the
   tail's bits, tab[2j+1]: the scale's bits less j 2^52/128), exp(r) - 1 by a polynomial: 0.511 ulp without fused
   multiply-add (Arm's exp_data.c) */
static const uint64_t exp_table[256] = {
    UINT64_C(0x0), UINT64_C(0x3ff0000000000000),
    UINT64_C(0x3c9b3b4f1a88bf6e), UINT64_C(0x3feff63da9fb3335),
    UINT64_C(0xbc7160139cd8dc5d), UINT64_C(0x3fefec9a3e778061),
    UINT64_C(0xbc905e7a108766d1), UINT64_C(0x3fefe315e86e7f85),
    UINT64_C(0x3c8cd2523567f613), UINT64_C(0x3fefd9b0d3158574),
    UINT64_C(0xbc8bce8023f98efa), UINT64_C(0x3fefd06b29ddf6de),
    UINT64_C(0x3c60f74e61e6c861), UINT64_C(0x3fefc74518759bc8),
    UINT64_C(0x3c90a3e45b33d399), UINT64_C(0x3fefbe3ecac6f383),
    UINT64_C(0x3c979aa65d837b6d), UINT64_C(0x3fefb5586cf9890f),
    UINT64_C(0x3c8eb51a92fdeffc), UINT64_C(0x3fefac922b7247f7),
    UINT64_C(0x3c3ebe3d702f9cd1), UINT64_C(0x3fefa3ec32d3d1a2),
    UINT64_C(0xbc6a033489906e0b), UINT64_C(0x3fef9b66affed31b),
    UINT64_C(0xbc9556522a2fbd0e), UINT64_C(0x3fef9301d0125b51),
    UINT64_C(0xbc5080ef8c4eea55), UINT64_C(0x3fef8abdc06c31cc),
    UINT64_C(0xbc91c923b9d5f416), UINT64_C(0x3fef829aaea92de0),
    UINT64_C(0x3c80d3e3e95c55af), UINT64_C(0x3fef7a98c8a58e51),
    UINT64_C(0xbc801b15eaa59348), UINT64_C(0x3fef72b83c7d517b),
    UINT64_C(0xbc8f1ff055de323d), UINT64_C(0x3fef6af9388c8dea),
    UINT64_C(0x3c8b898c3f1353bf), UINT64_C(0x3fef635beb6fcb75),
    UINT64_C(0xbc96d99c7611eb26), UINT64_C(0x3fef5be084045cd4),
    UINT64_C(0x3c9aecf73e3a2f60), UINT64_C(0x3fef54873168b9aa),
    UINT64_C(0xbc8fe782cb86389d), UINT64_C(0x3fef4d5022fcd91d),
    UINT64_C(0x3c8a6f4144a6c38d), UINT64_C(0x3fef463b88628cd6),
    UINT64_C(0x3c807a05b0e4047d), UINT64_C(0x3fef3f49917ddc96),
    UINT64_C(0x3c968efde3a8a894), UINT64_C(0x3fef387a6e756238),
    UINT64_C(0x3c875e18f274487d), UINT64_C(0x3fef31ce4fb2a63f),
    UINT64_C(0x3c80472b981fe7f2), UINT64_C(0x3fef2b4565e27cdd),
    UINT64_C(0xbc96b87b3f71085e), UINT64_C(0x3fef24dfe1f56381),
    UINT64_C(0x3c82f7e16d09ab31), UINT64_C(0x3fef1e9df51fdee1),
    UINT64_C(0xbc3d219b1a6fbffa), UINT64_C(0x3fef187fd0dad990),
    UINT64_C(0x3c8b3782720c0ab4), UINT64_C(0x3fef1285a6e4030b),
    UINT64_C(0x3c6e149289cecb8f), UINT64_C(0x3fef0cafa93e2f56),
    UINT64_C(0x3c834d754db0abb6), UINT64_C(0x3fef06fe0a31b715),
    UINT64_C(0x3c864201e2ac744c), UINT64_C(0x3fef0170fc4cd831),
    UINT64_C(0x3c8fdd395dd3f84a), UINT64_C(0x3feefc08b26416ff),
    UINT64_C(0xbc86a3803b8e5b04), UINT64_C(0x3feef6c55f929ff1),
    UINT64_C(0xbc924aedcc4b5068), UINT64_C(0x3feef1a7373aa9cb),
    UINT64_C(0xbc9907f81b512d8e), UINT64_C(0x3feeecae6d05d866),
    UINT64_C(0xbc71d1e83e9436d2), UINT64_C(0x3feee7db34e59ff7),
    UINT64_C(0xbc991919b3ce1b15), UINT64_C(0x3feee32dc313a8e5),
    UINT64_C(0x3c859f48a72a4c6d), UINT64_C(0x3feedea64c123422),
    UINT64_C(0xbc9312607a28698a), UINT64_C(0x3feeda4504ac801c),
    UINT64_C(0xbc58a78f4817895b), UINT64_C(0x3feed60a21f72e2a),
    UINT64_C(0xbc7c2c9b67499a1b), UINT64_C(0x3feed1f5d950a897),
    UINT64_C(0x3c4363ed60c2ac11), UINT64_C(0x3feece086061892d),
    UINT64_C(0x3c9666093b0664ef), UINT64_C(0x3feeca41ed1d0057),
    UINT64_C(0x3c6ecce1daa10379), UINT64_C(0x3feec6a2b5c13cd0),
    UINT64_C(0x3c93ff8e3f0f1230), UINT64_C(0x3feec32af0d7d3de),
    UINT64_C(0x3c7690cebb7aafb0), UINT64_C(0x3feebfdad5362a27),
    UINT64_C(0x3c931dbdeb54e077), UINT64_C(0x3feebcb299fddd0d),
    UINT64_C(0xbc8f94340071a38e), UINT64_C(0x3feeb9b2769d2ca7),
    UINT64_C(0xbc87deccdc93a349), UINT64_C(0x3feeb6daa2cf6642),
    UINT64_C(0xbc78dec6bd0f385f), UINT64_C(0x3feeb42b569d4f82),
    UINT64_C(0xbc861246ec7b5cf6), UINT64_C(0x3feeb1a4ca5d920f),
    UINT64_C(0x3c93350518fdd78e), UINT64_C(0x3feeaf4736b527da),
    UINT64_C(0x3c7b98b72f8a9b05), UINT64_C(0x3feead12d497c7fd),
    UINT64_C(0x3c9063e1e21c5409), UINT64_C(0x3feeab07dd485429),
    UINT64_C(0x3c34c7855019c6ea), UINT64_C(0x3feea9268a5946b7),
    UINT64_C(0x3c9432e62b64c035), UINT64_C(0x3feea76f15ad2148),
    UINT64_C(0xbc8ce44a6199769f), UINT64_C(0x3feea5e1b976dc09),
    UINT64_C(0xbc8c33c53bef4da8), UINT64_C(0x3feea47eb03a5585),
    UINT64_C(0xbc845378892be9ae), UINT64_C(0x3feea34634ccc320),
    UINT64_C(0xbc93cedd78565858), UINT64_C(0x3feea23882552225),
    UINT64_C(0x3c5710aa807e1964), UINT64_C(0x3feea155d44ca973),
    UINT64_C(0xbc93b3efbf5e2228), UINT64_C(0x3feea09e667f3bcd),
    UINT64_C(0xbc6a12ad8734b982), UINT64_C(0x3feea012750bdabf),
    UINT64_C(0xbc6367efb86da9ee), UINT64_C(0x3fee9fb23c651a2f),
    UINT64_C(0xbc80dc3d54e08851), UINT64_C(0x3fee9f7df9519484),
    UINT64_C(0xbc781f647e5a3ecf), UINT64_C(0x3fee9f75e8ec5f74),
    UINT64_C(0xbc86ee4ac08b7db0), UINT64_C(0x3fee9f9a48a58174),
    UINT64_C(0xbc8619321e55e68a), UINT64_C(0x3fee9feb564267c9),
    UINT64_C(0x3c909ccb5e09d4d3), UINT64_C(0x3feea0694fde5d3f),
    UINT64_C(0xbc7b32dcb94da51d), UINT64_C(0x3feea11473eb0187),
    UINT64_C(0x3c94ecfd5467c06b), UINT64_C(0x3feea1ed0130c132),
    UINT64_C(0x3c65ebe1abd66c55), UINT64_C(0x3feea2f336cf4e62),
    UINT64_C(0xbc88a1c52fb3cf42), UINT64_C(0x3feea427543e1a12),
    UINT64_C(0xbc9369b6f13b3734), UINT64_C(0x3feea589994cce13),
    UINT64_C(0xbc805e843a19ff1e), UINT64_C(0x3feea71a4623c7ad),
    UINT64_C(0xbc94d450d872576e), UINT64_C(0x3feea8d99b4492ed),
    UINT64_C(0x3c90ad675b0e8a00), UINT64_C(0x3feeaac7d98a6699),
    UINT64_C(0x3c8db72fc1f0eab4), UINT64_C(0x3feeace5422aa0db),
    UINT64_C(0xbc65b6609cc5e7ff), UINT64_C(0x3feeaf3216b5448c),
    UINT64_C(0x3c7bf68359f35f44), UINT64_C(0x3feeb1ae99157736),
    UINT64_C(0xbc93091fa71e3d83), UINT64_C(0x3feeb45b0b91ffc6),
    UINT64_C(0xbc5da9b88b6c1e29), UINT64_C(0x3feeb737b0cdc5e5),
    UINT64_C(0xbc6c23f97c90b959), UINT64_C(0x3feeba44cbc8520f),
    UINT64_C(0xbc92434322f4f9aa), UINT64_C(0x3feebd829fde4e50),
    UINT64_C(0xbc85ca6cd7668e4b), UINT64_C(0x3feec0f170ca07ba),
    UINT64_C(0x3c71affc2b91ce27), UINT64_C(0x3feec49182a3f090),
    UINT64_C(0x3c6dd235e10a73bb), UINT64_C(0x3feec86319e32323),
    UINT64_C(0xbc87c50422622263), UINT64_C(0x3feecc667b5de565),
    UINT64_C(0x3c8b1c86e3e231d5), UINT64_C(0x3feed09bec4a2d33),
    UINT64_C(0xbc91bbd1d3bcbb15), UINT64_C(0x3feed503b23e255d),
    UINT64_C(0x3c90cc319cee31d2), UINT64_C(0x3feed99e1330b358),
    UINT64_C(0x3c8469846e735ab3), UINT64_C(0x3feede6b5579fdbf),
    UINT64_C(0xbc82dfcd978e9db4), UINT64_C(0x3feee36bbfd3f37a),
    UINT64_C(0x3c8c1a7792cb3387), UINT64_C(0x3feee89f995ad3ad),
    UINT64_C(0xbc907b8f4ad1d9fa), UINT64_C(0x3feeee07298db666),
    UINT64_C(0xbc55c3d956dcaeba), UINT64_C(0x3feef3a2b84f15fb),
    UINT64_C(0xbc90a40e3da6f640), UINT64_C(0x3feef9728de5593a),
    UINT64_C(0xbc68d6f438ad9334), UINT64_C(0x3feeff76f2fb5e47),
    UINT64_C(0xbc91eee26b588a35), UINT64_C(0x3fef05b030a1064a),
    UINT64_C(0x3c74ffd70a5fddcd), UINT64_C(0x3fef0c1e904bc1d2),
    UINT64_C(0xbc91bdfbfa9298ac), UINT64_C(0x3fef12c25bd71e09),
    UINT64_C(0x3c736eae30af0cb3), UINT64_C(0x3fef199bdd85529c),
    UINT64_C(0x3c8ee3325c9ffd94), UINT64_C(0x3fef20ab5fffd07a),
    UINT64_C(0x3c84e08fd10959ac), UINT64_C(0x3fef27f12e57d14b),
    UINT64_C(0x3c63cdaf384e1a67), UINT64_C(0x3fef2f6d9406e7b5),
    UINT64_C(0x3c676b2c6c921968), UINT64_C(0x3fef3720dcef9069),
    UINT64_C(0xbc808a1883ccb5d2), UINT64_C(0x3fef3f0b555dc3fa),
    UINT64_C(0xbc8fad5d3ffffa6f), UINT64_C(0x3fef472d4a07897c),
    UINT64_C(0xbc900dae3875a949), UINT64_C(0x3fef4f87080d89f2),
    UINT64_C(0x3c74a385a63d07a7), UINT64_C(0x3fef5818dcfba487),
    UINT64_C(0xbc82919e2040220f), UINT64_C(0x3fef60e316c98398),
    UINT64_C(0x3c8e5a50d5c192ac), UINT64_C(0x3fef69e603db3285),
    UINT64_C(0x3c843a59ac016b4b), UINT64_C(0x3fef7321f301b460),
    UINT64_C(0xbc82d52107b43e1f), UINT64_C(0x3fef7c97337b9b5f),
    UINT64_C(0xbc892ab93b470dc9), UINT64_C(0x3fef864614f5a129),
    UINT64_C(0x3c74b604603a88d3), UINT64_C(0x3fef902ee78b3ff6),
    UINT64_C(0x3c83c5ec519d7271), UINT64_C(0x3fef9a51fbc74c83),
    UINT64_C(0xbc8ff7128fd391f0), UINT64_C(0x3fefa4afa2a490da),
    UINT64_C(0xbc8dae98e223747d), UINT64_C(0x3fefaf482d8e67f1),
    UINT64_C(0x3c8ec3bc41aa2008), UINT64_C(0x3fefba1bee615a27),
    UINT64_C(0x3c842b94c3a9eb32), UINT64_C(0x3fefc52b376bba97),
    UINT64_C(0x3c8a64a931d185ee), UINT64_C(0x3fefd0765b6e4540),
    UINT64_C(0xbc8e37bae43be3ed), UINT64_C(0x3fefdbfdad9cbe14),
    UINT64_C(0x3c77893b4d91cd9d), UINT64_C(0x3fefe7c1819e90d8),
    UINT64_C(0x3c5305c14160cc89), UINT64_C(0x3feff3c22b8f71f1),
};
static const double
INV_LN2_N = 0x1.71547652b82fep0 * 128, NEG_LN2_HI_N = -0x1.62e42fefa0000p-8, NEG_LN2_LO_N = -0x1.cf79abc9e3b3ap-47,
EXP_SHIFT = 0x1.8p52,  /* z + shift - shift rounds z to an integer; the sum's low bits are that integer */
E2 = 0x1.ffffffffffdbdp-2, E3 = 0x1.555555555543cp-3, E4 = 0x1.55555cf172b91p-5, E5 = 0x1.1111167a4d017p-7;
#define SIGN_BIAS (UINT64_C(0x800) << 7)  /* added to k: the result's sign bit, for a negative x to an odd y */

static uint32_t top12(double x) { return (uint32_t)(ln_bits(x) >> 52); }

/* scale (1 + tmp) where the scale's exponent, bits sbits, may have overflowed: positive k (bit 31 of ki clear) may
   overflow, negative k may underflow into the subnormals, where y is rounded once before it is scaled so that it is
   not rounded twice */
static double exp_special(double tmp, uint64_t sbits, uint64_t ki)
{
    double scale, y;
    if ((ki & 0x80000000) == 0) {
        sbits -= UINT64_C(1009) << 52;
        scale = ln_from_bits(sbits);
        return 0x1p1009 * (scale + scale * tmp);
    }
    sbits += UINT64_C(1022) << 52;
    scale = ln_from_bits(sbits);
    y = scale + scale * tmp;
    if (fabs(y) < 1.0) {
        const double one = y < 0.0 ? -1.0 : 1.0;
        double lo = scale - y + scale * tmp;
        const double hi = one + y;
        lo = one - hi + y + lo;
        y = (hi + lo) - one;
        if (y == 0.0) y = ln_from_bits(sbits & UINT64_C(0x8000000000000000));  /* the zero's sign */
    }
    return 0x1p-1022 * y;
}

/* sign exp(x + xtail), |xtail| < 2^-8/128 and |xtail| <= |x|; sign_bias is SIGN_BIAS for a negative result */
static double exp_extended(double x, double xtail, uint64_t sign_bias)
{
    uint32_t abstop = top12(x) & 0x7ff;
    if (abstop - top12(0x1p-54) >= top12(512.0) - top12(0x1p-54)) {
        if (abstop - top12(0x1p-54) >= 0x80000000) {  /* |x| < 2^-54: 1 (+ x, for the rounding) */
            const double one = 1.0 + x;
            return sign_bias ? -one : one;
        }
        if (abstop >= top12(1024.0)) {  /* overflow or underflow (inf and NaN were handled before) */
            if (ln_bits(x) >> 63) return sign_bias ? -0.0 : 0.0;
            return sign_bias ? -INFINITY : INFINITY;
        }
        abstop = 0;  /* large |x|: exp_special below */
    }
    /* x = k ln2/128 + r, |r| <= ln2/256 */
    const double z = INV_LN2_N * x;
    double kd = z + EXP_SHIFT;
    const uint64_t ki = ln_bits(kd);
    kd -= EXP_SHIFT;
    double r = x + kd * NEG_LN2_HI_N + kd * NEG_LN2_LO_N;
    r += xtail;  /* 2^-200 < |xtail| < 2^-8/128 */
    const uint64_t idx = 2 * (ki % 128), top = (ki + sign_bias) << (52 - 7);
    const double tail = ln_from_bits(exp_table[idx]);
    const uint64_t sbits = exp_table[idx + 1] + top;  /* a valid scale for -1023 128 < k < 1024 128 */
    /* exp(x) ~ scale + scale (tail + exp(r) - 1) */
    const double r2 = r * r;
    const double tmp = tail + r + r2 * (E2 + r * E3) + r2 * r2 * (E4 + r * E5);
    if (abstop == 0) return exp_special(tmp, sbits, ki);
    const double scale = ln_from_bits(sbits);
    return scale + scale * tmp;
}

/* 0 if iy (a non-zero finite y's bits) is not an integer, 1 if an odd one, 2 if an even one */
static int integer_kind(uint64_t iy)
{
    const int e = (int)(iy >> 52 & 0x7ff);
    if (e < 0x3ff) return 0;
    if (e > 0x3ff + 52) return 2;
    if (iy & ((UINT64_C(1) << (0x3ff + 52 - e)) - 1)) return 0;
    if (iy & (UINT64_C(1) << (0x3ff + 52 - e))) return 1;
    return 2;
}

/* whether i is the bits of a zero, an infinity or a NaN */
static int zero_inf_nan(uint64_t i) { return 2 * i - 1 >= 2 * ln_bits(INFINITY) - 1; }

double ln_pow(double x, double y)
{
    uint64_t sign_bias = 0, ix = ln_bits(x);
    const uint64_t iy = ln_bits(y);
    uint32_t topx = top12(x);
    const uint32_t topy = top12(y);
    if (topx - 0x001 >= 0x7ff - 0x001 || (topy & 0x7ff) - 0x3be >= 0x43e - 0x3be) {
        /* x < 2^-1022 (subnormal, zero, negative), inf or NaN; or |y| < 2^-65, |y| >= 2^63, NaN */
        if (zero_inf_nan(iy)) {
            if (2 * iy == 0) return 1.0;                          /* x^0 = 1, NaN too */
            if (ix == ln_bits(1.0)) return 1.0;                   /* 1^y = 1, NaN too */
            if (2 * ix > 2 * ln_bits(INFINITY) || 2 * iy > 2 * ln_bits(INFINITY)) return x + y;  /* NaN */
            if (2 * ix == 2 * ln_bits(1.0)) return 1.0;           /* (-1)^+-inf */
            if ((2 * ix < 2 * ln_bits(1.0)) == !(iy >> 63)) return 0.0;  /* |x| < 1, y = inf; |x| > 1, y = -inf */
            return y * y;                                         /* +inf */
        }
        if (zero_inf_nan(ix)) {
            double x2 = x * x;
            if ((ix >> 63) && integer_kind(iy) == 1) x2 = -x2;
            return (iy >> 63) ? 1 / x2 : x2;
        }
        /* x and y finite, non-zero */
        if (ix >> 63) {
            const int yint = integer_kind(iy);
            if (yint == 0) return NAN;  /* a negative number to a non-integer */
            if (yint == 1) sign_bias = SIGN_BIAS;
            ix &= UINT64_C(0x7fffffffffffffff);
            topx &= 0x7ff;
        }
        if ((topy & 0x7ff) - 0x3be >= 0x43e - 0x3be) {
            if (ix == ln_bits(1.0)) return 1.0;
            if ((topy & 0x7ff) < 0x3be) return ix > ln_bits(1.0) ? 1.0 + y : 1.0 - y;  /* |y| < 2^-65: 1 + y log x */
            return (ix > ln_bits(1.0)) == (topy < 0x800) ? INFINITY : 0.0;
        }
        if (topx == 0) {  /* subnormal x: normalized, the exponent negative */
            ix = ln_bits(x * 0x1p52) & UINT64_C(0x7fffffffffffffff);
            ix -= UINT64_C(52) << 52;
        }
    }
    double lo;
    const double hi = log_extended(ix, &lo);
    /* y log(x) = ehi + elo, the product split so that it is exact without fused multiply-add */
    const double yhi = ln_from_bits(iy & UINT64_C(0xfffffffff8000000)), ylo = y - yhi;
    const double lhi = ln_from_bits(ln_bits(hi) & UINT64_C(0xfffffffff8000000)), llo = hi - lhi + lo;
    const double ehi = yhi * lhi, elo = ylo * lhi + y * llo;  /* |elo| < |ehi| 2^-25 */
    return exp_extended(ehi, elo, sign_bias);
}

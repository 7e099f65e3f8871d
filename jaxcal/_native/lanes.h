// Vectors of W lanes (poses) for the kernels of chain.cc, and sin/cos on them.
#pragma once

#include <cstdint>

#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace {

// W lanes (poses) as one value (GCC/Clang vector extensions): one AVX-512 register of 8, else 4
// (one AVX register, two NEON ones). With 8 lanes on AVX2 the 12 entries of a running frame took
// 24 of its 16 registers and the chain spilled: in a build without AVX-512 on an AVX-512 host the
// chain took 81 cycles per pose with 8 lanes (the kernel before 2026-11-23) and 16 with 4 (phases
// timed as in benchmarks/bench_kernel_phases.py).
#if defined(__AVX512F__)
constexpr int W = 8;
#else
constexpr int W = 4;
#endif
typedef double vec __attribute__((vector_size(8 * W)));
typedef uint64_t uvec __attribute__((vector_size(8 * W)));
inline vec loadv(const double *p) { vec v; __builtin_memcpy(&v, p, sizeof v); return v; }
inline void storev(double *p, vec v) { __builtin_memcpy(p, &v, sizeof v); }

// sin and cos of 8 angles, |x| <= jaxcal.trig.DOMAIN. Both forms take n = round(x k/pi) by the
// shifter 1.5 * 2^52 (after the addition the integer n sits in the low bits of t's mantissa, two's
// complement mod 2^51, so n mod 16 is read off the bits) and r = x - n pi/k in three parts
// (Cody-Waite with jaxcal/trig.py's split of pi/2, scaled: n P1 and n P2 exact for |n| < 2^20).
#if defined(__AVX512F__)
// With AVX-512, k = 8 and a table of the 16 multiples of pi/8: |r| <= pi/16, sin r and cos r by
// Taylor series to r^11 and r^10 (the first omitted terms, r^13/13! and r^12/12!, at most 1.0e-19
// and 6.7e-18), then sin x = sin(n pi/8) cos r + cos(n pi/8) sin r and cos x = cos(n pi/8) cos r -
// sin(n pi/8) sin r, sin(n pi/8) and cos(n pi/8) looked up by n mod 16 with one two-register
// permute each. About 23 vector operations for 8 sincos, against ~30 for the quadrant form below
// and ~58 for the Taylor form on |r| <= pi/4 with a floating-point quadrant that both replaced
// (benchmarks/bench_kernel_phases.py).
constexpr double SIN16[16] = {0.0, 0.3826834323650898, 0.7071067811865476, 0.9238795325112867, 1.0,
                              0.9238795325112867, 0.7071067811865476, 0.3826834323650898, 0.0,
                              -0.3826834323650898, -0.7071067811865476, -0.9238795325112867, -1.0,
                              -0.9238795325112867, -0.7071067811865476, -0.3826834323650898};
constexpr double COS16[16] = {1.0, 0.9238795325112867, 0.7071067811865476, 0.3826834323650898, 0.0,
                              -0.3826834323650898, -0.7071067811865476, -0.9238795325112867, -1.0,
                              -0.9238795325112867, -0.7071067811865476, -0.3826834323650898, 0.0,
                              0.3826834323650898, 0.7071067811865476, 0.9238795325112867};

inline vec lookup16(const double *table, uvec k) {  // table[k mod 16] per lane
  return (vec)_mm512_permutex2var_pd(_mm512_loadu_pd(table), (__m512i)k, _mm512_loadu_pd(table + 8));
}

inline void sincos_lanes(vec x, vec &s_out, vec &c_out) {
  const double shifter = 6755399441055744.0;  // 1.5 * 2^52
  const double p1 = 1.5707963267341256 / 4, p2 = 6.077100506303966e-11 / 4, p3 = 2.0222662487959506e-21 / 4;
  const vec t = x * 2.5464790894703255 + shifter;  // 8/pi
  const vec n = t - shifter;
  const vec r = ((x - n * p1) - n * p2) - n * p3;
  const vec z = r * r;
  const vec s = r + (r * z) * (-1.0 / 6 + z * (1.0 / 120 + z * (-1.0 / 5040 + z * (1.0 / 362880
                + z * (-1.0 / 39916800)))));
  const vec c = (1.0 - 0.5 * z) + (z * z) * (1.0 / 24 + z * (-1.0 / 720 + z * (1.0 / 40320 + z * (-1.0 / 3628800))));
  const uvec k = (uvec)t;
  const vec sn = lookup16(SIN16, k), cn = lookup16(COS16, k);
  s_out = sn * c + cn * s;
  c_out = cn * c - sn * s;
}
#else
// Without AVX-512 (no two-register permute; a gather or per-lane loads cost more than they save),
// k = 2 and jaxcal/trig.py's polynomials on |r| <= pi/4 (fdlibm's minimax, to r^13 and r^14); odd
// n swaps sin and cos, and the signs are bit 1 of n (sin) and of n + 1 (cos), xor-ed into the sign
// bit, all as bit operations on the lanes (no vector conditionals, which not every compiler has).
inline void sincos_lanes(vec x, vec &s_out, vec &c_out) {
  const double shifter = 6755399441055744.0;  // 1.5 * 2^52
  const double p1 = 1.5707963267341256, p2 = 6.077100506303966e-11, p3 = 2.0222662487959506e-21;
  const double S1 = -1.66666666666666324348e-01, S2 = 8.33333333332248946124e-03, S3 = -1.98412698298579493134e-04,
               S4 = 2.75573137070700676789e-06, S5 = -2.50507602534068634195e-08, S6 = 1.58969099521155010221e-10;
  const double C1 = 4.16666666666666019037e-02, C2 = -1.38888888888741095749e-03, C3 = 2.48015872894767294178e-05,
               C4 = -2.75573143513906633035e-07, C5 = 2.08757232129817482790e-09, C6 = -1.13596475577881948265e-11;
  const vec t = x * 0.6366197723675814 + shifter;  // 2/pi
  const vec n = t - shifter;
  const vec r = ((x - n * p1) - n * p2) - n * p3;
  const vec z = r * r;
  const uvec s = (uvec)(r + (r * z) * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6))))));
  const uvec c = (uvec)((1.0 - 0.5 * z) + (z * z) * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6))))));
  const uvec k = (uvec)t, odd = -(k & 1), sign = uvec{} + (uint64_t(1) << 63);
  s_out = (vec)(((s & ~odd) | (c & odd)) ^ ((k << 62) & sign));
  c_out = (vec)(((c & ~odd) | (s & odd)) ^ (((k + 1) << 62) & sign));
}
#endif

inline void sincos1(double x, double *s, double *c) {
  vec sv, cv;
  sincos_lanes(vec{} + x, sv, cv);
  *s = sv[0];
  *c = cv[0];
}

#if defined(__AVX512F__)
// r[i][l] <- r[l][i]: an 8 x 8 transpose in registers (24 shuffles).
inline void transpose8(__m512d r[8]) {
  const __m512i i1 = _mm512_setr_epi64(0, 1, 8, 9, 4, 5, 12, 13), i2 = _mm512_setr_epi64(2, 3, 10, 11, 6, 7, 14, 15);
  const __m512i i3 = _mm512_setr_epi64(0, 1, 2, 3, 8, 9, 10, 11), i4 = _mm512_setr_epi64(4, 5, 6, 7, 12, 13, 14, 15);
  __m512d t[8], u[8];
  for (int i = 0; i < 8; i += 2) {
    t[i] = _mm512_unpacklo_pd(r[i], r[i + 1]);
    t[i + 1] = _mm512_unpackhi_pd(r[i], r[i + 1]);
  }
  for (int h = 0; h < 8; h += 4) {
    u[h] = _mm512_permutex2var_pd(t[h], i1, t[h + 2]);
    u[h + 1] = _mm512_permutex2var_pd(t[h + 1], i1, t[h + 3]);
    u[h + 2] = _mm512_permutex2var_pd(t[h], i2, t[h + 2]);
    u[h + 3] = _mm512_permutex2var_pd(t[h + 1], i2, t[h + 3]);
  }
  for (int j = 0; j < 4; ++j) {
    r[j] = _mm512_permutex2var_pd(u[j], i3, u[j + 4]);
    r[j + 4] = _mm512_permutex2var_pd(u[j], i4, u[j + 4]);
  }
}
#endif

}  // namespace

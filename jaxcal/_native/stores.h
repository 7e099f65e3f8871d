// Writing W lanes' end poses (or a tile of Jacobian columns) out of the kernels of chain.cc:
// pose-major through register transposes, or with the pose axis last.
#pragma once

#include <cstdint>

#include "lanes.h"

namespace {

// out[b * rows + e] = X[e * S + b] for b < m: a tile written pose-major. With AVX-512, 8 x 8
// blocks are transposed in registers (the strided gathers of the plain loop cost the Jacobian
// more than computing it); with AVX (AVX2 machines), 4 x 4 blocks; the rest take the plain loop.
template <int S>
inline void store_tile(int rows, int m, const double *X, double *out) {
  int b0 = 0;
#if defined(__AVX512F__)
  if (rows % 8 == 0) {
    for (; b0 + 8 <= m; b0 += 8) {
      for (int e0 = 0; e0 < rows; e0 += 8) {
        __m512d r[8];
        for (int i = 0; i < 8; ++i) r[i] = _mm512_loadu_pd(X + (e0 + i) * S + b0);
        transpose8(r);
        for (int j = 0; j < 8; ++j) _mm512_storeu_pd(out + (int64_t)(b0 + j) * rows + e0, r[j]);
      }
    }
  }
#endif
#if defined(__AVX__)
  if (rows % 4 == 0) {  // 4 x 4 blocks (AVX2 machines, and AVX-512 ones for the rest)
    for (; b0 + 4 <= m; b0 += 4) {
      for (int e0 = 0; e0 < rows; e0 += 4) {
        const __m256d r0 = _mm256_loadu_pd(X + (e0 + 0) * S + b0), r1 = _mm256_loadu_pd(X + (e0 + 1) * S + b0),
                      r2 = _mm256_loadu_pd(X + (e0 + 2) * S + b0), r3 = _mm256_loadu_pd(X + (e0 + 3) * S + b0);
        const __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1),
                      t2 = _mm256_unpacklo_pd(r2, r3), t3 = _mm256_unpackhi_pd(r2, r3);
        double *o = out + (int64_t)b0 * rows + e0;
        _mm256_storeu_pd(o, _mm256_permute2f128_pd(t0, t2, 0x20));
        _mm256_storeu_pd(o + rows, _mm256_permute2f128_pd(t1, t3, 0x20));
        _mm256_storeu_pd(o + 2 * rows, _mm256_permute2f128_pd(t0, t2, 0x31));
        _mm256_storeu_pd(o + 3 * rows, _mm256_permute2f128_pd(t1, t3, 0x31));
      }
    }
  }
#endif
  for (int b = b0; b < m; ++b)
#pragma omp simd
    for (int e = 0; e < rows; ++e) out[(int64_t)b * rows + e] = X[e * S + b];
}

// The end poses of lanes 0 .. m-1 (m <= W) written pose-major, 16 doubles each (the last row
// (0, 0, 0, 1)). With AVX-512 and all 8 lanes, straight from registers: rows 0..7 as one 8 x 8
// transpose, rows 8..11 as 4 x 8 (eight shuffles for eight poses), the constant quarter of each
// pose as one 256-bit store (the shuffle port bounds this store); otherwise through a tile.
inline void store_pose_major(const vec E[12], int m, double *out) {
#if defined(__AVX512F__)
  if (m == 8) {
    __m512d r[8];
    for (int i = 0; i < 8; ++i) r[i] = (__m512d)E[i];
    transpose8(r);
    for (int b = 0; b < 8; ++b) _mm512_storeu_pd(out + 16 * b, r[b]);
    const __m512i i1 = _mm512_setr_epi64(0, 1, 8, 9, 2, 3, 10, 11), i2 = _mm512_setr_epi64(4, 5, 12, 13, 6, 7, 14, 15);
    const __m256d last = _mm256_setr_pd(0.0, 0.0, 0.0, 1.0);
    const __m512d a = (__m512d)E[8], b = (__m512d)E[9], c = (__m512d)E[10], d = (__m512d)E[11];
    const __m512d t0 = _mm512_unpacklo_pd(a, b), t1 = _mm512_unpackhi_pd(a, b), t2 = _mm512_unpacklo_pd(c, d),
                  t3 = _mm512_unpackhi_pd(c, d);
    // u = poses (0, 2), (4, 6), (1, 3), (5, 7) of the eight, rows 8..11 each
    const __m512d u[4] = {_mm512_permutex2var_pd(t0, i1, t2), _mm512_permutex2var_pd(t0, i2, t2),
                          _mm512_permutex2var_pd(t1, i1, t3), _mm512_permutex2var_pd(t1, i2, t3)};
    const int first[4] = {0, 4, 1, 5};
    for (int h = 0; h < 4; ++h) {
      double *o = out + 16 * first[h] + 8;
      _mm256_storeu_pd(o, _mm512_castpd512_pd256(u[h]));
      _mm256_storeu_pd(o + 32, _mm512_extractf64x4_pd(u[h], 1));
      _mm256_storeu_pd(o + 4, last);
      _mm256_storeu_pd(o + 36, last);
    }
    return;
  }
#endif
  double X[16][W];
  for (int e = 0; e < 12; ++e) storev(X[e], E[e]);
  for (int e = 12; e < 16; ++e) storev(X[e], vec{} + (e == 15 ? 1.0 : 0.0));
  store_tile<W>(16, m, &X[0][0], out);
}

// The end poses of lanes 0 .. m-1 (m <= W) with the pose axis last: entry e of lane l at
// out[e * K + l]. No transpose: plain stores.
inline void store_pose_last(const vec E[12], int m, int64_t K, double *out) {
  for (int e = 0; e < 16; ++e) {
    const vec v = e < 12 ? E[e] : vec{} + (e == 15 ? 1.0 : 0.0);
    if (m == W) {
      storev(out + e * K, v);
    } else {
      for (int l = 0; l < m; ++l) out[e * K + l] = v[l];
    }
  }
}

}  // namespace

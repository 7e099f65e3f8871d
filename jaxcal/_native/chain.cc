// Fused CPU kernels for forward kinematics and the identification Jacobian, called from JAX
// through the XLA FFI (jaxcal/_native/__init__.py compiles and registers them; the pure-JAX
// code in kinematics.py / error_model.py is the reference and the fallback, and the tests
// compare the two).
//
// Why: XLA CPU materialises every link's 12 entries for all poses between links and computed
// float64 sin/cos one value at a time; here a block of BLK poses gets all its sincos first, then
// runs through all links 8 poses at a time with the running transform in registers
// (benchmarks/bench_roofline.py measures both).
//
// Layout: q (B, K, n) joint values, B robots (leading batch axes flattened) of K poses each;
// dh (B, n, 4) rows (theta, d, a, alpha); rev (n) 1.0 revolute / 0.0 prismatic (or (B, n));
// base, tool (B, 4, 4). A robot-side buffer with a single robot's worth of entries is shared by
// all B. Outputs: T (B, K, 4, 4); J (B, K, rows, 4n), columns link-major (theta, d, a, alpha),
// rows dp (3) then dphi (3) as in error_model._columns (pose rows).
// Standard DH link (paper eq. 1): R = [[c, -s ca, s sa], [s, c ca, -c sa], [0, sa, ca]],
//   t = (a c, a s, d). Modified DH: R = [[c, -s, 0], [s ca, c ca, -sa], [s sa, c sa, ca]],
//   t = (a, -sa d, ca d).
// sin/cos of theta: the polynomial of jaxcal/trig.py (Cody-Waite by pi/2, Taylor to r^17/r^18).
#include <cmath>
#include <cstddef>
#include <cstdint>

#if defined(__linux__)
#include <sys/mman.h>
#endif

#if defined(__AVX__)
#include <immintrin.h>
#endif

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

constexpr int BLK = 64;
constexpr int MAXN = 16;  // joints; longer chains use the pure-JAX path

inline void sincos_poly(double x, double *s_out, double *c_out) {
  const double p1 = 1.5707963267341256, p2 = 6.077100506303966e-11, p3 = 2.0222662487959506e-21;
  double n = std::nearbyint(x * 0.6366197723675814);
  double r = ((x - n * p1) - n * p2) - n * p3;
  double r2 = r * r;
  double s = r * (1.0 + r2 * (-1.0 / 6 + r2 * (1.0 / 120 + r2 * (-1.0 / 5040 + r2 * (1.0 / 362880
             + r2 * (-1.0 / 39916800 + r2 * (1.0 / 6227020800.0 + r2 * (-1.0 / 1307674368000.0
             + r2 * (1.0 / 355687428096000.0)))))))));
  double c = 1.0 + r2 * (-0.5 + r2 * (1.0 / 24 + r2 * (-1.0 / 720 + r2 * (1.0 / 40320
             + r2 * (-1.0 / 3628800 + r2 * (1.0 / 479001600.0 + r2 * (-1.0 / 87178291200.0
             + r2 * (1.0 / 20922789888000.0 + r2 * (-1.0 / 6402373705728000.0)))))))));
  // The quadrant n mod 4 as k = n - 4 round(n/4) in {-2, ..., 2}, in floating point (exact for
  // |n| < 2^53). Without AVX-512 there is no vector conversion of doubles to 64-bit integers,
  // and GCC 12 does not vectorise std::floor in an omp simd loop: either kept it from
  // vectorising the whole loop over poses on AVX2 (with the 4 x 4 stores below, FK was 3.1x
  // and the Jacobian 2.4x slower than now on a Zen 3 host: benchmarks/bench_kernel_ab.py).
  const double k = n - 4.0 * std::nearbyint(n * 0.25), ak = std::fabs(k);
  const bool odd = ak == 1.0;
  const double ss = odd ? c : s, cc = odd ? s : c;
  *s_out = (k == -1.0 || ak == 2.0) ? -ss : ss;  // quadrants 2, 3
  *c_out = (k == 1.0 || ak == 2.0) ? -cc : cc;   // quadrants 1, 2
}

struct Problem {
  int64_t B, K, n;
  const double *q, *dh, *rev, *base, *tool;
  int64_t dh_stride, rev_stride, base_stride, tool_stride;  // 0 when shared by all robots
  bool mdh;
};

// A block: m <= BLK consecutive poses k0 .. k0+m-1 of one robot r (blocks never straddle
// robots, so every link constant is a scalar per block). Lanes m.. repeat pose k0 (written
// nowhere).
struct Block {
  int64_t r, k0;
  int m;
  double qT[MAXN][BLK];
};

// A frame per lane, F[e][b]: rotation entries e = 0..8 row-major, translation e = 9..11.
using Frame = double[12][BLK];

// The joint values of a block, joint-major. A full block is read with one strided (gather)
// loop per joint; the scalar loop this replaced took ~9 of the ~48 cycles per pose of FK.
inline void block_init(const Problem &P, int64_t ib, Block &blk) {
  const int64_t per = (P.K + BLK - 1) / BLK, n = P.n;
  blk.r = ib / per;
  blk.k0 = (ib % per) * BLK;
  blk.m = static_cast<int>(P.K - blk.k0 < BLK ? P.K - blk.k0 : BLK);
  const double *q = P.q + (blk.r * P.K + blk.k0) * n;
  if (blk.m == BLK) {
    for (int64_t j = 0; j < n; ++j)
#pragma omp simd
      for (int b = 0; b < BLK; ++b) blk.qT[j][b] = q[b * n + j];
  } else {
    for (int b = 0; b < BLK; ++b) {
      const double *qb = q + (b < blk.m ? b : 0) * n;
      for (int64_t j = 0; j < n; ++j) blk.qT[j][b] = qb[j];
    }
  }
}

// Every link of a block: cos/sin of theta and d per lane, a and cos/sin of alpha per link
// (all joints first, so that many independent sincos are in flight).
struct Links {
  double c[MAXN][BLK], s[MAXN][BLK], d[MAXN][BLK], a[MAXN], ca[MAXN], sa[MAXN];
};

inline void link_values(const Problem &P, const Block &blk, Links &L) {
  const double *dh = P.dh + blk.r * P.dh_stride, *rev = P.rev + blk.r * P.rev_stride;
#pragma omp simd
  for (int64_t j = 0; j < P.n; ++j) {
    L.a[j] = dh[4 * j + 2];
    sincos_poly(dh[4 * j + 3], &L.sa[j], &L.ca[j]);
  }
  for (int64_t j = 0; j < P.n; ++j) {
    const double rv = rev[j], th0 = dh[4 * j], d0 = dh[4 * j + 1];
#pragma omp simd
    for (int b = 0; b < BLK; ++b) {
      sincos_poly(th0 + blk.qT[j][b] * rv, &L.s[j][b], &L.c[j][b]);
      L.d[j][b] = d0 + blk.qT[j][b] * (1.0 - rv);
    }
  }
}

// Eight lanes as one value; GCC and Clang lower it to the target's widest vectors (one AVX-512
// register, two AVX ones, four NEON ones).
typedef double v8d __attribute__((vector_size(64)));
inline v8d load8(const double *p) { v8d v; __builtin_memcpy(&v, p, sizeof v); return v; }
inline void store8(double *p, v8d v) { __builtin_memcpy(p, &v, sizeof v); }

// The lanes g .. g+7 of a block through every link, the running frame R (12 entries) in
// registers; each frame after a link is also stored into Fs[j + 1] when Fs is given (the
// Jacobian), and the last one into Fend. Fo = Fi * A_j row by row, as two plane rotations
// (paper eq. 1: SDH A = Rz(theta) Tz(d) Tx(a) Rx(alpha); MDH A = Rx(alpha) Tx(a) Rz(theta)
// Tz(d)), 16 FLOP per row:
//   SDH: u = x c + y s, v = y c - x s; row (u, v ca + z sa, z ca - v sa); t += a u + d z.
//   MDH: y' = y ca + z sa, z' = z ca - y sa; row (x c + y' s, y' c - x s, z'); t += a x + d z'.
// Loading and storing a frame of 12 x 64 lanes per link instead cost FK ~5 % more.
template <bool MDH>
inline void chain8(const Problem &P, const Block &blk, const Links &L, int g, Frame *Fs, Frame &Fend) {
  const double *T = P.base + blk.r * P.base_stride;
  v8d R[12];
  for (int e = 0; e < 12; ++e) R[e] = v8d{} + (e < 9 ? T[4 * (e / 3) + e % 3] : T[4 * (e - 9) + 3]);
  if (Fs != nullptr)
    for (int e = 0; e < 12; ++e) store8(&Fs[0][e][g], R[e]);
  for (int64_t j = 0; j < P.n; ++j) {
    const v8d c = load8(&L.c[j][g]), s = load8(&L.s[j][g]), d = load8(&L.d[j][g]);
    const double ca = L.ca[j], sa = L.sa[j], a = L.a[j];
    for (int r = 0; r < 3; ++r) {
      const v8d x = R[3 * r], y = R[3 * r + 1], z = R[3 * r + 2];
      if (!MDH) {
        const v8d u = x * c + y * s, v = y * c - x * s;
        R[3 * r] = u;
        R[3 * r + 1] = v * ca + z * sa;
        R[3 * r + 2] = z * ca - v * sa;
        R[9 + r] = R[9 + r] + u * a + z * d;
      } else {
        const v8d y1 = y * ca + z * sa, z1 = z * ca - y * sa;
        R[3 * r] = x * c + y1 * s;
        R[3 * r + 1] = y1 * c - x * s;
        R[3 * r + 2] = z1;
        R[9 + r] = R[9 + r] + x * a + z1 * d;
      }
    }
    if (Fs != nullptr)
      for (int e = 0; e < 12; ++e) store8(&Fs[j + 1][e][g], R[e]);
  }
  if (Fs == nullptr)
    for (int e = 0; e < 12; ++e) store8(&Fend[e][g], R[e]);
}

// The frames of a whole block: the end frame into Fend, and every frame into Fs when given.
inline void chain(const Problem &P, const Block &blk, const Links &L, Frame *Fs, Frame &Fend) {
  for (int g = 0; g < BLK; g += 8) {
    if (P.mdh) chain8<true>(P, blk, L, g, Fs, Fend); else chain8<false>(P, blk, L, g, Fs, Fend);
  }
}

// out[b * rows + e] = X[e * S + b] for b < m: a tile written pose-major. With AVX-512, 8 x 8
// blocks are transposed in registers (the strided gathers of the plain loop cost the Jacobian
// more than computing it); with AVX (AVX2 machines), 4 x 4 blocks; the rest take the plain loop.
template <int S = BLK>
inline void store_tile(int rows, int m, const double *X, double *out, int64_t ostride = 0) {
  const int64_t os = ostride ? ostride : rows;
  int b0 = 0;
#if defined(__AVX512F__)
  if (rows % 8 == 0) {
    const __m512i i1 = _mm512_setr_epi64(0, 1, 8, 9, 4, 5, 12, 13), i2 = _mm512_setr_epi64(2, 3, 10, 11, 6, 7, 14, 15);
    const __m512i i3 = _mm512_setr_epi64(0, 1, 2, 3, 8, 9, 10, 11), i4 = _mm512_setr_epi64(4, 5, 6, 7, 12, 13, 14, 15);
    for (; b0 + 8 <= m; b0 += 8) {
      for (int e0 = 0; e0 < rows; e0 += 8) {
        __m512d r[8], t[8], u[8];
        for (int i = 0; i < 8; ++i) r[i] = _mm512_loadu_pd(X + (e0 + i) * S + b0);
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
          _mm512_storeu_pd(out + (int64_t)(b0 + j) * os + e0, _mm512_permutex2var_pd(u[j], i3, u[j + 4]));
          _mm512_storeu_pd(out + (int64_t)(b0 + j + 4) * os + e0, _mm512_permutex2var_pd(u[j], i4, u[j + 4]));
        }
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
        double *o = out + (int64_t)b0 * os + e0;
        _mm256_storeu_pd(o, _mm256_permute2f128_pd(t0, t2, 0x20));
        _mm256_storeu_pd(o + os, _mm256_permute2f128_pd(t1, t3, 0x20));
        _mm256_storeu_pd(o + 2 * os, _mm256_permute2f128_pd(t0, t2, 0x31));
        _mm256_storeu_pd(o + 3 * os, _mm256_permute2f128_pd(t1, t3, 0x31));
      }
    }
  }
#endif
  for (int b = b0; b < m; ++b)
#pragma omp simd
    for (int e = 0; e < rows; ++e) out[(int64_t)b * os + e] = X[e * S + b];
}

// store_tile(16, m, X, out) for the end poses, whose rows 12..15 are (0, 0, 0, 1): with AVX-512,
// rows 0..7 as one 8 x 8 transpose, rows 8..11 as 4 x 8 (eight shuffles for eight poses) and the
// constant quarter of each pose as one 256-bit store, a third fewer shuffles than two 8 x 8
// transposes (the shuffle port bounds this store).
inline void store_poses(int m, const double *X, double *out) {
  int b0 = 0;
#if defined(__AVX512F__)
  const __m512i i1 = _mm512_setr_epi64(0, 1, 8, 9, 2, 3, 10, 11), i2 = _mm512_setr_epi64(4, 5, 12, 13, 6, 7, 14, 15);
  const __m256d last = _mm256_setr_pd(0.0, 0.0, 0.0, 1.0);
  for (; b0 + 8 <= m; b0 += 8) {
    store_tile<BLK>(8, 8, X + b0, out + 16 * b0, 16);
    const __m512d a = _mm512_loadu_pd(X + 8 * BLK + b0), b = _mm512_loadu_pd(X + 9 * BLK + b0),
                  c = _mm512_loadu_pd(X + 10 * BLK + b0), d = _mm512_loadu_pd(X + 11 * BLK + b0);
    const __m512d t0 = _mm512_unpacklo_pd(a, b), t1 = _mm512_unpackhi_pd(a, b), t2 = _mm512_unpacklo_pd(c, d),
                  t3 = _mm512_unpackhi_pd(c, d);
    // u = poses (0, 2), (4, 6), (1, 3), (5, 7) of the eight, rows 8..11 each
    const __m512d u[4] = {_mm512_permutex2var_pd(t0, i1, t2), _mm512_permutex2var_pd(t0, i2, t2),
                          _mm512_permutex2var_pd(t1, i1, t3), _mm512_permutex2var_pd(t1, i2, t3)};
    const int first[4] = {0, 4, 1, 5};
    for (int h = 0; h < 4; ++h) {
      double *o = out + 16 * (int64_t)(b0 + first[h]) + 8;
      _mm256_storeu_pd(o, _mm512_castpd512_pd256(u[h]));
      _mm256_storeu_pd(o + 32, _mm512_extractf64x4_pd(u[h], 1));
      _mm256_storeu_pd(o + 4, last);
      _mm256_storeu_pd(o + 36, last);
    }
  }
#endif
  if (b0 < m) store_tile(16, m - b0, X + b0, out + 16 * (int64_t)b0);
}

// End pose with the tool into T (pose-major, 16 per pose; skipped when T_out is null); the
// end position per lane into pe.
inline void write_end(const Problem &P, const Block &blk, const Frame &F, double pe[3][BLK],
                      double *T_out) {
  const double *tool = P.tool + blk.r * P.tool_stride;
  double Tt[16][BLK];
#pragma omp simd
  for (int b = 0; b < BLK; ++b) {
    for (int r = 0; r < 3; ++r) {
      const double x = F[3 * r][b], y = F[3 * r + 1][b], z = F[3 * r + 2][b];
      for (int col = 0; col < 3; ++col) Tt[4 * r + col][b] = x * tool[col] + y * tool[4 + col] + z * tool[8 + col];
      Tt[4 * r + 3][b] = x * tool[3] + y * tool[7] + z * tool[11] + F[9 + r][b];
      pe[r][b] = Tt[4 * r + 3][b];
    }
    Tt[12][b] = 0.0; Tt[13][b] = 0.0; Tt[14][b] = 0.0; Tt[15][b] = 1.0;
  }
  if (T_out != nullptr) store_poses(blk.m, &Tt[0][0], T_out + 16 * (blk.r * P.K + blk.k0));
}

// Ask Linux for 2 MiB pages behind a large output buffer. XLA gives every call a fresh buffer,
// which glibc maps from the kernel beyond 32 MiB; touching it 4 KiB page by page cost the
// 10^5-pose Jacobian (115 MB) 28,000 page faults per call, ~30 ms against ~4 ms of computing
// (benchmarks/bench_roofline.py counts them). Only the 2 MiB-aligned interior of the buffer is
// advised; a hint, a no-op where transparent huge pages are off.
inline void advise_huge(void *p, size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  const uintptr_t H = uintptr_t(2) << 20, lo = reinterpret_cast<uintptr_t>(p), a = (lo + H - 1) & ~(H - 1),
                  e = (lo + bytes) & ~(H - 1);
  if (bytes >= 2 * H && e > a) madvise(reinterpret_cast<void *>(a), e - a, MADV_HUGEPAGE);
#else
  (void)p, (void)bytes;
#endif
}

int64_t n_blocks(const Problem &P) { return P.B * ((P.K + BLK - 1) / BLK); }

void fk_kernel(const Problem &P, double *T_out) {
#pragma omp parallel for schedule(static)
  for (int64_t ib = 0; ib < n_blocks(P); ++ib) {
    Block blk;
    Links L;
    Frame F;
    double pe[3][BLK];
    block_init(P, ib, blk);
    link_values(P, blk, L);
    chain(P, blk, L, nullptr, F);
    write_end(P, blk, F, pe, T_out);
  }
}

// The 4 columns of link i for the 8 poses b0 .. b0+7 of the block, into the tile
// J[(row * m + 4i + k) * 8 + l] (8 poses: the tile stays in L1 and is written out at once).
// Each column is the unit twist of one DH parameter: a rotation about an axis u through a point
// o, dp = u x (p_end - o) and dphi = u, or a translation along u, dp = u and dphi = 0. These are
// derivatives.omega_twist_entries carried into the world frame through the frames around link i
// (error_model._columns is the twist form, and the tests hold the two together):
//   SDH (eq. 5): theta about z_{i-1} through o_{i-1}, d along z_{i-1}, a along x_i, alpha about
//     x_i through o_i;
//   MDH (eq. 7, corrected): theta about z_i through o_i, d along z_i, a along x_{i-1}, alpha
//     about x_{i-1} through o_{i-1}.
// So z comes from Fz and x from Fx, the frames before (Fb = F[i]) or after (Fa = F[i+1]) link i:
// two cross products per link, nothing multiplied by a zero entry of a twist.
template <int ROWS>
inline void link_columns(int64_t m, int64_t i, const Frame &Fz, const Frame &Fx, const double pe[3][BLK], int b0,
                         double *J) {
  double *J0 = J + 4 * i * 8;
#pragma omp simd
  for (int l = 0; l < 8; ++l) {
    const int b = b0 + l;
    const double z0 = Fz[2][b], z1 = Fz[5][b], z2 = Fz[8][b], x0 = Fx[0][b], x1 = Fx[3][b], x2 = Fx[6][b];
    const double lz0 = pe[0][b] - Fz[9][b], lz1 = pe[1][b] - Fz[10][b], lz2 = pe[2][b] - Fz[11][b];
    const double lx0 = pe[0][b] - Fx[9][b], lx1 = pe[1][b] - Fx[10][b], lx2 = pe[2][b] - Fx[11][b];
    auto col = [&](int k, double p0, double p1, double p2, double w0, double w1, double w2) {
      double *out = J0 + k * 8 + l;
      out[0] = p0; out[m * 8] = p1; out[2 * m * 8] = p2;
      if (ROWS == 6) {
        out[3 * m * 8] = w0; out[4 * m * 8] = w1; out[5 * m * 8] = w2;
      }
    };
    col(0, z1 * lz2 - z2 * lz1, z2 * lz0 - z0 * lz2, z0 * lz1 - z1 * lz0, z0, z1, z2);  // theta: about z
    col(1, z0, z1, z2, 0.0, 0.0, 0.0);                                                   // d: along z
    col(2, x0, x1, x2, 0.0, 0.0, 0.0);                                                   // a: along x
    col(3, x1 * lx2 - x2 * lx1, x2 * lx0 - x0 * lx2, x0 * lx1 - x1 * lx0, x0, x1, x2);  // alpha: about x
  }
}

void jac_kernel(const Problem &P, int rows, double *J_out, double *T_out) {
  const int64_t m = 4 * P.n;
#pragma omp parallel for schedule(static)
  for (int64_t ib = 0; ib < n_blocks(P); ++ib) {
    static thread_local Block blk;
    static thread_local Frame F[MAXN + 1];  // F[0] the base, F[j + 1] the frame after link j
    static thread_local double Jt[6 * 4 * MAXN * 8];
    static thread_local Links L;
    double pe[3][BLK];
    block_init(P, ib, blk);
    link_values(P, blk, L);
    chain(P, blk, L, F, F[P.n]);
    write_end(P, blk, F[P.n], pe, T_out);
    for (int b0 = 0; b0 < blk.m; b0 += 8) {
      for (int64_t i = 0; i < P.n; ++i) {
        const Frame &Fz = P.mdh ? F[i + 1] : F[i], &Fx = P.mdh ? F[i] : F[i + 1];
        if (rows == 6) link_columns<6>(m, i, Fz, Fx, pe, b0, Jt); else link_columns<3>(m, i, Fz, Fx, pe, b0, Jt);
      }
      store_tile<8>(rows * m, blk.m - b0 < 8 ? blk.m - b0 : 8, Jt, J_out + rows * m * (blk.r * P.K + blk.k0 + b0));
    }
  }
}

ffi::Error make_problem(ffi::Buffer<ffi::F64> &q, ffi::Buffer<ffi::F64> &dh, ffi::Buffer<ffi::F64> &rev,
                        ffi::Buffer<ffi::F64> &base, ffi::Buffer<ffi::F64> &tool, int64_t mdh, Problem &P) {
  auto qd = q.dimensions(), dd = dh.dimensions();
  if (qd.size() < 1 || dd.size() < 2 || dd.back() != 4) return ffi::Error::InvalidArgument("jaxcal native: bad shapes");
  P.n = dd[dd.size() - 2];
  if (P.n < 1 || P.n > MAXN || qd.back() != P.n) return ffi::Error::InvalidArgument("jaxcal native: q and dh disagree on n");
  int64_t nq = q.element_count() / P.n, ndh = dh.element_count() / (4 * P.n);
  P.B = ndh;
  if (nq % ndh != 0) return ffi::Error::InvalidArgument("jaxcal native: q is not batched like dh");
  P.K = nq / ndh;
  P.q = q.typed_data(); P.dh = dh.typed_data(); P.rev = rev.typed_data();
  P.base = base.typed_data(); P.tool = tool.typed_data();
  P.dh_stride = ndh > 1 ? 4 * P.n : 0;
  P.rev_stride = (rev.element_count() == P.n) ? 0 : P.n;
  P.base_stride = (base.element_count() == 16) ? 0 : 16;
  P.tool_stride = (tool.element_count() == 16) ? 0 : 16;
  if ((P.rev_stride && rev.element_count() != P.n * P.B) || (P.base_stride && base.element_count() != 16 * P.B) ||
      (P.tool_stride && tool.element_count() != 16 * P.B))
    return ffi::Error::InvalidArgument("jaxcal native: robot buffers are not batched like dh");
  P.mdh = mdh != 0;
  return ffi::Error::Success();
}

ffi::Error FkImpl(ffi::Buffer<ffi::F64> q, ffi::Buffer<ffi::F64> dh, ffi::Buffer<ffi::F64> rev,
                  ffi::Buffer<ffi::F64> base, ffi::Buffer<ffi::F64> tool, ffi::ResultBuffer<ffi::F64> T,
                  int64_t mdh) {
  Problem P;
  ffi::Error err = make_problem(q, dh, rev, base, tool, mdh, P);
  if (err.failure()) return err;
  if (T->element_count() != 16 * P.B * P.K) return ffi::Error::InvalidArgument("jaxcal native: bad output shape");
  advise_huge(T->typed_data(), T->size_bytes());
  fk_kernel(P, T->typed_data());
  return ffi::Error::Success();
}

ffi::Error JacImpl(ffi::Buffer<ffi::F64> q, ffi::Buffer<ffi::F64> dh, ffi::Buffer<ffi::F64> rev,
                   ffi::Buffer<ffi::F64> base, ffi::Buffer<ffi::F64> tool, ffi::ResultBuffer<ffi::F64> J,
                   ffi::ResultBuffer<ffi::F64> T, int64_t mdh, int64_t rows) {
  Problem P;
  ffi::Error err = make_problem(q, dh, rev, base, tool, mdh, P);
  if (err.failure()) return err;
  if ((rows != 3 && rows != 6) || J->element_count() != rows * 4 * P.n * P.B * P.K ||
      T->element_count() != 16 * P.B * P.K)
    return ffi::Error::InvalidArgument("jaxcal native: bad output shape");
  advise_huge(J->typed_data(), J->size_bytes());
  advise_huge(T->typed_data(), T->size_bytes());
  jac_kernel(P, static_cast<int>(rows), J->typed_data(), T->typed_data());
  return ffi::Error::Success();
}

using F64 = ffi::Buffer<ffi::F64>;

// The five inputs both handlers take: q, dh, rev, base, tool.
auto bind_inputs() { return ffi::Ffi::Bind().Arg<F64>().Arg<F64>().Arg<F64>().Arg<F64>().Arg<F64>(); }

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxcalFk, FkImpl, bind_inputs().Ret<F64>().Attr<int64_t>("mdh"));

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxcalJac, JacImpl,
                              bind_inputs().Ret<F64>().Ret<F64>().Attr<int64_t>("mdh").Attr<int64_t>("rows"));

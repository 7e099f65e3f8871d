// Fused CPU kernels for forward kinematics and the identification Jacobian, called from JAX
// through the XLA FFI (jaxcal/_native/__init__.py compiles and registers them; the pure-JAX
// code in kinematics.py / error_model.py is the reference and the fallback, and the tests
// compare the two).
//
// Why: XLA CPU materialises every link's 12 entries for all poses between links and computed
// float64 sin/cos one value at a time; here a block of BLK poses gets all its sincos first, then
// runs through all links W poses at a time (8 with AVX-512, else 4) with the running transform in
// registers (benchmarks/bench_roofline.py measures both, benchmarks/bench_kernel_phases.py each
// phase). Blocks are spread over the calling thread and the kernel's own workers (pool.h).
//
// Layout: q (B, K, n) joint values, B robots (leading batch axes flattened) of K poses each, or
// pose axis last, q (B, n, K) (JaxcalFkPoseLast); dh (B, n, 4) rows (theta, d, a, alpha); rev
// (n) 1.0 revolute / 0.0 prismatic (or (B, n)); base, tool (B, 4, 4). A robot-side buffer with a
// single robot's worth of entries is shared by all B. Outputs: T (B, K, 4, 4), or (B, 4, 4, K)
// pose axis last; J (B, K, rows, 4n), columns link-major (theta, d, a, alpha), rows dp (3) then
// dphi (3) as in error_model._columns (pose rows).
// Standard DH link (paper eq. 1): R = [[c, -s ca, s sa], [s, c ca, -c sa], [0, sa, ca]],
//   t = (a c, a s, d). Modified DH: R = [[c, -s, 0], [s ca, c ca, -sa], [s sa, c sa, ca]],
//   t = (a, -sa d, ca d).
// sin/cos of theta: sincos_lanes (lanes.h; with AVX-512 a table of the multiples of pi/8, otherwise
//   the polynomials of jaxcal/trig.py).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

#if defined(__linux__)
#include <sys/mman.h>
#endif

#include "lanes.h"   // vectors of W lanes, sincos_lanes, transpose8
#include "pool.h"    // parallel_blocks: the kernel's threads
#include "stores.h"  // store_tile, store_pose_major, store_pose_last
#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

constexpr int BLK = 64;
constexpr int MAXN = 16;  // joints; longer chains use the pure-JAX path

struct Problem {
  int64_t B, K, n;
  const double *q, *dh, *rev, *base, *tool;
  int64_t dh_stride, rev_stride, base_stride, tool_stride;  // 0 when shared by all robots
  bool mdh, pose_last;
};

// A block: m <= BLK consecutive poses k0 .. k0+m-1 of one robot r (blocks never straddle
// robots, so every link constant is a scalar per block). Joint j's values for the block's lanes
// are at qj[j * qstride + b]: straight from q when the pose axis is last and the block is
// full, else from qT, joint-major, where lanes m.. repeat pose k0 (written nowhere).
struct Block {
  int64_t r, k0;
  int m;
  const double *qj;
  int64_t qstride;
  double qT[MAXN][BLK];
};

// A frame per lane, F[e][b]: rotation entries e = 0..8 row-major, translation e = 9..11.
using Frame = double[12][BLK];

// The joint values of a full block of pose-major q, joint-major: with AVX-512 each 8 poses' rows
// (masked loads, 8 joints at a time) are transposed in registers; otherwise one strided loop per
// joint (gathers: about 5 of the ~45 cycles per pose of FK on an AVX-512 host).
inline void gather_full(const double *q, int64_t n, double qT[MAXN][BLK]) {
#if defined(__AVX512F__)
  for (int g = 0; g < BLK; g += 8) {
    for (int64_t j0 = 0; j0 < n; j0 += 8) {
      const int w = static_cast<int>(n - j0 < 8 ? n - j0 : 8);
      const __mmask8 mask = static_cast<__mmask8>((1u << w) - 1);
      __m512d r[8];
      for (int b = 0; b < 8; ++b) r[b] = _mm512_maskz_loadu_pd(mask, q + (g + b) * n + j0);
      transpose8(r);
      for (int j = 0; j < w; ++j) _mm512_storeu_pd(&qT[j0 + j][g], r[j]);
    }
  }
#else
  for (int64_t j = 0; j < n; ++j)
#pragma omp simd
    for (int b = 0; b < BLK; ++b) qT[j][b] = q[b * n + j];
#endif
}

inline void block_init(const Problem &P, int64_t ib, Block &blk) {
  const int64_t per = (P.K + BLK - 1) / BLK, n = P.n;
  blk.r = ib / per;
  blk.k0 = (ib % per) * BLK;
  blk.m = static_cast<int>(P.K - blk.k0 < BLK ? P.K - blk.k0 : BLK);
  blk.qj = &blk.qT[0][0];
  blk.qstride = BLK;
  if (P.pose_last) {
    const double *q = P.q + blk.r * n * P.K + blk.k0;  // joint j at q[j * K + b]
    if (blk.m == BLK) {
      blk.qj = q;
      blk.qstride = P.K;
    } else {
      for (int64_t j = 0; j < n; ++j)
        for (int b = 0; b < BLK; ++b) blk.qT[j][b] = q[j * P.K + (b < blk.m ? b : 0)];
    }
    return;
  }
  const double *q = P.q + (blk.r * P.K + blk.k0) * n;
  if (blk.m == BLK) {
    gather_full(q, n, blk.qT);
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
  for (int64_t j = 0; j < P.n; ++j) {
    L.a[j] = dh[4 * j + 2];
    sincos1(dh[4 * j + 3], &L.sa[j], &L.ca[j]);
  }
  for (int64_t j = 0; j < P.n; ++j) {
    const double rv = rev[j], th0 = dh[4 * j], d0 = dh[4 * j + 1];
    const double *qj = blk.qj + j * blk.qstride;
    for (int g = 0; g < BLK; g += W) {
      const vec q = loadv(qj + g);
      vec s, c;
      sincos_lanes(th0 + q * rv, s, c);
      storev(&L.s[j][g], s);
      storev(&L.c[j][g], c);
      storev(&L.d[j][g], d0 + q * (1.0 - rv));
    }
  }
}

// The lanes g .. g+W-1 of a block through every link, the running frame R (12 entries) in
// registers; each frame before a link is also stored into Fs[j] when Fs is given (the
// Jacobian). Fo = Fi * A_j row by row, as two plane rotations (paper eq. 1: SDH A = Rz(theta)
// Tz(d) Tx(a) Rx(alpha); MDH A = Rx(alpha) Tx(a) Rz(theta) Tz(d)), 16 FLOP per row:
//   SDH: u = x c + y s, v = y c - x s; row (u, v ca + z sa, z ca - v sa); t += a u + d z.
//   MDH: y' = y ca + z sa, z' = z ca - y sa; row (x c + y' s, y' c - x s, z'); t += a x + d z'.
// Loading and storing a frame of 12 x 64 lanes per link instead cost FK ~5 % more.
template <bool MDH>
inline void chain_lanes(const Problem &P, const Block &blk, const Links &L, int g, Frame *Fs, vec R[12]) {
  const double *T = P.base + blk.r * P.base_stride;
  for (int e = 0; e < 12; ++e) R[e] = vec{} + (e < 9 ? T[4 * (e / 3) + e % 3] : T[4 * (e - 9) + 3]);
  for (int64_t j = 0; j < P.n; ++j) {
    if (Fs != nullptr)
      for (int e = 0; e < 12; ++e) storev(&Fs[j][e][g], R[e]);
    const vec c = loadv(&L.c[j][g]), s = loadv(&L.s[j][g]), d = loadv(&L.d[j][g]);
    const double ca = L.ca[j], sa = L.sa[j], a = L.a[j];
    for (int r = 0; r < 3; ++r) {
      const vec x = R[3 * r], y = R[3 * r + 1], z = R[3 * r + 2];
      if (!MDH) {
        const vec u = x * c + y * s, v = y * c - x * s;
        R[3 * r] = u;
        R[3 * r + 1] = v * ca + z * sa;
        R[3 * r + 2] = z * ca - v * sa;
        R[9 + r] = R[9 + r] + u * a + z * d;
      } else {
        const vec y1 = y * ca + z * sa, z1 = z * ca - y * sa;
        R[3 * r] = x * c + y1 * s;
        R[3 * r + 1] = y1 * c - x * s;
        R[3 * r + 2] = z1;
        R[9 + r] = R[9 + r] + x * a + z1 * d;
      }
    }
  }
  if (Fs != nullptr)
    for (int e = 0; e < 12; ++e) storev(&Fs[P.n][e][g], R[e]);
}

// The end pose's top three rows E[4 r + col] = (R * tool)[r][col], W lanes.
inline void end_lanes(const double *tool, const vec R[12], vec E[12]) {
  for (int r = 0; r < 3; ++r) {
    const vec x = R[3 * r], y = R[3 * r + 1], z = R[3 * r + 2];
    for (int col = 0; col < 3; ++col) E[4 * r + col] = x * tool[col] + y * tool[4 + col] + z * tool[8 + col];
    E[4 * r + 3] = x * tool[3] + y * tool[7] + z * tool[11] + R[9 + r];
  }
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

// The end poses of a block, W lanes at a time: the chain (every frame into Fs when given), the
// tool, then put(E, g, m) with the end pose's top rows E of lanes g .. g+m-1 (m <= W), the end
// frame never leaving registers.
template <bool MDH, class Put>
inline void end_poses(const Problem &P, const Block &blk, const Links &L, Frame *Fs, Put &&put) {
  const double *tool = P.tool + blk.r * P.tool_stride;
  for (int g = 0; g < blk.m; g += W) {
    vec R[12], E[12];
    chain_lanes<MDH>(P, blk, L, g, Fs, R);
    end_lanes(tool, R, E);
    put(E, g, blk.m - g < W ? blk.m - g : W);
  }
}

// One block of FK: joint values, sincos, end poses written in the layout asked for.
template <bool MDH>
inline void fk_block(const Problem &P, int64_t ib, double *T_out) {
  Block blk;
  Links L;
  block_init(P, ib, blk);
  link_values(P, blk, L);
  end_poses<MDH>(P, blk, L, nullptr, [&](const vec *E, int g, int m) {
    if (P.pose_last)
      store_pose_last(E, m, P.K, T_out + 16 * blk.r * P.K + blk.k0 + g);
    else
      store_pose_major(E, m, T_out + 16 * (blk.r * P.K + blk.k0 + g));
  });
}

void fk_kernel(const Problem &P, double *T_out) {
  parallel_blocks(n_blocks(P), [&](int64_t ib) {
    if (P.mdh) fk_block<true>(P, ib, T_out); else fk_block<false>(P, ib, T_out);
  });
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

// One block of the Jacobian: every frame of the chain kept (F[0] the base, F[j + 1] the frame
// after link j), the end poses written and their positions kept in pe, then the columns.
template <bool MDH>
inline void jac_block(const Problem &P, int64_t ib, int rows, double *J_out, double *T_out) {
  static thread_local Block blk;
  static thread_local Frame F[MAXN + 1];
  static thread_local double Jt[6 * 4 * MAXN * 8];
  static thread_local Links L;
  double pe[3][BLK];
  const int64_t m = 4 * P.n;
  block_init(P, ib, blk);
  link_values(P, blk, L);
  end_poses<MDH>(P, blk, L, F, [&](const vec *E, int g, int mg) {
    store_pose_major(E, mg, T_out + 16 * (blk.r * P.K + blk.k0 + g));
    for (int r = 0; r < 3; ++r) storev(&pe[r][g], E[4 * r + 3]);
  });
  for (int b0 = 0; b0 < blk.m; b0 += 8) {
    for (int64_t i = 0; i < P.n; ++i) {
      const Frame &Fz = MDH ? F[i + 1] : F[i], &Fx = MDH ? F[i] : F[i + 1];
      if (rows == 6) link_columns<6>(m, i, Fz, Fx, pe, b0, Jt); else link_columns<3>(m, i, Fz, Fx, pe, b0, Jt);
    }
    store_tile<8>(rows * m, blk.m - b0 < 8 ? blk.m - b0 : 8, Jt, J_out + rows * m * (blk.r * P.K + blk.k0 + b0));
  }
}

void jac_kernel(const Problem &P, int rows, double *J_out, double *T_out) {
  parallel_blocks(n_blocks(P), [&](int64_t ib) {
    if (P.mdh) jac_block<true>(P, ib, rows, J_out, T_out); else jac_block<false>(P, ib, rows, J_out, T_out);
  }, /*chunks_per_thread=*/2);
}

ffi::Error make_problem(ffi::Buffer<ffi::F64> &q, ffi::Buffer<ffi::F64> &dh, ffi::Buffer<ffi::F64> &rev,
                        ffi::Buffer<ffi::F64> &base, ffi::Buffer<ffi::F64> &tool, int64_t mdh, bool pose_last,
                        Problem &P) {
  auto qd = q.dimensions(), dd = dh.dimensions();
  if (qd.size() < (pose_last ? 2 : 1) || dd.size() < 2 || dd.back() != 4)
    return ffi::Error::InvalidArgument("jaxcal native: bad shapes");
  P.n = dd[dd.size() - 2];
  if (P.n < 1 || P.n > MAXN || qd[qd.size() - (pose_last ? 2 : 1)] != P.n)
    return ffi::Error::InvalidArgument("jaxcal native: q and dh disagree on n");
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
  P.pose_last = pose_last;
  return ffi::Error::Success();
}

ffi::Error fk_impl(ffi::Buffer<ffi::F64> q, ffi::Buffer<ffi::F64> dh, ffi::Buffer<ffi::F64> rev,
                   ffi::Buffer<ffi::F64> base, ffi::Buffer<ffi::F64> tool, ffi::ResultBuffer<ffi::F64> T,
                   int64_t mdh, bool pose_last) {
  Problem P;
  ffi::Error err = make_problem(q, dh, rev, base, tool, mdh, pose_last, P);
  if (err.failure()) return err;
  if (T->element_count() != 16 * P.B * P.K) return ffi::Error::InvalidArgument("jaxcal native: bad output shape");
  advise_huge(T->typed_data(), T->size_bytes());
  fk_kernel(P, T->typed_data());
  return ffi::Error::Success();
}

ffi::Error FkImpl(ffi::Buffer<ffi::F64> q, ffi::Buffer<ffi::F64> dh, ffi::Buffer<ffi::F64> rev,
                  ffi::Buffer<ffi::F64> base, ffi::Buffer<ffi::F64> tool, ffi::ResultBuffer<ffi::F64> T,
                  int64_t mdh) {
  return fk_impl(q, dh, rev, base, tool, T, mdh, false);
}

ffi::Error FkPoseLastImpl(ffi::Buffer<ffi::F64> q, ffi::Buffer<ffi::F64> dh, ffi::Buffer<ffi::F64> rev,
                          ffi::Buffer<ffi::F64> base, ffi::Buffer<ffi::F64> tool, ffi::ResultBuffer<ffi::F64> T,
                          int64_t mdh) {
  return fk_impl(q, dh, rev, base, tool, T, mdh, true);
}

ffi::Error JacImpl(ffi::Buffer<ffi::F64> q, ffi::Buffer<ffi::F64> dh, ffi::Buffer<ffi::F64> rev,
                   ffi::Buffer<ffi::F64> base, ffi::Buffer<ffi::F64> tool, ffi::ResultBuffer<ffi::F64> J,
                   ffi::ResultBuffer<ffi::F64> T, int64_t mdh, int64_t rows) {
  Problem P;
  ffi::Error err = make_problem(q, dh, rev, base, tool, mdh, false, P);
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

// The five inputs every handler takes: q, dh, rev, base, tool.
auto bind_inputs() { return ffi::Ffi::Bind().Arg<F64>().Arg<F64>().Arg<F64>().Arg<F64>().Arg<F64>(); }

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxcalFk, FkImpl, bind_inputs().Ret<F64>().Attr<int64_t>("mdh"));

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxcalFkPoseLast, FkPoseLastImpl, bind_inputs().Ret<F64>().Attr<int64_t>("mdh"));

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxcalJac, JacImpl,
                              bind_inputs().Ret<F64>().Ret<F64>().Attr<int64_t>("mdh").Attr<int64_t>("rows"));

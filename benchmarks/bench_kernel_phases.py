"""Where the native kernel's time goes, without JAX: a C++ harness that includes
``jaxcal/_native/chain.cc`` and is built with the shipped flags (``jaxcal._native._FLAGS``).

* **Phases of FK**, one thread, both layouts (pose-major ``fk``, pose axis last
  ``fk_pose_last``): the per-block work is timed cumulatively over all blocks of ``--poses``
  poses (the joint values' gather; + the sincos of every joint; + the chain through the links;
  the whole block with the tool and the store) and the phases are the differences. Lanes are
  those of the kernel (8 with AVX-512, else 4).
* **Whole kernels**, on one thread and on every core: FK in both layouts and the identification
  Jacobian (6 rows), ns per pose, the hand-counted FLOP rate (``bench_roofline.hand_flops``) and
  its fraction of the float64 peak. Then FK and the Jacobian again over passes of only
  ``--cache-poses`` poses (default 512) on one thread, so that the outputs stay in the core's
  L2 (the Jacobian's 0.6 MB): the kernel's own rate, with the memory behind the cache taken out.
* **Peak**: measured DGEMM (``bench_roofline.cpu_peak``, the reference of ``bench_roofline.py``)
  and a loop of independent fused multiply-adds on the kernel's vectors (the FMA units' own
  rate, usually above DGEMM's).

Medians with min/max over ``--repeats`` passes; cycles are at the reference clock
``/proc/cpuinfo`` reports (the time-stamp counter's rate; cores may run faster). ``--source``
builds another version of the kernel (a file or a git revision) for the whole-kernel rows only
(its internals may differ).

    python benchmarks/bench_kernel_phases.py [--poses 10000] [--repeats 300] [--cache-poses 512]
        [--source REV|FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

HARNESS = r"""
#include SOURCE
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <vector>
#ifdef _OPENMP
#include <omp.h>
#endif

namespace {
using clk = std::chrono::steady_clock;
#if defined(__AVX512F__)
constexpr int HW = 8;  // the widest vector, in doubles (the kernel's lanes since 2026-11-23)
#else
constexpr int HW = 4;
#endif
typedef double hvec __attribute__((vector_size(8 * HW)));

// whether this version of the kernel has the pose-last layout (since 2026-11-23)
template <class T> auto set_pose_last(T &p, bool v, int) -> decltype(p.pose_last = v, bool()) { p.pose_last = v; return true; }
template <class T> bool set_pose_last(T &, bool, long) { return false; }
const double *q_major, *q_last;
template <class T> bool layout(T &p, bool last) {  // the layout and the joint values laid out for it
  p.q = last ? q_last : q_major;
  return set_pose_last(p, last, 0);
}

void print_runs(const char *name, std::vector<double> &t, double per) {
  std::sort(t.begin(), t.end());
  printf("{\"name\": \"%s\", \"median\": %.6e, \"min\": %.6e, \"max\": %.6e}\n", name, t[t.size() / 2] / per,
         t.front() / per, t.back() / per);
}

void set_threads(int th) {  // the kernel's own pool since 2026-11-23, OpenMP before
#ifdef HAS_POOL
  max_threads.store(th == 1 ? 1 : 0);
#elif defined(_OPENMP)
  omp_set_num_threads(th);
#endif
}

template <class F> std::vector<double> passes(int repeats, F f) {
  f();
  std::vector<double> t;
  for (int r = 0; r < repeats; ++r) {
    auto t0 = clk::now();
    f();
    t.push_back(std::chrono::duration<double>(clk::now() - t0).count());
  }
  return t;
}

#ifndef NO_PHASES
double sink[12][W];
// STAGE 1: joint values; 2: + sincos; 3: + the chain; 4: the whole block (tool and store)
template <int STAGE> __attribute__((noinline)) void stages(const Problem &P, double *T) {
  for (int64_t ib = 0; ib < n_blocks(P); ++ib) {
    if (STAGE == 4) {
      fk_block<false>(P, ib, T);
      continue;
    }
    Block blk;
    Links L;
    block_init(P, ib, blk);
    if (STAGE >= 2) link_values(P, blk, L);
    if (STAGE >= 3)
      for (int g = 0; g < blk.m; g += W) {
        vec R[12];
        chain_lanes<false>(P, blk, L, g, nullptr, R);
        for (int e = 0; e < 12; ++e) storev(sink[e], R[e]);
      }
    asm volatile("" : : "r"(&blk), "r"(&L) : "memory");
  }
}
// The Jacobian (6 rows, SDH): STAGE 1: frames, end poses and their store (the chain with every
// frame kept); 2: + the columns into the block's tile; 3: the whole block (+ the tile's
// transposed store into J).
double Jsink[6 * 4 * MAXN * 8];
template <int STAGE> __attribute__((noinline)) void jac_stages(const Problem &P, double *J, double *T) {
  static Frame F[MAXN + 1];
  double pe[3][BLK];
  const int64_t m = 4 * P.n;
  for (int64_t ib = 0; ib < n_blocks(P); ++ib) {
    if (STAGE == 3) {
      jac_block<false>(P, ib, 6, J, T);
      continue;
    }
    Block blk;
    Links L;
    block_init(P, ib, blk);
    link_values(P, blk, L);
    end_poses<false>(P, blk, L, F, [&](const vec *E, int g, int mg) {
      store_pose_major(E, mg, T + 16 * (blk.r * P.K + blk.k0 + g));
      for (int r = 0; r < 3; ++r) storev(&pe[r][g], E[4 * r + 3]);
    });
    if (STAGE >= 2)
      for (int b0 = 0; b0 < blk.m; b0 += 8)
        for (int64_t i = 0; i < P.n; ++i) link_columns<6>(m, i, F[i], F[i + 1], pe, b0, Jsink);
    asm volatile("" : : "r"(&blk), "r"(&L), "r"(F), "r"(pe) : "memory");
  }
}
#endif

double fma_rate(int threads, long iters) {
  double total = 0;
  auto t0 = clk::now();
#pragma omp parallel num_threads(threads) reduction(+ : total)
  {
    hvec a[12], b = hvec{} + 0.9999999, c = hvec{} + 1e-9;  // 12 chains: enough for 2 FMA pipes of latency 4-6
    for (int i = 0; i < 12; ++i) a[i] = hvec{} + (1.0 + i * 1e-9);
    for (long k = 0; k < iters; ++k)
      for (int i = 0; i < 12; ++i) a[i] = a[i] * b + c;
    for (int i = 0; i < 12; ++i) total += a[i][0];
  }
  double s = std::chrono::duration<double>(clk::now() - t0).count();
  if (total == 0.125) printf("#\n");
  return threads * iters * 12.0 * HW * 2 / s;
}
}  // namespace

int main(int argc, char **argv) {
  int64_t K = atol(argv[1]);
  int repeats = atoi(argv[2]);
  int n, mdh;
  if (scanf("%d %d", &n, &mdh) != 2) return 2;
  std::vector<double> dh(4 * n), rev(n), base(16), tool(16);
  for (auto *v : {&dh, &rev, &base, &tool})
    for (auto &x : *v)
      if (scanf("%lf", &x) != 1) return 2;
  std::mt19937_64 g(0);
  std::uniform_real_distribution<double> U(-3.141592653589793, 3.141592653589793);
  std::vector<double> q(K * n), qT(n * K), T(16 * K), J(6 * 4 * n * K), T2(16 * K);
  for (auto &x : q) x = U(g);
  for (int64_t k = 0; k < K; ++k)
    for (int j = 0; j < n; ++j) qT[j * K + k] = q[k * n + j];  // the same poses, pose axis last
  q_major = q.data();
  q_last = qT.data();
  Problem P{};
  P.B = 1; P.K = K; P.n = n; P.q = q.data(); P.dh = dh.data(); P.rev = rev.data(); P.base = base.data();
  P.tool = tool.data(); P.mdh = mdh != 0;
  int all = 1;
#ifdef HAS_POOL
  all = int(Workers::get().size()) + 1;
#elif defined(_OPENMP)
  all = omp_get_max_threads();
#endif
  const char *control = "none";  // what the one-thread rows set: without it they run on every thread
#ifdef HAS_POOL
  control = "pool";
#elif defined(_OPENMP)
  control = "openmp";
#endif
  printf("{\"lanes\": %d, \"threads\": %d, \"control\": \"%s\"}\n", HW, all, control);
#ifndef NO_PHASES
  if (!P.mdh) {
    for (int last = 0; last < 2; ++last) {
      layout(P, last != 0);
      set_threads(1);
      const char *lay = last ? "pose-last" : "pose-major";
      char name[64];
      auto run = [&](int s, auto f) {
        auto t = passes(repeats, f);
        snprintf(name, sizeof name, "stage %d %s", s, lay);
        print_runs(name, t, double(K));
      };
      run(1, [&] { stages<1>(P, T.data()); });
      run(2, [&] { stages<2>(P, T.data()); });
      run(3, [&] { stages<3>(P, T.data()); });
      run(4, [&] { stages<4>(P, T.data()); });
    }
  }
#endif
  for (int th : {1, all}) {
    set_threads(th);
    char name[64];
    for (int last = 0; last < 2; ++last) {
      if (!layout(P, last != 0) && last) continue;
      auto t = passes(repeats, [&] { fk_kernel(P, last ? T2.data() : T.data()); });
      snprintf(name, sizeof name, "FK %s, %d thread(s)", last ? "pose-last" : "pose-major", th);
      print_runs(name, t, double(K));
    }
    layout(P, false);
    auto t = passes(repeats, [&] { jac_kernel(P, 6, J.data(), T.data()); });
    snprintf(name, sizeof name, "Jacobian, %d thread(s)", th);
    print_runs(name, t, double(K));
    if (all == 1) break;
  }
  // The same kernels over passes of the first Ks poses only, on one thread: outputs that stay in
  // the core's L2 (the Jacobian's 1,152 bytes per pose of 6 rows: 512 poses = 0.6 MB), so what
  // is left is the kernel's own work, not the memory behind it. Pose-major only (a pose-last
  // pass reads the joint values with the stride of all K poses).
  const int64_t Ks = argc > 3 ? atol(argv[3]) : 0;
  if (Ks > 0 && Ks < K) {
    set_threads(1);
    layout(P, false);
    Problem S = P;
    S.K = Ks;
    const int rs = int(std::min<int64_t>(int64_t(repeats) * (K / Ks), 100000));
    char name[96];
    auto t = passes(rs, [&] { fk_kernel(S, T.data()); });
    snprintf(name, sizeof name, "FK pose-major (%lld poses per pass), 1 thread(s)", (long long)Ks);
    print_runs(name, t, double(Ks));
    t = passes(rs, [&] { jac_kernel(S, 6, J.data(), T.data()); });
    snprintf(name, sizeof name, "Jacobian (%lld poses per pass), 1 thread(s)", (long long)Ks);
    print_runs(name, t, double(Ks));
#ifndef NO_PHASES
    if (!S.mdh) {
      t = passes(rs, [&] { jac_stages<1>(S, J.data(), T.data()); });
      print_runs("jstage 1", t, double(Ks));
      t = passes(rs, [&] { jac_stages<2>(S, J.data(), T.data()); });
      print_runs("jstage 2", t, double(Ks));
      t = passes(rs, [&] { jac_stages<3>(S, J.data(), T.data()); });
      print_runs("jstage 3", t, double(Ks));
    }
#endif
  }
  bool agree = true;  // the layouts' end poses, entry by entry (when this version has both)
  if (layout(P, true)) {
    fk_kernel(P, T2.data());
    layout(P, false);
    fk_kernel(P, T.data());
    for (int64_t k = 0; k < K; ++k)
      for (int e = 0; e < 16; ++e) agree = agree && T[16 * k + e] == T2[e * K + k];
  }
  printf("{\"layouts_agree\": %s}\n", agree ? "true" : "false");
  for (int th : {1, all}) printf("{\"fma_flops\": %.6e, \"threads\": %d}\n", fma_rate(th, 20000000), th);
}
"""


def build(source: str, tmp: str, phases: bool) -> str:
    import jax
    from jaxcal import _native
    cxx = os.environ.get("CXX") or shutil.which("c++") or shutil.which("g++")
    flags = [f for f in _native._FLAGS if f not in ("-shared", "-fPIC")]
    flags += os.environ.get("JAXCAL_NATIVE_FLAGS", "").split()
    src, exe = os.path.join(tmp, "harness.cc"), os.path.join(tmp, "harness")
    with open(src, "w") as f:
        f.write(HARNESS.replace("SOURCE", json.dumps(source)))
    extra = [] if phases else ["-DNO_PHASES"]
    # the kernel's own pool (HAS_POOL: the one-thread rows set it), in chain.cc or, since 56880a1, in pool.h
    folder = os.path.dirname(source)
    texts = [open(os.path.join(folder, f)).read() for f in os.listdir(folder) if f.endswith((".cc", ".h"))]
    if any("class Workers" in t for t in texts):
        extra.append("-DHAS_POOL")
    for omp in (["-fopenmp"], []):
        p = subprocess.run([cxx, *flags, *omp, *extra, f"-I{jax.ffi.include_dir()}", src, "-o", exe],
                           capture_output=True, text=True)
        if p.returncode == 0:
            return exe
    raise SystemExit(f"building the harness failed: {p.stderr[-1500:]}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=10_000)
    ap.add_argument("--repeats", type=int, default=300)
    ap.add_argument("--source", help="another chain.cc (file or git revision): whole-kernel rows only")
    ap.add_argument("--cache-poses", type=int, default=512,
                    help="also time passes of this many poses on one thread, small enough for L2 (0: not)")
    ap.add_argument("--robot", default="paper-6r")
    ap.add_argument("--peak", type=float, help="the float64 peak in GFLOP/s (default: measure DGEMM)")
    args = ap.parse_args()
    sys.path.insert(0, HERE)
    import numpy as np
    import jaxcal
    from jaxcal import _native
    from _util import kernel_source, machine
    from bench_roofline import cpu_peak, hand_flops

    print("machine:", machine())
    robot = jaxcal.preset(args.robot)
    n = robot.n_joints
    peak = args.peak * 1e9 if args.peak else max(v for k, v in cpu_peak().items() if k.endswith("dgemm_flops"))
    with tempfile.TemporaryDirectory() as tmp:
        source = kernel_source(args.source, tmp, ROOT) if args.source else str(_native.SOURCE)
        exe = build(source, tmp, phases=args.source is None)
        values = np.concatenate([np.ravel(robot.dh), np.ravel(robot.revolute_mask), np.ravel(robot.base),
                                 np.ravel(robot.tool)])
        stdin = f"{n} {int(robot.convention == 'mdh')} " + " ".join(repr(float(v)) for v in values)
        p = subprocess.run([exe, str(args.poses), str(args.repeats), str(args.cache_poses)], input=stdin,
                           capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"harness failed ({p.returncode}): {p.stderr[-1500:]}")
    rows = [json.loads(line) for line in p.stdout.splitlines() if line.startswith("{")]
    info = rows[0]
    mhz = [float(line.split(":")[1]) for line in open("/proc/cpuinfo") if line.startswith("cpu MHz")] \
        if os.path.exists("/proc/cpuinfo") else []
    ghz = mhz[0] / 1e3 if mhz else float("nan")
    fma = {r["threads"]: r["fma_flops"] for r in rows if "fma_flops" in r}
    agree = next(r["layouts_agree"] for r in rows if "layouts_agree" in r)
    if not agree:
        raise SystemExit("the pose-major and pose-last FK kernels disagree")
    flops = hand_flops(n)
    print(f"kernel: {args.source or source}; {args.robot} ({n} joints), {args.poses:,} poses per pass, {args.repeats} passes; "
          f"vectors of {info['lanes']} doubles, {info['threads']} threads (set by {info['control']})")
    print(f"peak float64: DGEMM {peak / 1e9:.1f} GFLOP/s (the reference below); FMA loop "
          f"{fma.get(1, float('nan')) / 1e9:.1f} GFLOP/s on 1 thread, {fma.get(info['threads'], float('nan')) / 1e9:.1f} "
          f"on {info['threads']}; cycles at {ghz:.2f} GHz (the reference clock)")
    by = {r["name"]: r for r in rows if "name" in r}
    for lay in ("pose-major", "pose-last"):
        st = [by.get(f"stage {s} {lay}") for s in (1, 2, 3, 4)]
        if None in st:
            continue
        med = [s["median"] for s in st]
        parts = [("joint values", med[0]), ("sincos", med[1] - med[0]), ("chain", med[2] - med[1]),
                 ("tool + store", med[3] - med[2])]
        print(f"FK phases, {lay}, 1 thread (ns | cycles per pose): "
              + ", ".join(f"{k} {v * 1e9:.2f} | {v * ghz * 1e9:.1f}" for k, v in parts)
              + f"; whole block {med[3] * 1e9:.2f} | {med[3] * ghz * 1e9:.1f}")
    js = [by.get(f"jstage {s}") for s in (1, 2, 3)]
    if None not in js:
        med = [s["median"] for s in js]
        parts = [("frames and end poses", med[0]), ("columns", med[1] - med[0]), ("transposed store of J", med[2] - med[1])]
        out_mb = args.cache_poses * (6 * 4 * n + 16) * 8 / 1e6  # J and T: what has to fit in the core's L2
        print(f"Jacobian phases, {args.cache_poses} poses per pass ({out_mb:.2f} MB of output), 1 thread "
              f"(ns | cycles per pose): "
              + ", ".join(f"{k} {v * 1e9:.2f} | {v * ghz * 1e9:.1f}" for k, v in parts)
              + f"; whole block {med[2] * 1e9:.2f} | {med[2] * ghz * 1e9:.1f}")
    for name, r in by.items():
        if name.startswith(("stage", "jstage")):
            continue
        op = "FK" if name.startswith("FK") else "Jacobian"
        th = int(name.rsplit(", ", 1)[1].split()[0])
        rate = flops[op] / r["median"]  # against the peak of as many cores as threads
        print(f"{name:28s} median {r['median'] * 1e9:7.2f} ns/pose (min {r['min'] * 1e9:.2f}, max {r['max'] * 1e9:.2f})"
              f" = {r['median'] * ghz * 1e9 * th:6.1f} cycles per pose per thread; {1e-6 / r['median']:6.1f} M poses/s; "
              f"{rate / 1e9:5.1f} GFLOP/s = {rate / (peak * th / info['threads']):6.1%} of the DGEMM peak of {th} core(s)"
              f" ({rate / fma[th]:.1%} of the FMA loop's)")


if __name__ == "__main__":
    main()

"""The limit (issue 7.3): FLOPs per pose of FK and of the identification Jacobian against the
measured throughput, as a fraction of this machine's float64 peak; and the levers tried.

FLOPs per pose are counted two ways: by hand (the arithmetic the closed form needs, below) and
by XLA's cost analysis of the compiled function. Peak: (a) measured float64 GEMM throughput
(``numpy`` / OpenBLAS and ``jnp.dot``, 2000x2000, the best a BLAS reaches here); (b) the
nominal ``cores x GHz x FLOP/cycle`` with FLOP/cycle from the CPU flags (AVX-512: 2 FMA
pipes x 8 doubles x 2 = 32; AVX2: 16).

Ceilings below that peak, measured in the same run: the memory roofline, compulsory bytes per
pose (:func:`compulsory_bytes`) against the bandwidth of writing an output of the size timed
(:func:`write_bandwidth`: the results are almost all writes; the rows' "of its roofline"), and
against the STREAM-style bandwidth of :func:`stream_bandwidth` for reference; and the time of
sin + cos of every joint angle alone, with XLA's and with :func:`jaxcal.trig.sincos` (the
hand-counted FLOPs in that time, as if everything else were free).

Levers, each timed in this run on the same poses (paper arm, ``--poses`` uniform poses):
* jaxcal as shipped: the fused native kernel (``jaxcal/_native/chain.cc``, XLA FFI): blocks of
  64 poses through all links in registers/L1, polynomial sincos, vectorised over poses; FK also
  with the pose axis last (``jaxcal.fk_pose_last``: joint values ``(n, K)`` in, ``(4, 4, K)``
  out, no transposes); also timed at 10^4 poses per call (at 10^5 the Jacobian's 115 MB output
  is fresh memory on every call, which Linux must fault in and zero; the kernel asks for 2 MiB
  pages for it), and at every size of ``--sweep``; the native rows time each sample over many
  back-to-back calls (about 2 ms), a call of 10^4 poses taking tens of microseconds;
* pure JAX (the fallback without a compiler): structure of arrays (every entry of the running
  transform a ``(K,)`` vector) with a ``lax.scan`` over the links, so each link's entries are
  materialised once; the Jacobian then forms every column at once from the materialised
  frames; sin/cos by :func:`jaxcal.trig.sincos`;
* the same with XLA's own sin/cos (the shipped form of commit 01cbb2a);
* the previous Jacobian (commit d42a99f): the spatial twists formed inside the scan;
* jaxcal before (commit 1bd4056): 4x4 matrices, links unrolled in Python, fused elementwise
  rigid products; its Jacobian from those frames by broadcasting;
* ``lax.scan`` over the links with 4x4 matrices;
* structure of arrays, links unrolled: XLA CPU fuses the chain into each output entry and
  recomputes it (the finding that led to the shipped form);
* chunking: ``lax.map`` over blocks of poses so intermediates stay in cache;
* autodiff ``jacfwd`` through FK instead of the closed-form Jacobian;
* XLA CPU flags (each in a fresh process; ``--flags`` to choose), and environment settings
  with the native kernel (``--envs``, e.g. ``GLIBC_TUNABLES=glibc.malloc.hugetlb=1``; none by
  default).

    python benchmarks/bench_roofline.py [--poses 100000] [--sweep 1000 10000 ...] [--json docs/bench/roofline.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

HAND_NOTE = (
    "hand count of the arithmetic each result needs, n links: the running frame times a link as "
    "two plane rotations (paper eq. 1: SDH A = Rz(theta) Tz(d) Tx(a) Rx(alpha)), per row of the "
    "frame u = x c + y s and v = y c - x s (6), (v ca + z sa, z ca - v sa) (6), t + a u + d z (4): "
    "16 -> 48 per link; the tool, a general rigid product, 45 + 18 = 63. FK = 48n + 63. Jacobian "
    "(J alone): the n frames 48n, the end position with the tool 18, the levers p_end - o_j to "
    "the n + 1 frame origins 3(n + 1), per link two cross products (the columns of theta and "
    "alpha; those of d and a are frame axes, no arithmetic) 18n -> 69n + 21. Not counted: sin/cos, "
    "joint offsets. Earlier counts: 63n + 63 and 84n + 21 until 2026-11-23 (the link matrix formed "
    "first, 6, then multiplied, 57: 441 / 525 for 6 joints instead of 351 / 435), and 63(n+1) + 6n "
    "and 273n + 63 until 2026-11-22 (general 3x3 products, the columns as general twists: 477 / "
    "1,701)")


def hand_flops(n: int) -> dict:
    return {"FK": 48 * n + 63, "Jacobian": 69 * n + 21}


def time_fn(fn, *args, repeats=7, inner=1):
    """(first call's seconds, warm seconds per call): each of ``repeats`` samples times ``inner``
    calls back to back (a call of a few tens of microseconds is timed over many)."""
    import jax
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            jax.block_until_ready(fn(*args))
        runs.append((time.perf_counter() - t0) / inner)
    return first, runs


def inner_calls(poses: int) -> int:
    """Calls per timing sample: about 2 ms of work for the native kernel."""
    return max(1, min(200, 200_000 // poses))


def faults_per_call(fn, *args, repeats=5) -> float:
    """Minor page faults per warm call (``getrusage``): a fresh output buffer beyond glibc's mmap
    threshold is faulted in page by page on every call."""
    import resource
    import jax
    jax.block_until_ready(fn(*args))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(repeats):
        jax.block_until_ready(fn(*args))
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / repeats


def xla_flops(fn, *args) -> float:
    ca = fn.lower(*args).compile().cost_analysis()
    ca = ca[0] if isinstance(ca, (list, tuple)) else ca
    return float(ca.get("flops", float("nan")))


def cpu_peak() -> dict:
    import numpy as np
    import jax.numpy as jnp
    import jaxcal  # noqa: F401  (enables x64: without it jnp.asarray below is float32, twice the rate)
    flags = open("/proc/cpuinfo").read()
    mhz = [float(l.split(":")[1]) for l in flags.splitlines() if l.startswith("cpu MHz")]
    per_cycle = 32 if " avx512f" in flags else 16 if " fma" in flags else 4
    cores = os.cpu_count()
    nominal = cores * (mhz[0] * 1e6 if mhz else float("nan")) * per_cycle
    n = 2000
    a = np.random.default_rng(0).standard_normal((n, n))
    runs = []
    for _ in range(5):
        t0 = time.perf_counter()
        a @ a
        runs.append(time.perf_counter() - t0)
    ja = jnp.asarray(a)
    if ja.dtype != jnp.float64:
        raise RuntimeError(f"the GEMM peak must be measured in float64, got {ja.dtype}")
    f, jruns = time_fn(lambda x: x @ x, ja, repeats=5)
    return {"numpy_dgemm_flops": 2 * n ** 3 / min(runs), "jax_dgemm_flops": 2 * n ** 3 / min(jruns),
            "nominal_flops": nominal, "ghz": mhz[0] / 1e3 if mhz else None, "flop_per_cycle_per_core": per_cycle,
            "cores": cores}


def stream_bandwidth(n: int = 1 << 25) -> dict:
    """Memory bandwidth, the roofline's other roof: a STREAM-style "scale" ``y = a x`` over ``n``
    doubles (256 MiB in, 256 MiB out: far beyond the caches), 16 bytes counted per element.
    ``bytes_per_s``: NumPy into a preallocated output (the machine's roof; a fresh output pays
    page faults on first touch). ``jax_bytes_per_s``: the same as a jitted function returning a
    new array, what XLA-generated code reaches on outputs that size."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    x = np.random.default_rng(1).standard_normal(n)
    y = np.empty_like(x)
    runs = []
    for _ in range(8):
        t0 = time.perf_counter()
        np.multiply(x, 1.000001, out=y)
        runs.append(time.perf_counter() - t0)
    xj = jnp.asarray(x)
    if xj.dtype != jnp.float64:
        raise RuntimeError(f"the bandwidth must be measured on float64, got {xj.dtype}")
    _, jruns = time_fn(jax.jit(lambda v: 1.000001 * v), xj, repeats=7)
    return {"bytes_per_s": 16 * n / statistics.median(runs[1:]), "best_bytes_per_s": 16 * n / min(runs[1:]),
            "jax_bytes_per_s": 16 * n / statistics.median(jruns), "n": n}


def write_bandwidth(nbytes: int, repeats: int = 9) -> dict:
    """The roof for a result of ``nbytes``: filling a preallocated float64 array that size, one
    thread per core on a slice each (NumPy; its loops release the GIL), each thread refilling its
    slice until ~64 MB are written per repeat so the thread start-up is amortised (the same
    buffer again, as a reused XLA output is). The results here are almost all writes (the
    Jacobian writes 1,152 bytes per pose and reads 48), and writing runs at about half STREAM's
    read+write rate; an output that fits the L3 is written faster than one that goes to memory,
    so the roof is measured at each output size timed."""
    from concurrent.futures import ThreadPoolExecutor
    import numpy as np
    n, cores = max(nbytes // 8, 1024), os.cpu_count() or 1
    reps = max(1, (64 << 20) // (8 * n))
    y = np.empty(n)
    parts = [slice(i * n // cores, (i + 1) * n // cores) for i in range(cores)]

    def fill(sl):
        for _ in range(reps):
            y[sl] = 1.000001

    runs = []
    with ThreadPoolExecutor(cores) as ex:
        for _ in range(repeats):
            t0 = time.perf_counter()
            list(ex.map(fill, parts))
            runs.append(time.perf_counter() - t0)
    total = 8 * n * reps
    return {"bytes": 8 * n, "threads": cores, "bytes_per_s": total / statistics.median(runs[1:]),
            "best_bytes_per_s": total / min(runs[1:])}


def native_status() -> dict:
    """Whether jaxcal's native kernel is in use here, and the time of a fresh build (a child
    process with an empty cache: what a new machine pays once)."""
    import tempfile
    from jaxcal import _native
    ok, why = _native.status()
    with tempfile.TemporaryDirectory() as d:
        code = "import time; from jaxcal import _native; t = time.perf_counter(); _native.status(); print(time.perf_counter() - t)"
        p = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, XDG_CACHE_HOME=d), capture_output=True,
                           text=True)
    return {"in_use": ok, "reason": why, "build_s": float(p.stdout.strip().splitlines()[-1]) if p.returncode == 0
            else float("nan")}


def compulsory_bytes(n: int) -> dict:
    """Bytes per pose that any implementation must move to or from memory: the joint angles in
    (n doubles) and the result out (FK: the 4x4 pose, 16 doubles; Jacobian: 6 x 4n doubles)."""
    return {"FK": 8 * (n + 16), "Jacobian": 8 * (n + 6 * 4 * n)}


from _roofline_variants import NATIVE, NATIVE_LAST, POSE_LAST, PURE, SMALL, variants  # noqa: E402
from _util import HUGETLB, KEEP_HEAP  # noqa: E402


def native_row(f, x, poses, repeats):
    """A native-kernel row at ``poses`` poses per call, each sample over :func:`inner_calls` calls."""
    first, runs = time_fn(f, x, repeats=repeats, inner=inner_calls(poses))
    med = statistics.median(runs)
    return {"fusions": 0, "median_s": med, "min_s": min(runs), "max_s": max(runs), "compile_s": first - med,
            "poses_per_s": poses / med, "xla_flops_per_pose": None, "poses_per_call": poses,
            "faults_per_call": faults_per_call(f, x)}


def measure(poses: int, repeats: int, only=None, sweep=()) -> dict:
    """Every variant (``only=None``) or just those named in ``only`` (the fresh-process rows); the
    native kernels also at :data:`SMALL` poses per call and at every size in ``sweep`` (under
    ``"sweep"``). Variants in :data:`POSE_LAST` get the joint values as ``(n, K)``."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    import jaxcal
    robot = jaxcal.preset("paper-6r")
    Qn = np.random.default_rng(0).uniform(-np.pi, np.pi, (poses, 6))
    Q, QT = jnp.asarray(Qn), jnp.asarray(np.ascontiguousarray(Qn.T))

    def arg(name, k=None):
        return (QT[:, :k] if name in POSE_LAST else Q[:k]) if k is not None else (QT if name in POSE_LAST else Q)

    def pose_major(name, out):
        return np.moveaxis(np.asarray(out), -1, 0) if name in POSE_LAST else np.asarray(out)

    ref = {"FK": np.asarray(jaxcal.fk(robot, Q[:100])),
           "Jacobian": np.asarray(jaxcal.error_model.identification_jacobian(robot, Q[:100]))}
    # the floor set by the transcendentals: sin and cos of every joint angle, nothing else
    from jaxcal.trig import sincos
    out = {}
    for key, f in (("sincos_only", lambda q: jnp.sin(q) + jnp.cos(q)), ("sincos_poly", lambda q: sum(sincos(q)))):
        first, runs = time_fn(jax.jit(f), Q, repeats=repeats)
        out[key] = {"median_s": statistics.median(runs), "min_s": min(runs), "max_s": max(runs)}
    vs_all = variants(robot)
    for op, vs in vs_all.items():
        out[op] = {}
        # the native kernels with fewer poses per call too (the XLA output buffer of 1e5 poses is fresh
        small = min(SMALL, poses)  # memory every call: page faults; see the README)
        for name in (NATIVE, NATIVE_LAST):
            if name in vs and (only is None or name in only):
                out[op][f"{name}, {small:,} poses/call"] = native_row(jax.jit(vs[name]), arg(name, small), small,
                                                                      repeats)
        for name, f in vs.items():
            if only is not None and name not in only:
                continue
            jf = jax.jit(f)
            got = pose_major(name, jf(arg(name, 100)))
            assert np.allclose(got, ref[op], atol=1e-8), f"{op} {name} disagrees with jaxcal"
            x = arg(name)
            if name in (NATIVE, NATIVE_LAST):
                out[op][name] = native_row(jf, x, poses, repeats)
                continue
            first, runs = time_fn(jf, x, repeats=repeats)
            med = statistics.median(runs)
            hlo = jf.lower(x).compile().as_text()
            n_fusions = sum(1 for line in hlo.splitlines() if " fusion(" in line and "kind=k" in line)
            out[op][name] = {"fusions": n_fusions, "median_s": med, "min_s": min(runs), "max_s": max(runs), "compile_s": first - med,
                             "poses_per_s": poses / med,
                             # XLA's cost analysis counts a loop body once (no figure for lax.map)
                             "xla_flops_per_pose": None if "lax.map" in name else xla_flops(jf, x) / poses}
    if sweep:
        out["sweep"] = {}
        for op, name in (("FK", NATIVE), ("FK", NATIVE_LAST), ("Jacobian", NATIVE)):
            if only is not None and name not in only:
                continue
            f = jax.jit(vs_all[op][name])
            for k in sweep:
                Qk = np.random.default_rng(1).uniform(-np.pi, np.pi, (k, 6))
                x = jnp.asarray(np.ascontiguousarray(Qk.T) if name in POSE_LAST else Qk)
                out["sweep"][f"{op} | {name} | {k}"] = native_row(f, x, k, repeats)
    return out


def print_sweep(sweep: dict, hand: dict, ref_peak: float, title: str):
    print(f"\n{title} (each sample over ~2 ms of calls; % of the measured peak, median (at the fastest sample)):")
    for key, r in sweep.items():
        op, name, k = key.split(" | ")
        gf = hand[op] * r["poses_per_s"]
        r.update(gflops_hand=gf / 1e9, frac_dgemm=gf / ref_peak, frac_dgemm_best=hand[op] * int(k) / r["min_s"] / ref_peak)
        print(f"  {op:9s} {name:38s} {int(k):>7,} poses/call: {r['median_s'] * 1e3:8.4f} ms (min "
              f"{r['min_s'] * 1e3:.4f}, max {r['max_s'] * 1e3:.4f}) {r['poses_per_s'] / 1e6:7.1f} M poses/s "
              f"{r['frac_dgemm']:6.1%} ({r['frac_dgemm_best']:.1%})  {r['faults_per_call']:,.0f} page faults/call")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--flags", nargs="*", default=[
        "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
        "--xla_cpu_enable_fast_math=true", "--xla_cpu_use_thunk_runtime=false"],
        help='XLA_FLAGS settings, each timed with pure JAX in a fresh process; from the command line one per '
             'run, as --flags="--xla_..." (argparse takes a bare "--xla_..." for an option); --flags alone for none')
    ap.add_argument("--envs", nargs="*", default=[KEEP_HEAP],
                    help="environment settings (e.g. " + HUGETLB + "; several in one, space separated), each timed "
                         "with the native kernels (their rows and --sweep) in a fresh process; default: "
                         "_util.KEEP_HEAP, glibc keeping freed memory; --envs alone for none")
    ap.add_argument("--sweep", type=int, nargs="*", default=[1_000, 3_000, 10_000, 30_000, 100_000],
                    help="poses per call at which the native kernels are also timed (--sweep alone for none)")
    ap.add_argument("--json")
    ap.add_argument("--_child", nargs="*", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args._child is not None:
        print(json.dumps(measure(args.poses, args.repeats, only=set(args._child), sweep=args.sweep)))
        return

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from _util import machine
    print("machine:", machine())
    peak = cpu_peak()
    print(f"float64 peak: nominal (reported base clock; turbo is higher) {peak['nominal_flops'] / 1e9:.1f} GFLOP/s ({peak['cores']} cores x "
          f"{peak['ghz']:.2f} GHz x {peak['flop_per_cycle_per_core']} FLOP/cycle); measured dgemm numpy "
          f"{peak['numpy_dgemm_flops'] / 1e9:.1f}, jax {peak['jax_dgemm_flops'] / 1e9:.1f} GFLOP/s")
    hand = hand_flops(6)
    print("FLOPs per pose by hand:", hand, "\n  (" + HAND_NOTE + ")")
    native = native_status()
    print(f"native kernel: in use {native['in_use']} ({native['reason']}); a fresh build (empty cache) took "
          f"{native['build_s']:.2f} s")
    res = measure(args.poses, args.repeats, sweep=args.sweep)
    ref_peak = max(peak["numpy_dgemm_flops"], peak["jax_dgemm_flops"])
    print(f"\n{args.poses} poses; fraction = hand FLOPs x poses/s / peak (measured dgemm | nominal)")
    bw = stream_bandwidth()
    nbytes = compulsory_bytes(6)
    print(f"memory bandwidth (STREAM scale, 2 x 256 MiB): NumPy into a preallocated output median "
          f"{bw['bytes_per_s'] / 1e9:.1f} GB/s (best {bw['best_bytes_per_s'] / 1e9:.1f}); a jitted jax function "
          f"returning a new array {bw['jax_bytes_per_s'] / 1e9:.1f} GB/s")
    roof = {}
    for op in ("FK", "Jacobian"):
        ai = hand[op] / nbytes[op]
        ceil = min(ref_peak, ai * bw["best_bytes_per_s"])
        roof[op] = {"bytes_per_pose": nbytes[op], "flop_per_byte": ai, "stream_ceiling_flops": ceil,
                    "stream_ceiling_frac_peak": ceil / ref_peak, "write": {}}
        print(f"  roofline for {op}: {nbytes[op]} compulsory bytes/pose, {ai:.2f} FLOP/byte -> with STREAM's "
              f"bandwidth a ceiling of {ceil / 1e9:.1f} GFLOP/s = {ceil / ref_peak:.1%} of the measured peak")
        for k in sorted({min(SMALL, args.poses), args.poses}):
            wb = write_bandwidth(nbytes[op] * k)
            wceil = min(ref_peak, ai * wb["best_bytes_per_s"])
            roof[op]["write"][k] = dict(wb, ceiling_flops=wceil, ceiling_frac_peak=wceil / ref_peak)
            print(f"    writing its {k:,}-pose output ({wb['bytes'] / 1e6:.1f} MB, {wb['threads']} threads): "
                  f"{wb['bytes_per_s'] / 1e9:.1f} GB/s median (best {wb['best_bytes_per_s'] / 1e9:.1f}) -> ceiling "
                  f"{wceil / 1e9:.1f} GFLOP/s = {wceil / ref_peak:.1%} of the measured peak (\"its roofline\" below)")
    sweep = res.pop("sweep", {})
    sc, sp = res.pop("sincos_only"), res.pop("sincos_poly")
    print(f"sin + cos of all {args.poses} x 6 joint angles alone: XLA's median {sc['median_s'] * 1e3:.2f} ms "
          f"(min {sc['min_s'] * 1e3:.2f}, max {sc['max_s'] * 1e3:.2f}); jaxcal.trig.sincos in XLA "
          f"{sp['median_s'] * 1e3:.2f} ms (min {sp['min_s'] * 1e3:.2f}, max {sp['max_s'] * 1e3:.2f})")
    sc["poly"] = sp
    # the ceiling the transcendentals set: every other operation free, the hand-counted FLOPs in
    # the time of sin + cos alone (both FK and the Jacobian need exactly these 12 values per pose)
    sc["ceiling"] = {}
    for op in ("FK", "Jacobian"):
        gf = hand[op] * args.poses / sc["median_s"]
        sc["ceiling"][op] = {"gflops": gf / 1e9, "frac_dgemm": gf / ref_peak}
        gp = hand[op] * args.poses / sp["median_s"]
        sc["ceiling"][op].update(gflops_poly=gp / 1e9, frac_dgemm_poly=gp / ref_peak)
        print(f"  ceiling for {op} if everything but sin/cos were free: {gf / 1e9:.1f} GFLOP/s = "
              f"{gf / ref_peak:.1%} of the measured peak with XLA's sin/cos, {gp / ref_peak:.1%} with jaxcal.trig's")
    for op, vs in res.items():
        base = vs[NATIVE]["poses_per_s"]
        for name, r in vs.items():
            gf = hand[op] * r["poses_per_s"]
            xf = "   n/a" if r["xla_flops_per_pose"] is None else f"{r['xla_flops_per_pose']:6.0f}"
            r.update(gflops_hand=gf / 1e9, frac_dgemm=gf / ref_peak, frac_nominal=gf / peak["nominal_flops"],
                     speedup_vs_shipped=r["poses_per_s"] / base,
                     frac_roofline=gf / roof[op]["write"][r.get("poses_per_call", args.poses)]["ceiling_flops"])
            per = f"/{r['poses_per_call']:,}" if "poses_per_call" in r else ""
            print(f"{op:9s} {name:43s} median {r['median_s'] * 1e3:8.2f} ms{per} (min {r['min_s'] * 1e3:.2f}, max "
                  f"{r['max_s'] * 1e3:.2f}) {r['poses_per_s']:>11,.0f} poses/s  x{r['speedup_vs_shipped']:.2f}  "
                  f"XLA {xf} FLOP/pose  {r['gflops_hand']:6.2f} GFLOP/s = "
                  f"{r['frac_dgemm']:6.1%} | {r['frac_nominal']:6.1%} ({r['frac_roofline']:5.1%} of its roofline)  "
                  f"compile {r['compile_s']:.2f} s  "
                  f"{r['fusions']} loop fusions"
                  + (f"  {r['faults_per_call']:,.0f} page faults/call" if "faults_per_call" in r else ""))
    if sweep:
        print_sweep(sweep, hand, ref_peak, "the native kernels vs poses per call")
    flag_rows = {}
    # each setting in a fresh process: XLA flags with the pure-JAX path, environment settings
    # (read by glibc at process start) with the native kernel
    settings = [(f"XLA_FLAGS={f!r}", {"XLA_FLAGS": f}, PURE) for f in args.flags]
    settings += [(e, dict(t.split("=", 1) for t in e.split()), [NATIVE, NATIVE_LAST]) for e in args.envs]
    for label, extra, names in settings:
        p = subprocess.run([sys.executable, __file__, "--_child", *([names] if isinstance(names, str) else names),
                            "--poses", str(args.poses), "--repeats", str(args.repeats), "--sweep",
                            *map(str, args.sweep if names != PURE else [])],
                           env=dict(os.environ, **extra), capture_output=True, text=True)
        if p.returncode != 0:
            msg = (p.stderr.strip().splitlines() or ["?"])[-1][:160]
            print(f"{label}: not accepted ({msg})")
            flag_rows[label] = {"error": msg}
            continue
        r = json.loads(p.stdout.strip().splitlines()[-1])
        flag_rows[label] = r
        if r.get("sweep"):
            print_sweep(r["sweep"], hand, ref_peak, f"{label}, fresh process: the native kernels vs poses per call")
        for op, vs in r.items():
            if op.startswith("sincos") or op == "sweep":
                continue
            for name, x in vs.items():
                ratio = res[op][name]["median_s"] / x["median_s"]
                gf = hand[op] * x["poses_per_s"]
                faults = f"  {x['faults_per_call']:,.0f} page faults/call" if "faults_per_call" in x else ""
                print(f"{label}: {op:9s} {name} median {x['median_s'] * 1e3:8.2f} ms  x{ratio:.2f} vs default  "
                      f"{gf / ref_peak:6.1%} of the measured peak{faults}")
    if args.json:
        os.makedirs(os.path.dirname(args.json) or ".", exist_ok=True)
        with open(args.json, "w") as f:
            json.dump({"machine": machine(), "poses": args.poses, "peak": peak, "hand_flops_per_pose": hand,
                       "hand_note": HAND_NOTE, "variants": res, "sincos_only": sc, "bandwidth": bw,
                       "roofline": roof, "settings": flag_rows, "native": native, "sweep": sweep}, f, indent=1)


if __name__ == "__main__":
    main()

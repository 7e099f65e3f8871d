// The worker threads of the kernels of chain.cc: blocks of poses split over the calling thread
// and a pool of its own.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <thread>

namespace {

// fk_kernel and jac_kernel run their blocks on the calling thread and on a pool of (cores - 1)
// worker threads of the kernel's own, started on first use and shared by every thread that calls
// in. Until 2026-11-23 they used an OpenMP loop. Through JAX a process would then switch at some
// call to a slow state for good: one more thread in /proc, two voluntary context switches per call
// (getrusage) and FK on 10^4 poses in 0.13-0.16 ms instead of 0.06-0.07, as if on one core.
// OpenMP's workers belong to the thread that starts the loop; JAX's asynchronous dispatch may call
// the kernel from another thread, which gets a second team, and libgomp stops spinning idle
// workers when it counts more threads than cores. Consistent with that: with dispatch in the
// calling thread (jax_cpu_enable_async_dispatch=False) the slow state did not come, and with this
// pool it comes with neither setting. XLA's own intra-op pool (the FFI's ThreadPool) had no slow
// state either but woke its sleeping worker on every call (FK on 10^4 poses 0.074-0.083 ms).
//
// A call publishes a job; workers spin on the job counter for SPIN_US after their last job (so
// back-to-back calls find them awake), then sleep on a condition variable. Jobs are shared_ptr: a
// worker that picks a job up after its call returned finds no chunk left and touches nothing of
// the caller's; the caller waits only for chunks already taken. Calls from several threads at once
// each get the workers that pick their job up, at worst none (then they run serially).
constexpr int SPIN_US = 200;

// 1: every call runs on its calling thread alone; otherwise on the pool too (the one-thread rows of
// benchmarks/bench_kernel_phases.py set it).
std::atomic<int64_t> max_threads{0};

// A call's blocks in ranges, one per thread (the caller's first): each thread drains its own
// range first, so across calls a thread keeps writing the same part of the output and finds it in
// its own cache (taking chunks in any order instead was 10-30 % slower for FK on 10^4 poses),
// then helps with the others' chunks.
struct Job {
  struct alignas(64) Range {
    std::atomic<int64_t> next{0};
    int64_t end = 0;
  };
  static constexpr int MAXR = 64;
  Range range[MAXR];
  alignas(64) std::atomic<int64_t> done{0};
  int ranges = 0;
  int64_t chunks = 0, per = 1;
  virtual void blocks(int64_t b0, int64_t b1) = 0;
  virtual ~Job() = default;
  void run(int home) {
    for (int k = 0; k < ranges; ++k) {
      Range &r = range[(home + k) % ranges];
      for (int64_t c; (c = r.next.fetch_add(1, std::memory_order_relaxed)) < r.end;) {
        blocks(c * per, std::min(c * per + per, nb_));
        done.fetch_add(1, std::memory_order_release);
      }
    }
  }
  int64_t nb_ = 0;
};

class Workers {
 public:
  static Workers &get() {
    static Workers *w = new Workers;  // never destroyed: its threads live as long as the process
    return *w;
  }
  int64_t size() const { return static_cast<int64_t>(threads_); }
  void publish(std::shared_ptr<Job> job) {
    std::lock_guard<std::mutex> lk(m_);
    current_ = std::move(job);
    gen_.fetch_add(1, std::memory_order_release);
    if (sleepers_ > 0) cv_.notify_all();
  }

 private:
  Workers() {  // a thread per core, the caller's included; JAXCAL_NATIVE_THREADS caps the count
    unsigned n = std::max(1u, std::thread::hardware_concurrency());
    if (const char *env = std::getenv("JAXCAL_NATIVE_THREADS")) n = std::max(1, std::min(std::atoi(env), int(n)));
    n = std::min<unsigned>(n, Job::MAXR);
    for (unsigned i = 0; i + 1 < n; ++i, ++threads_) std::thread([this, i] { loop(int(i) + 1); }).detach();
  }
  void loop(int home) {
    uint64_t seen = 0;
    for (;;) {
      auto t0 = std::chrono::steady_clock::now();
      for (int spins = 0; gen_.load(std::memory_order_acquire) == seen; ++spins) {
        if (spins % 64 != 63) continue;
        if (std::chrono::steady_clock::now() - t0 > std::chrono::microseconds(SPIN_US)) {
          std::unique_lock<std::mutex> lk(m_);
          ++sleepers_;
          cv_.wait(lk, [&] { return gen_.load(std::memory_order_acquire) != seen; });
          --sleepers_;
        }
      }
      std::shared_ptr<Job> job;
      {
        std::lock_guard<std::mutex> lk(m_);
        job = current_;
        seen = gen_.load(std::memory_order_acquire);
      }
      if (job && home < job->ranges) job->run(home);
    }
  }
  std::mutex m_;
  std::condition_variable cv_;
  std::atomic<uint64_t> gen_{0};
  std::shared_ptr<Job> current_;
  int sleepers_ = 0;
  unsigned threads_ = 0;
};

// body(ib) for every block ib < nb, on the calling thread and the workers, in about
// chunks_per_thread chunks per thread. More chunks let a thread that finishes early take more of
// the others' work; fewer keep each thread's writes to its own part of the output. FK takes 8.
// The Jacobian takes 2: with 8, a 10^5-pose Jacobian (a fresh 115 MB output on every call, 1,050
// page faults per call) ran at 7-17 ms per call, some processes twice as slow as others, and at
// 7.3-8.3 ms with 2 or 1 (13 fresh processes each; benchmarks/bench_kernel_ab.py --keep-heap,
// 2026-11-24); FK and the 10^4-pose Jacobian did not move beyond noise.
template <class Body>
void parallel_blocks(int64_t nb, const Body &body, int64_t chunks_per_thread = 8) {
  Workers &w = Workers::get();
  const int64_t threads = std::min(w.size() + 1, nb);
  if (threads < 2 || max_threads.load(std::memory_order_relaxed) == 1) {
    for (int64_t ib = 0; ib < nb; ++ib) body(ib);
    return;
  }
  struct BodyJob : Job {
    const Body *body;
    void blocks(int64_t b0, int64_t b1) override {
      for (int64_t ib = b0; ib < b1; ++ib) (*body)(ib);
    }
  };
  auto job = std::make_shared<BodyJob>();
  job->body = &body;
  job->nb_ = nb;
  job->per = std::max<int64_t>(1, nb / (chunks_per_thread * threads));
  job->chunks = (nb + job->per - 1) / job->per;
  job->ranges = static_cast<int>(threads);
  for (int k = 0; k < job->ranges; ++k) {  // range k: chunks [chunks k / ranges, chunks (k + 1) / ranges)
    job->range[k].next.store(job->chunks * k / job->ranges, std::memory_order_relaxed);
    job->range[k].end = job->chunks * (k + 1) / job->ranges;
  }
  w.publish(job);
  job->run(0);
  for (int spins = 0; job->done.load(std::memory_order_acquire) < job->chunks; ++spins)
    if (spins > 64) std::this_thread::yield();
}

}  // namespace

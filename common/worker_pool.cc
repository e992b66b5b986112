#include "common/worker_pool.h"

#include <chrono>
#include <stdexcept>
#include <thread>

namespace perch {

namespace {

using Clock = std::chrono::steady_clock;

inline void CpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

// Polls pred() for up to spin_us; true when it held within that time.
template <typename Pred>
bool SpinFor(double spin_us, Pred pred) {
  const auto until = Clock::now() + std::chrono::duration<double, std::micro>(spin_us);
  for (int i = 0;; ++i) {
    if (pred()) return true;
    CpuRelax();
    if ((i & 63) == 63) {
      if (Clock::now() >= until) return pred();
      // Should the thread we wait for share this core, let it run.
      std::this_thread::yield();
    }
  }
}

}  // namespace

WorkerPool::WorkerPool(int threads, double spin_us) : spin_us_(spin_us) {
  if (threads < 1) throw std::invalid_argument("WorkerPool: threads must be >= 1");
  for (int i = 1; i < threads; ++i) workers_.emplace_back([this, i] { WorkerLoop(i); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  start_cv_.notify_all();
  for (std::thread& t : workers_) t.join();
}

void WorkerPool::Run(int n, const std::function<void(int)>& fn) {
  if (n <= 0) return;
  if (n > threads()) throw std::invalid_argument("WorkerPool::Run: more tasks than threads");
  if (n > 1) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      fn_ = &fn;
      tasks_ = n;
      error_ = nullptr;
      pending_.store(n - 1, std::memory_order_relaxed);
      round_.fetch_add(1, std::memory_order_release);
    }
    start_cv_.notify_all();
  }
  std::exception_ptr mine;
  try {
    fn(0);
  } catch (...) {
    mine = std::current_exception();
  }
  if (n > 1) {
    if (!SpinFor(spin_us_, [&] { return pending_.load(std::memory_order_acquire) == 0; })) {
      std::unique_lock<std::mutex> lock(mu_);
      done_cv_.wait(lock, [&] { return pending_.load(std::memory_order_acquire) == 0; });
    }
    std::lock_guard<std::mutex> lock(mu_);
    fn_ = nullptr;
    if (!mine) mine = error_;
  }
  if (mine) std::rethrow_exception(mine);
}

void WorkerPool::WorkerLoop(int index) {
  uint64_t seen = 0;
  for (;;) {
    const auto fresh = [&] {
      return stop_.load(std::memory_order_acquire) ||
             round_.load(std::memory_order_acquire) != seen;
    };
    if (!SpinFor(spin_us_, fresh)) {
      std::unique_lock<std::mutex> lock(mu_);
      start_cv_.wait(lock, fresh);
    }
    const std::function<void(int)>* fn = nullptr;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stop_) return;
      seen = round_.load(std::memory_order_relaxed);
      if (index >= tasks_) continue;  // this round needs fewer workers
      fn = fn_;
    }
    std::exception_ptr err;
    try {
      (*fn)(index);
    } catch (...) {
      err = std::current_exception();
    }
    if (err) {
      std::lock_guard<std::mutex> lock(mu_);
      if (!error_) error_ = err;
    }
    if (pending_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
      // The caller may be asleep on done_cv_: take the lock so the notify cannot fall between
      // its check and its wait.
      std::lock_guard<std::mutex> lock(mu_);
      done_cv_.notify_one();
    }
  }
}

}  // namespace perch

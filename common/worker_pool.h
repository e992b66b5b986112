// A fixed set of worker threads that run one parallel-for at a time: Run(n, fn) calls fn(0..n-1),
// task 0 on the calling thread, the others on the workers, and returns when all are done. Made
// for the learner's minibatch gradients: many short (sub-millisecond) rounds in a burst, so the
// threads are started once, and between rounds they spin briefly before sleeping: waking a
// sleeping thread costs tens to hundreds of microseconds on a VM, as much as a round's work.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace perch {

class WorkerPool {
 public:
  // threads >= 1 counts the caller: WorkerPool(1) starts no thread and runs everything inline.
  // spin_us: how long a worker polls for the next round (and the caller for the workers) before
  // sleeping.
  explicit WorkerPool(int threads, double spin_us = 2000.0);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int threads() const { return static_cast<int>(workers_.size()) + 1; }

  // fn(i) for i in [0, n), n <= threads(); blocks until every call returned. An exception thrown by
  // any call is rethrown here (the first one, after all calls finished). One caller at a time.
  void Run(int n, const std::function<void(int)>& fn);

 private:
  void WorkerLoop(int index);

  std::vector<std::thread> workers_;
  double spin_us_;
  std::mutex mu_;
  std::condition_variable start_cv_, done_cv_;
  const std::function<void(int)>* fn_ = nullptr;
  int tasks_ = 0;                    // of the current round
  std::atomic<int> pending_{0};      // worker tasks of the current round not finished
  std::atomic<uint64_t> round_{0};   // incremented per Run; workers wait for a new value
  std::atomic<bool> stop_{false};
  std::exception_ptr error_;         // guarded by mu_
};

}  // namespace perch

#include "inhand/core/internal/parallel.h"

#include <sched.h>
#include <tbb/global_control.h>

#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <mutex>

namespace inhand::detail {
namespace {

// One worker per further core, parked on a condition variable between calls. A call publishes
// its task under a new generation number with the number of workers it wants; each wanted
// worker takes it once, runs it and reports back; the caller waits for all of them before it
// returns, so the task (on the caller's stack) outlives every use.
class WorkerPool {
 public:
  // Runs task on `helpers` workers and the caller; false when the pool is in use (nothing run).
  bool run(int helpers, void (*task)(void*), void* ctx) {
    bool expected = false;
    if (!inUse_.compare_exchange_strong(expected, true)) return false;
    start(helpers);
    const int wanted = std::min<int>(helpers, int(threads_.size()));
    {
      std::lock_guard<std::mutex> lock(mutex_);
      task_ = task;
      ctx_ = ctx;
      wanted_ = wanted;
      running_ = wanted;
      ++generation_;
    }
    wake_.notify_all();
    task(ctx);
    {
      std::unique_lock<std::mutex> lock(mutex_);
      done_.wait(lock, [&] { return running_ == 0; });
    }
    inUse_ = false;
    return true;
  }

 private:
  // Starts workers up to `count` (only the caller holding inUse_ gets here).
  void start(int count) {
    while (int(threads_.size()) < count) threads_.emplace_back([this] { loop(); });
  }
  void loop() {
    uint64_t seen = 0;
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      wake_.wait(lock, [&] { return generation_ != seen; });
      seen = generation_;
      if (wanted_ == 0) continue;  // enough workers took this one
      --wanted_;
      void (*task)(void*) = task_;
      void* ctx = ctx_;
      lock.unlock();
      task(ctx);
      lock.lock();
      if (--running_ == 0) done_.notify_all();
    }
  }

  std::atomic<bool> inUse_{false};
  std::vector<std::thread> threads_;  // touched only by the caller holding inUse_
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  uint64_t generation_ = 0;
  int wanted_ = 0, running_ = 0;
  void (*task_)(void*) = nullptr;
  void* ctx_ = nullptr;
};

}  // namespace

void runOnThreads(int helpers, void (*task)(void*), void* ctx) {
  if (helpers <= 0) {
    task(ctx);
    return;
  }
  // Never destroyed: parked workers may outlive static destruction at exit, and a call made
  // during it still finds the pool.
  static WorkerPool* pool = new WorkerPool;
  if (pool->run(helpers, task, ctx)) return;
  std::vector<std::thread> threads;
  for (int t = 0; t < helpers; ++t) threads.emplace_back(task, ctx);
  task(ctx);
  for (std::thread& t : threads) t.join();
}

}  // namespace inhand::detail

namespace inhand {
namespace {
int defaultThreads() {
  if (const char* env = std::getenv("INHAND_THREADS")) {
    char* end = nullptr;
    const long n = std::strtol(env, &end, 10);
    if (end != env && *end == '\0' && n >= 1 && n <= 1024) return int(n);
  }
  // The CPUs this process may run on (taskset, a container's or a batch system's CPU set), not
  // every core of the machine.
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) == 0 && CPU_COUNT(&set) > 0) return CPU_COUNT(&set);
  return std::max(1, int(std::thread::hardware_concurrency()));
}
std::atomic<int> g_threads{0};  // 0: not yet decided
std::unique_ptr<tbb::global_control>& tbbLimit() {
  static std::unique_ptr<tbb::global_control> limit;
  return limit;
}
std::once_flag g_envApplied;
}  // namespace

int threadCount() {
  // The environment's setting reaches TBB too, on first use.
  std::call_once(g_envApplied, [] {
    if (g_threads.load() == 0 && std::getenv("INHAND_THREADS")) setThreadCount(defaultThreads());
  });
  const int n = g_threads.load();
  return n > 0 ? n : defaultThreads();
}

void setThreadCount(int n) {
  static std::mutex m;
  std::lock_guard<std::mutex> lock(m);
  g_threads = n > 0 ? n : 0;
  tbbLimit().reset();
  const int effective = n > 0 ? n : defaultThreads();
  tbbLimit() = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                     size_t(effective));
}

}  // namespace inhand

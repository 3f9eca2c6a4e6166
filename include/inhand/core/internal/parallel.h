#pragma once
// Thin wrapper over TBB so modules share one way of using both cores.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>
#include <vector>

namespace inhand {

// Threads inhand uses: the INHAND_THREADS environment variable when set (a positive integer),
// else one per core. setThreadCount(n) changes it for what follows (TBB's parallelism included;
// 0: back to the default). Results do not depend on it (tests/test_determinism.cc).
int threadCount();
void setThreadCount(int n);

// Calls fn(i) for i in [begin, end) on all cores, in chunks of at least `grain` items.
template <typename Fn>
void parallelFor(int begin, int end, Fn&& fn, int grain = 1) {
  tbb::parallel_for(tbb::blocked_range<int>(begin, end, grain),
                    [&](const tbb::blocked_range<int>& r) {
                      for (int i = r.begin(); i != r.end(); ++i) fn(i);
                    });
}

}  // namespace inhand

namespace inhand {

namespace detail {
// Runs task(ctx) on the calling thread and on `helpers` other threads at once and returns when
// all have returned. The helpers are persistent workers (started on first use, one per further
// core, parked between calls), so a call costs no thread start and finds the workers'
// thread_local buffers as the last call left them. When the workers are already in use (a call
// from inside a task, or from two threads at once) fresh std::threads run it instead.
// `task` must not throw.
void runOnThreads(int helpers, void (*task)(void*), void* ctx);
}  // namespace detail

// Calls fn(i) for i in [begin, end) on plain threads (one per core), taking items one at a time.
// For coarse items that call into Embree scene builds: inside TBB tasks, Embree's own TBB use in
// rtcCommitScene serialised the work (measured: no speed-up from the second core). The first
// exception an item throws stops the handing out of items and is rethrown here once every thread
// is done.
template <typename Fn>
void parallelForThreads(int begin, int end, Fn&& fn) {
  const int n = end - begin;
  if (n <= 0) return;
  const int threads = std::max(1, std::min<int>(n, threadCount()));
  struct Context {
    Fn& fn;
    int end;
    std::atomic<int> next;
    std::atomic<bool> failed{false};
    std::exception_ptr error;
  } context{fn, end, {begin}, {false}, nullptr};
  auto work = [](void* p) {
    Context& c = *static_cast<Context*>(p);
    for (int i = c.next++; i < c.end; i = c.next++) {
      try {
        c.fn(i);
      } catch (...) {
        if (!c.failed.exchange(true)) c.error = std::current_exception();
        c.next = c.end;
      }
    }
  };
  detail::runOnThreads(threads - 1, work, &context);
  if (context.error) std::rethrow_exception(context.error);
}

}  // namespace inhand

#pragma once
// Thin wrapper over TBB so modules share one way of using both cores.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

namespace inhand {

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

// Calls fn(i) for i in [begin, end) on plain std::threads (one per core), taking items one at a
// time. For coarse items that call into Embree scene builds: inside TBB tasks, Embree's own TBB
// use in rtcCommitScene serialised the work (measured: no speed-up from the second core).
template <typename Fn>
void parallelForThreads(int begin, int end, Fn&& fn) {
  const int n = end - begin;
  if (n <= 0) return;
  const int workers = std::max(1, std::min<int>(n, int(std::thread::hardware_concurrency())));
  std::atomic<int> next{begin};
  auto work = [&] {
    for (int i = next++; i < end; i = next++) fn(i);
  };
  std::vector<std::thread> threads;
  for (int t = 1; t < workers; ++t) threads.emplace_back(work);
  work();
  for (std::thread& t : threads) t.join();
}

}  // namespace inhand

#pragma once
// Thin wrapper over TBB so modules share one way of using both cores.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

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

#pragma once
// Wall-clock timing of the scan's steps (summary.json's timing_s).
#include <chrono>

namespace inhand {

using Clock = std::chrono::steady_clock;

// Seconds from t to now.
inline double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

}  // namespace inhand

#!/usr/bin/env bash
# Builds inhand with AddressSanitizer + UndefinedBehaviorSanitizer in ./build-asan and runs the
# whole test suite under them (CI runs it after the README's test command). Extra arguments go
# to ctest (e.g. -R Checkpoint).
set -euo pipefail
cd "$(dirname "$0")/.."
generator=()
command -v ninja > /dev/null && [ ! -f build-asan/CMakeCache.txt ] && generator=(-G Ninja)
cmake -S . -B build-asan "${generator[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DINHAND_SANITIZE=ON \
  -DINHAND_BUILD_BENCHMARKS=OFF > /dev/null
cmake --build build-asan -j"$(nproc)"
# Debian's urdfdom leaks its partly built tree on a URDF it rejects (fuzz/regressions/urdf):
# those tests set their own ASAN_OPTIONS; everything else runs with leak checking on.
ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1}" UBSAN_OPTIONS="print_stacktrace=1" \
  ctest --test-dir build-asan --output-on-failure -j"$(nproc)" "$@"

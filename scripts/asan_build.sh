#!/usr/bin/env bash
# Configures ./build-asan, the one sanitizer build that scripts/sanitize.sh (the test suite under
# AddressSanitizer + UBSan) and scripts/fuzz.sh (the libFuzzer targets) share: clang, ASan and
# UBSan, the library instrumented for libFuzzer's coverage (INHAND_FUZZ), no benchmarks. One
# build instead of two saves CI a whole sanitized compile of the library. Sourced, not run.
asan_configure() {
  command -v clang++ > /dev/null || { echo "sanitizers: need clang (apt-get install clang)" >&2; return 2; }
  # A build tree configured with another compiler cannot switch: start it again.
  if [ -f build-asan/CMakeCache.txt ] &&
     ! grep -q '^CMAKE_CXX_COMPILER:[A-Z]*=.*clang++' build-asan/CMakeCache.txt; then
    rm -rf build-asan
  fi
  local generator=()
  command -v ninja > /dev/null && [ ! -f build-asan/CMakeCache.txt ] && generator=(-G Ninja)
  # Line tables only (-g1): reports keep their file:line, and the build takes about a third less
  # time than with full debug information.
  CC=clang CXX=clang++ cmake -S . -B build-asan "${generator[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" \
    -DINHAND_FUZZ=ON -DINHAND_BUILD_BENCHMARKS=OFF -DINHAND_BUILD_PYTHON=OFF > /dev/null
}

#!/usr/bin/env bash
# Builds inhand with AddressSanitizer + UndefinedBehaviorSanitizer in ./build-asan (clang; the
# fuzzers share the build: scripts/asan_build.sh) and runs the test suite under them (CI runs it
# after the README's test command). Without arguments: every test but those labelled whole_scans
# (checkpoints, faults, determinism: a dozen two-grasp scans, about 40 min more under the
# sanitizers; the ordinary build runs them) and the long tests named in
# scripts/sanitize_skip.txt. Arguments go to ctest instead (e.g. `-L whole_scans`, or `-E NONE`
# for everything).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/asan_build.sh
asan_configure
cmake --build build-asan -j"$(nproc)"
# Debian's urdfdom leaks its partly built tree on a URDF it rejects (fuzz/regressions/urdf):
# those tests set their own ASAN_OPTIONS; everything else runs with leak checking on.
args=("$@")
# The default leaves out, besides whole_scans, the tests named in scripts/sanitize_skip.txt (the
# longest under the sanitizers; the ordinary build runs them all).
skip=$(grep -v '^#' scripts/sanitize_skip.txt | grep . | sed 's/[.]/[.]/g' | paste -sd'|')
slow="^(${skip})\$"
[ ${#args[@]} -gt 0 ] || args=(-LE whole_scans -E "$slow")
ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1}" UBSAN_OPTIONS="print_stacktrace=1" \
  ctest --test-dir build-asan --output-on-failure -j"$(nproc)" "${args[@]}"

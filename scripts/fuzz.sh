#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan+UBSan, in build-asan/, the build scripts/sanitize.sh
# runs the tests in: scripts/asan_build.sh) and fuzzes each for SECONDS (default 60) from its seed
# corpus (fuzz/corpus/<target>, copied: the repository's corpus is not changed) and its regressions
# (fuzz/regressions/<target>, read only: inputs that once crashed a loader). Usage: scripts/fuzz.sh
# [SECONDS] [TARGET...]. A crash stops with a non-zero exit; the input is in
# build-asan/artifacts/<target>/. Prints a table row per target: executions, corpus size, crashes.
# FUZZ_SEED=N fixes libFuzzer's seed (CI: 1); unset, each run differs.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(depth_png frames_json ply mesh_import urdf robot_config scan_config volume_data)
source scripts/asan_build.sh
asan_configure
cmake --build build-asan -j"$(nproc)" --target $(printf 'fuzz_%s ' "${targets[@]}")
status=0
printf '%-14s %8s %12s %8s %8s\n' target seconds executions corpus crashes
for t in "${targets[@]}"; do
  corpus="build-asan/corpus/$t"
  artifacts="build-asan/artifacts/$t/"
  rm -rf "$artifacts"
  mkdir -p "$corpus" "$artifacts"
  cp -n fuzz/corpus/"$t"/* "$corpus"/ 2> /dev/null || true
  log="build-asan/fuzz_$t.log"
  regressions=()
  [ -d fuzz/regressions/"$t" ] && regressions=(fuzz/regressions/"$t")
  # Both cores: one fuzzing job per core. -rss_limit_mb/-malloc_limit_mb: a loader that believes
  # a header claiming 10^9 vertices fails here.
  # urdfdom (Debian's) leaks its partly built tree on a URDF with a loop: no leak check there.
  leaks=1
  [ "$t" = urdf ] && leaks=0
  set +e
  ASAN_OPTIONS=detect_leaks=$leaks "build-asan/fuzz/fuzz_$t" "$corpus" "${regressions[@]}" \
    -max_total_time="$seconds" -detect_leaks=$leaks -seed="${FUZZ_SEED:-0}" \
    -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024 -max_len=65536 -print_final_stats=1 \
    -artifact_prefix="$artifacts" -jobs="$(nproc)" -workers="$(nproc)" > "$log" 2>&1
  rc=$?
  set -e
  execs=$(grep -h 'stat::number_of_executed_units' "$log" fuzz-*.log 2> /dev/null |
          awk '{s += $2} END {print s + 0}')
  crashes=$(find "$artifacts" -type f | wc -l)
  printf '%-14s %8s %12s %8s %8s\n' "$t" "$seconds" "$execs" "$(ls "$corpus" | wc -l)" "$crashes"
  rm -f fuzz-*.log
  if [ "$rc" -ne 0 ] || [ "$crashes" -ne 0 ]; then
    echo "fuzz: $t found a problem (exit $rc); inputs in $artifacts, log $log" >&2
    status=1
  fi
done
exit "$status"

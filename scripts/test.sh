#!/usr/bin/env bash
# The README's test command: installs what is missing, builds, runs every test (arguments, if
# any, go to ctest: e.g. `-LE whole_scans`).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
# INHAND_NO_AVX2=1: the suite as on a CPU without AVX2 and FMA (inhand's run-time AVX2 paths and
# Embree's AVX2 kernels off, glibc's libm without its FMA and AVX2 variants). CI runs both.
if [ -n "${INHAND_NO_AVX2:-}" ] && [ "${INHAND_NO_AVX2}" != 0 ]; then
  export GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F
fi
ctest --test-dir build --output-on-failure -j"$(nproc)" "$@"

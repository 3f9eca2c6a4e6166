#!/usr/bin/env bash
# scripts/check_includes.py passes on this repository and fails on a tree whose lower module
# includes a header of a module above it.
set -euo pipefail
src="$1"
/usr/bin/python3 "$src/scripts/check_includes.py"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/src/low" "$tmp/src/high" "$tmp/include/inhand/low" "$tmp/include/inhand/high"
cat > "$tmp/src/CMakeLists.txt" << 'CMAKE'
inhand_module(low
  SOURCES low/a.cc
  DEPS Eigen3::Eigen)
inhand_module(high
  SOURCES high/b.cc
  DEPS inhand::low)
CMAKE
echo '#include "inhand/low/a.h"' > "$tmp/src/high/b.cc"
echo '#include "inhand/low/a.h"' > "$tmp/src/low/a.cc"
/usr/bin/python3 "$src/scripts/check_includes.py" --root "$tmp"
echo '#include "inhand/high/b.h"' > "$tmp/include/inhand/low/a.h"
if /usr/bin/python3 "$src/scripts/check_includes.py" --root "$tmp" > "$tmp/out.txt"; then
  echo "check_includes_test: a wrong-way include was not found" >&2
  exit 1
fi
grep -q "low includes high" "$tmp/out.txt"
echo "check_includes_test: passed"

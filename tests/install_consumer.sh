#!/usr/bin/env bash
# ctest: installs the build tree into a temporary prefix, builds examples/cpp_consumer against it
# with find_package(inhand), and runs it and the installed CLI on the installed data.
# Usage: install_consumer.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
build="$1"
source="$2"
prefix="$(mktemp -d)"
trap 'rm -rf "$prefix"' EXIT
cmake --install "$build" --prefix "$prefix/usr" > "$prefix/install.log"
test -f "$prefix/usr/include/inhand/inhand.h"
test -f "$prefix/usr/lib/cmake/inhand/inhandConfig.cmake"
generator=()
command -v ninja > /dev/null && generator=(-G Ninja)
cmake -S "$source/examples/cpp_consumer" -B "$prefix/build" "${generator[@]}" \
  -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH="$prefix/usr" > "$prefix/configure.log"
cmake --build "$prefix/build" -j2 > "$prefix/build.log" || { cat "$prefix/build.log"; exit 1; }
"$prefix/build/consumer" "$prefix/usr/share/inhand/data/robots/wam_barretthand.json"
# The installed CLI finds its data and web assets beside itself.
"$prefix/usr/bin/inhand" robot --config "$prefix/usr/share/inhand/data/robots/wam_barretthand.json" \
  --grid 1 --directions 8 --rolls 2 | head -n 3
# Recorded frames fused, and a ScanSession driven against the simulator, by programs of one's own.
"$prefix/usr/bin/inhand" render --object builtin:pill_bottle --views 12 --out "$prefix/frames" \
  > /dev/null 2>&1
"$prefix/build/fuse_frames" "$prefix/frames" "$prefix/fused.ply"
test -s "$prefix/fused.ply"
"$prefix/build/drive_session" "$prefix/usr/share/inhand/data/robots/wam_barretthand.json" \
  "$prefix/session"
test -s "$prefix/session/model.ply" && test -s "$prefix/session/scan.inhand"
# The Python package, when built, imports from the installed tree and finds the installed data.
if [ -d "$build/python/inhand" ]; then
  PYTHONPATH="$prefix/usr/lib/python3/dist-packages" /usr/bin/python3 -c "
import inhand, sys
assert inhand.data_dir().startswith('$prefix'), inhand.data_dir()
print('install_consumer: python', inhand.Robot.load().name, 'from', inhand.__file__)"
fi
echo "install_consumer: ok"

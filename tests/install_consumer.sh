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
echo "install_consumer: ok"

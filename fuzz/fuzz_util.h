#pragma once
// Shared by the libFuzzer targets: the input goes to a file (the loaders read files), the loader
// runs, and only inhand::Error (a clean rejection naming the file) is an accepted way to fail.
// Any other exception, a crash, a hang or an unbounded allocation is a finding.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "inhand/core/error.h"

namespace inhand::fuzz {

// A per-process scratch folder (removed at exit by the OS's tmp cleaning; reused per input).
inline const std::filesystem::path& scratch() {
  static const std::filesystem::path dir = [] {
    std::filesystem::path d =
        std::filesystem::temp_directory_path() / ("inhand_fuzz_" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    return d;
  }();
  return dir;
}

inline std::filesystem::path writeInput(const std::string& name, const uint8_t* data, size_t size) {
  const std::filesystem::path p = scratch() / name;
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  return p;
}

// Runs fn(); an inhand::Error must name `file` (its file name) in its message, or `companion`
// when given (a file read together with it, e.g. the robot config a URDF is checked against).
template <typename Fn>
void expectCleanResult(const std::filesystem::path& file, Fn&& fn,
                       const std::filesystem::path& companion = {}) {
  try {
    fn();
  } catch (const inhand::Error& e) {
    const std::string what = e.what();
    const bool named =
        what.find(file.filename().string()) != std::string::npos ||
        (!companion.empty() && what.find(companion.filename().string()) != std::string::npos);
    if (!named) {
      std::fprintf(stderr, "error does not name %s: %s\n", file.filename().c_str(), what.c_str());
      std::abort();
    }
  }
}

}  // namespace inhand::fuzz

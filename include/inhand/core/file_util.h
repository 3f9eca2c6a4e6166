#pragma once
// Output files appear whole or not at all: write to a temporary sibling, then rename.
#include <filesystem>
#include <functional>
#include <string>

namespace inhand {

namespace fs = std::filesystem;

// Writes `path` by calling write(tmp_path) and renaming tmp_path over path. On any exception the
// temporary is removed and the exception propagates; `path` is untouched.
void writeFileAtomically(const fs::path& path, const std::function<void(const fs::path&)>& write);

// Writes text to `path` atomically; throws Error naming the path on failure.
void writeTextAtomically(const fs::path& path, const std::string& text);

// Reads a whole text file; throws Error naming the path when it is missing or unreadable.
std::string readTextFile(const fs::path& path);

// Where a resource folder `name` (data, web) is: beside an installed executable
// (EXE_DIR/../share/inhand/NAME, as `cmake --install` lays it out) when that exists, else
// `built_in` (the source tree the program was built from).
fs::path resourceDirectory(const std::string& name, const fs::path& built_in);

// A directory that is filled in a temporary sibling and renamed into place on commit().
// Without commit() (an exception, an early return) the temporary is removed.
class StagedDirectory {
 public:
  // Throws Error when `target` exists and is not an empty directory (with `replace`: when it
  // exists and is not a directory). commit() replaces whatever the target holds then.
  explicit StagedDirectory(const fs::path& target, bool replace = false);
  ~StagedDirectory();
  StagedDirectory(const StagedDirectory&) = delete;
  StagedDirectory& operator=(const StagedDirectory&) = delete;

  const fs::path& path() const { return staging_; }  // where to write the files
  void commit();

 private:
  fs::path target_;
  fs::path staging_;
  bool committed_ = false;
};

}  // namespace inhand

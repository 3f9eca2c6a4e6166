#include "inhand/core/file_util.h"

#include <unistd.h>

#include <atomic>
#include <fstream>
#include <sstream>

#include "inhand/core/error.h"

namespace inhand {

namespace {
fs::path tempSibling(const fs::path& path, const char* tag) {
  static std::atomic<int> counter{0};
  fs::path dir = path.parent_path();
  std::string name(".");
  name += path.filename().string();
  name += '.';
  name += tag;
  name += '.';
  name += std::to_string(getpid());
  name += '.';
  name += std::to_string(counter++);
  return dir.empty() ? fs::path(name) : dir / name;
}
}  // namespace

void writeFileAtomically(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  fs::path parent = path.parent_path();
  if (!parent.empty() && !fs::is_directory(parent))
    throw Error(path.string() + ": the directory " + parent.string() + " does not exist");
  fs::path tmp = tempSibling(path, "tmp");
  try {
    write(tmp);
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) throw Error(path.string() + ": cannot write (" + ec.message() + ")");
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

void writeTextAtomically(const fs::path& path, const std::string& text) {
  writeFileAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw Error(path.string() + ": cannot open for writing");
    out << text;
    out.close();
    if (!out) throw Error(path.string() + ": write failed (disk full?)");
  });
}

std::string readTextFile(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(path.string() + ": no such file");
  if (fs::is_directory(path, ec)) throw Error(path.string() + ": is a directory, not a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path.string() + ": cannot open for reading");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

StagedDirectory::StagedDirectory(const fs::path& target, bool replace) : target_(target) {
  std::error_code ec;
  if (fs::exists(target_, ec)) {
    if (!fs::is_directory(target_, ec))
      throw Error(target_.string() + ": exists and is not a directory");
    if (!replace && !fs::is_empty(target_, ec))
      throw Error(target_.string() +
                  ": directory exists and is not empty; choose a new output directory");
  }
  fs::path parent = fs::absolute(target_).parent_path();
  if (!fs::is_directory(parent, ec))
    throw Error(target_.string() + ": the parent directory " + parent.string() + " does not exist");
  staging_ = tempSibling(fs::absolute(target_).lexically_normal(), "partial");
  fs::create_directory(staging_, ec);
  if (ec) throw Error(target_.string() + ": cannot create a directory here (" + ec.message() + ")");
}

StagedDirectory::~StagedDirectory() {
  if (!committed_) {
    std::error_code ec;
    fs::remove_all(staging_, ec);
  }
}

void StagedDirectory::commit() {
  std::error_code ec;
  // What the target holds now (nothing, or e.g. a checkpoint) is moved aside, the staged
  // directory takes its name, then the old one is removed.
  fs::path old;
  if (fs::exists(target_, ec)) {
    old = tempSibling(fs::absolute(target_).lexically_normal(), "old");
    fs::rename(target_, old, ec);
    if (ec) throw Error(target_.string() + ": cannot replace it (" + ec.message() + ")");
  }
  fs::rename(staging_, target_, ec);
  if (ec) {
    std::error_code ignored;
    if (!old.empty()) fs::rename(old, target_, ignored);
    throw Error(target_.string() + ": cannot move output into place (" + ec.message() + ")");
  }
  committed_ = true;
  if (!old.empty()) fs::remove_all(old, ec);
}

fs::path resourceDirectory(const std::string& name, const fs::path& built_in) {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path installed = exe.parent_path().parent_path() / "share" / "inhand" / name;
    if (fs::is_directory(installed, ec)) return installed;
  }
  return built_in;
}

}  // namespace inhand

#pragma once
// Error policy (DESIGN.md): bad input at a boundary throws inhand::Error naming the file/field and
// the problem; expected outcomes are values; broken invariants abort with file and line.
#include <stdexcept>
#include <string>

namespace inhand {

// Bad input: a file, a field, an option. what() is a complete sentence for the user.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

[[noreturn]] void abortInvariant(const char* expr, const char* file, int line, const char* msg);

}  // namespace inhand

// Aborts with file and line when an internal invariant is broken (never for user input).
#define INHAND_CHECK(cond, msg)                                              \
  do {                                                                       \
    if (!(cond)) ::inhand::abortInvariant(#cond, __FILE__, __LINE__, (msg)); \
  } while (0)

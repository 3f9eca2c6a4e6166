#include "inhand/core/error.h"

#include <cstdio>
#include <cstdlib>

namespace inhand {

void abortInvariant(const char* expr, const char* file, int line, const char* msg) {
  std::fprintf(stderr, "inhand: internal error at %s:%d: %s (%s)\n", file, line, msg, expr);
  std::abort();
}

}  // namespace inhand

#pragma once
// An enum's names in JSON and logs from one table per enum: the name of a value and the value of
// a name, so that a reason is written and read back under one spelling.
#include <string>
#include <utility>

namespace inhand {

template <class E, size_t N>
using EnumNames = std::pair<E, const char*>[N];

// The name of `e` in `table` ("?" if the table lacks it).
template <class E, size_t N>
const char* enumName(const EnumNames<E, N>& table, E e) {
  for (const auto& [value, name] : table)
    if (value == e) return name;
  return "?";
}

// The value named `name` in `table`; false when none is.
template <class E, size_t N>
bool enumFromName(const EnumNames<E, N>& table, const std::string& name, E* out) {
  for (const auto& [value, n] : table)
    if (name == n) {
      *out = value;
      return true;
    }
  return false;
}

}  // namespace inhand

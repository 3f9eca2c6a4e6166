#pragma once
// One row per option. An options struct lists its options once, in a static member
//
//   template <class V, class S> static void fields(V& v, S& o);   // S: the struct, const or not
//
// with a row per option: its key, the field, what it means and the range it must lie in:
//
//   v.num("t_hand_m", o.t_hand_m, "hits this close to the hand are skipped, m", Range::atLeast(0));
//
// A visitor does one thing with every row: OptionChecker below checks each value against its range
// (the struct's validate() starts with it), and config/ reads, writes and documents the same rows
// (a scan's JSON options, summary.json's "options", docs/config.md). The visitor interface:
//   num(key, double, doc, Range), integer(key, int, doc, Range), boolean(key, bool, doc),
//   numbers(key, std::vector<double>, doc, Range of each), string(key, std::string, doc),
//   choice(key, T, const EnumNames<T, N>&, doc), object(key, doc, visit(V& sub)).
// Relations between options (touch force ≤ finger force, p_free < p_unknown) stay in validate().
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "inhand/core/enum_names.h"

namespace inhand {

// An interval of allowed values, each end open or closed (±∞: no bound).
struct Range {
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false, hi_open = false;

  static Range any() { return {}; }
  static Range atLeast(double lo) { return {lo, kInf, false, false}; }             // [lo, ∞)
  static Range above(double lo) { return {lo, kInf, true, false}; }                // (lo, ∞)
  static Range closed(double lo, double hi) { return {lo, hi, false, false}; }     // [lo, hi]
  static Range open(double lo, double hi) { return {lo, hi, true, true}; }         // (lo, hi)
  static Range closedOpen(double lo, double hi) { return {lo, hi, false, true}; }  // [lo, hi)
  static Range openClosed(double lo, double hi) { return {lo, hi, true, false}; }  // (lo, hi]

  bool bounded() const { return std::isfinite(lo) || std::isfinite(hi); }
  bool contains(double x) const {
    if (std::isnan(x)) return false;
    if (lo_open ? !(x > lo) : !(x >= lo)) return false;
    return hi_open ? x < hi : x <= hi;
  }
  // ">= 0", "> 0", "in (0, 90)", "in 1..16" (integers: closed ends).
  std::string text(bool integer = false) const {
    const bool has_lo = std::isfinite(lo), has_hi = std::isfinite(hi);
    if (!has_lo && !has_hi) return "any";
    if (integer) {
      const double a = lo_open ? std::floor(lo) + 1 : std::ceil(lo);
      const double b = hi_open ? std::ceil(hi) - 1 : std::floor(hi);
      if (!has_hi) return ">= " + number(a);
      if (!has_lo) return "<= " + number(b);
      return "in " + number(a) + ".." + number(b);
    }
    if (!has_hi) return (lo_open ? "> " : ">= ") + number(lo);
    if (!has_lo) return (hi_open ? "< " : "<= ") + number(hi);
    return "in " + std::string(lo_open ? "(" : "[") + number(lo) + ", " + number(hi) +
           (hi_open ? ")" : "]");
  }
  static std::string number(double x) {
    char s[32];
    std::snprintf(s, sizeof s, "%g", x);
    return s;
  }

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
};

// Checks every row against its range; `error` is the first row out of range ("prefix.key must be
// in (0, 90), is 95"), empty when all are in range.
class OptionChecker {
 public:
  explicit OptionChecker(std::string prefix = "") : prefix_(std::move(prefix)) {}
  std::string error;

  void num(const std::string& key, double v, const char*, Range r = {}) {
    if (error.empty() && !r.contains(v)) fail(key, r.text(), Range::number(v));
  }
  void integer(const std::string& key, int v, const char*, Range r = {}) {
    if (error.empty() && !r.contains(v)) fail(key, r.text(true), std::to_string(v));
  }
  void boolean(const std::string&, bool, const char*) {}
  void numbers(const std::string& key, const std::vector<double>& v, const char*, Range r = {}) {
    for (double x : v)
      if (error.empty() && !r.contains(x)) fail(key, r.text() + " each", Range::number(x));
  }
  void string(const std::string&, const std::string&, const char*) {}
  template <class T, size_t N>
  void choice(const std::string& key, const T& v, const EnumNames<T, N>& names, const char*) {
    for (const auto& [value, name] : names)
      if (value == v) return;
    if (error.empty()) error = prefix_ + key + " has a value outside its names";
  }
  template <class F>
  void object(const std::string& key, const char*, F visit) {
    OptionChecker sub(prefix_ + key + ".");
    visit(sub);
    if (error.empty()) error = sub.error;
  }

 private:
  void fail(const std::string& key, const std::string& range, const std::string& value) {
    error = prefix_ + key + " must be " + range + " (is " + value + ")";
  }
  std::string prefix_;
};

// The first row of `o` out of its range (O::fields), empty when every row is in range.
template <class O>
std::string checkOptionRanges(const O& o) {
  OptionChecker c;
  O::fields(c, o);
  return c.error;
}

}  // namespace inhand

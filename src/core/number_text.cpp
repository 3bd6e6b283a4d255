#include "covoxslam/core/number_text.h"

#include <locale.h>  // newlocale (POSIX 2008)
#include <stdlib.h>  // strtod_l

#include <cerrno>
#include <cstdio>
#include <cmath>
#include <string>

namespace covox {
namespace {

// The "C" locale, created once and never freed (a locale_t lives for the process).
locale_t classic_locale() {
  static const locale_t locale = newlocale(LC_ALL_MASK, "C", static_cast<locale_t>(0));
  return locale;
}

// strtod_l also accepts leading white space and hexadecimal floats ("0x1p3"), which none of the
// text formats allows; they are refused before parsing.
bool has_foreign_characters(std::string_view token) {
  for (const char c : token) {
    if (c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f' || c == 'x' ||
        c == 'X') {
      return true;
    }
  }
  return false;
}

}  // namespace

bool parse_double(std::string_view token, double* value) {
  if (token.empty() || has_foreign_characters(token)) return false;
  // A null-terminated copy: short tokens (every number in practice) on the stack.
  constexpr size_t kStackCharacters = 64;
  char stack_copy[kStackCharacters];
  std::string heap_copy;
  const char* text = stack_copy;
  if (token.size() < kStackCharacters) {
    token.copy(stack_copy, token.size());
    stack_copy[token.size()] = '\0';
  } else {
    heap_copy.assign(token);
    text = heap_copy.c_str();
  }
  errno = 0;
  char* end = nullptr;
  const double parsed = strtod_l(text, &end, classic_locale());
  if (end != text + token.size()) return false;
  if (errno == ERANGE && std::isinf(parsed)) return false;  // overflow; underflow rounds
  *value = parsed;
  return true;
}

std::string format_double(double value) {
  // %g at each precision in turn, in the "C" locale; among the texts that read back exactly, the
  // shortest (the first of equal length). 17 significant digits always read back.
  const locale_t previous = uselocale(classic_locale());
  std::string best;
  for (int precision = 1; precision <= 17; ++precision) {
    char text[40];
    std::snprintf(text, sizeof(text), "%.*g", precision, value);
    double back = 0.0;
    const bool exact = parse_double(text, &back) && (back == value || std::isnan(value));
    if (exact && (best.empty() || std::string_view(text).size() < best.size())) best = text;
  }
  uselocale(previous);
  return best;
}

}  // namespace covox

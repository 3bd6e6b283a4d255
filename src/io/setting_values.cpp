#include "covoxslam/io/setting_values.h"

#include <charconv>
#include <cmath>
#include <system_error>

#include "covoxslam/core/number_text.h"

namespace covox {
namespace io {
namespace {

bool is_digit(char c) { return c >= '0' && c <= '9'; }

// The length of the run of digits at `position`.
size_t digits_at(std::string_view text, size_t position) {
  size_t end = position;
  while (end < text.size() && is_digit(text[end])) ++end;
  return end - position;
}

// Whether `text` is exactly the decimal number grammar of parse_number_value.
bool is_decimal_number(std::string_view text) {
  size_t position = 0;
  if (position < text.size() && (text[position] == '+' || text[position] == '-')) ++position;
  const size_t whole = digits_at(text, position);
  position += whole;
  size_t fraction = 0;
  if (position < text.size() && text[position] == '.') {
    fraction = digits_at(text, position + 1);
    position += 1 + fraction;
  }
  if (whole + fraction == 0) return false;
  if (position < text.size() && (text[position] == 'e' || text[position] == 'E')) {
    ++position;
    if (position < text.size() && (text[position] == '+' || text[position] == '-')) ++position;
    const size_t exponent = digits_at(text, position);
    if (exponent == 0) return false;
    position += exponent;
  }
  return position == text.size();
}

std::string quoted(std::string_view text) { return "'" + std::string(text) + "'"; }

}  // namespace

std::string parse_number_value(std::string_view text, double* value) {
  if (!is_decimal_number(text)) return "expected a finite decimal number, got " + quoted(text);
  // The grammar is checked above, so parse_double refuses only a magnitude beyond a double's.
  double parsed = 0.0;
  if (!parse_double(text, &parsed) || !std::isfinite(parsed))
    return "the number " + quoted(text) + " is out of a double's range";
  *value = parsed;
  return std::string();
}

std::string parse_integer_value(std::string_view text, int64_t* value) {
  size_t position = !text.empty() && (text.front() == '+' || text.front() == '-') ? 1 : 0;
  if (digits_at(text, position) == 0 || position + digits_at(text, position) != text.size())
    return "expected an integer, got " + quoted(text);
  const std::string_view digits = text.front() == '+' ? text.substr(1) : text;
  int64_t parsed = 0;
  const std::from_chars_result result =
      std::from_chars(digits.data(), digits.data() + digits.size(), parsed);
  if (result.ec == std::errc::result_out_of_range)
    return "the integer " + quoted(text) + " is out of range";
  if (result.ec != std::errc() || result.ptr != digits.data() + digits.size())
    return "expected an integer, got " + quoted(text);
  *value = parsed;
  return std::string();
}

std::string parse_bool_value(std::string_view text, bool* value) {
  if (text == "true" || text == "false") {
    *value = text == "true";
    return std::string();
  }
  return "expected true or false, got " + quoted(text);
}

std::string format_setting_number(double value) { return format_double(value); }

}  // namespace io
}  // namespace covox

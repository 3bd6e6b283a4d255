#pragma once
// Splitting and number parsing for the text formats (pose files, intrinsics, ASCII PCD); the
// numbers go through covox::parse_double (core/number_text.h), which ignores the locale.
#include <string>
#include <string_view>
#include <vector>

#include "covoxslam/core/number_text.h"

namespace covox {
namespace io {

// Splits on spaces, tabs and carriage returns.
std::vector<std::string_view> split_whitespace(std::string_view line);

// One line of a text file that is neither empty nor a '#' comment, split on white space (views
// into the text), with its 1-based line number for error messages.
struct TokenLine {
  int line_number = 0;
  std::vector<std::string_view> tokens;
};

// Every line of `text` that has a token and does not start with '#' (the comment convention of
// every text format read here).
std::vector<TokenLine> split_token_lines(std::string_view text);

// One non-empty line of a numeric text file, with its 1-based line number for error messages.
struct NumberLine {
  int line_number = 0;
  std::vector<double> values;
};

// Every non-empty line that is not a '#' comment, parsed into numbers. Throws covox::Error naming
// `path` and the line on a token that is not a number.
std::vector<NumberLine> parse_number_lines(const std::string& text, const std::string& path);

}  // namespace io
}  // namespace covox

#pragma once
// Locale-independent number parsing for the text formats (pose files, intrinsics, ASCII PCD).
// strtod would read "0,5" under a German locale that a ROS node may have set; from_chars never
// looks at the locale.
#include <string>
#include <string_view>
#include <vector>

namespace covox {
namespace io {

// Parses the whole token as a double ("nan", "inf", a leading '+' accepted); false on anything
// else, including trailing characters.
bool parse_double(std::string_view token, double* value);

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

#include "covoxslam/io/text_numbers.h"

#include <charconv>
#include <system_error>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {

bool parse_double(std::string_view token, double* value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const char* end = token.data() + token.size();
  const std::from_chars_result result = std::from_chars(token.data(), end, *value);
  // out-of-range (e.g. 1e400) is reported as an error by from_chars; we treat it as a bad number
  // too, because a pose or coordinate that large is corrupt anyway.
  return result.ec == std::errc() && result.ptr == end;
}

std::vector<std::string_view> split_whitespace(std::string_view line) {
  std::vector<std::string_view> tokens;
  size_t position = 0;
  while (position < line.size()) {
    const size_t begin = line.find_first_not_of(" \t\r", position);
    if (begin == std::string_view::npos) break;
    size_t end = line.find_first_of(" \t\r", begin);
    if (end == std::string_view::npos) end = line.size();
    tokens.push_back(line.substr(begin, end - begin));
    position = end;
  }
  return tokens;
}

std::vector<NumberLine> parse_number_lines(const std::string& text, const std::string& path) {
  std::vector<NumberLine> lines;
  const std::string_view all(text);
  size_t line_begin = 0;
  int line_number = 0;
  while (line_begin < all.size()) {
    size_t line_end = all.find('\n', line_begin);
    if (line_end == std::string_view::npos) line_end = all.size();
    ++line_number;
    const std::vector<std::string_view> tokens = split_whitespace(all.substr(line_begin, line_end - line_begin));
    line_begin = line_end + 1;
    if (tokens.empty() || tokens.front().front() == '#') continue;

    NumberLine parsed;
    parsed.line_number = line_number;
    parsed.values.resize(tokens.size());
    for (size_t i = 0; i < tokens.size(); ++i) {
      if (!parse_double(tokens[i], &parsed.values[i])) {
        throw Error(path + ":" + std::to_string(line_number) + ": '" + std::string(tokens[i]) +
                    "' is not a number");
      }
    }
    lines.push_back(std::move(parsed));
  }
  return lines;
}

}  // namespace io
}  // namespace covox

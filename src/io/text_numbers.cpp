#include "covoxslam/io/internal/text_numbers.h"

#include "covoxslam/core/error.h"

namespace covox {
namespace io {

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

std::vector<TokenLine> split_token_lines(std::string_view text) {
  std::vector<TokenLine> lines;
  size_t line_begin = 0;
  int line_number = 0;
  while (line_begin < text.size()) {
    size_t line_end = text.find('\n', line_begin);
    if (line_end == std::string_view::npos) line_end = text.size();
    ++line_number;
    std::vector<std::string_view> tokens =
        split_whitespace(text.substr(line_begin, line_end - line_begin));
    line_begin = line_end + 1;
    if (tokens.empty() || tokens.front().front() == '#') continue;
    lines.push_back(TokenLine{line_number, std::move(tokens)});
  }
  return lines;
}

std::vector<NumberLine> parse_number_lines(const std::string& text, const std::string& path) {
  std::vector<NumberLine> lines;
  for (const TokenLine& line : split_token_lines(text)) {
    NumberLine parsed;
    parsed.line_number = line.line_number;
    parsed.values.resize(line.tokens.size());
    for (size_t i = 0; i < line.tokens.size(); ++i) {
      if (!parse_double(line.tokens[i], &parsed.values[i])) {
        throw Error(path + ":" + std::to_string(line.line_number) + ": '" +
                    std::string(line.tokens[i]) + "' is not a number");
      }
    }
    lines.push_back(std::move(parsed));
  }
  return lines;
}

}  // namespace io
}  // namespace covox

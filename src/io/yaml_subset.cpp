#include "covoxslam/io/yaml_subset.h"

#include <fstream>
#include <map>
#include <sstream>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {

namespace {

class Parser {
 public:
  explicit Parser(std::string name) : name_(std::move(name)) { document_.name = name_; }

  void line(const std::string& raw, int number) {
    number_ = number;
    const std::string text = without_comment(raw);
    const size_t indent = text.find_first_not_of(' ');
    if (indent == std::string::npos || trim(text).empty()) return;
    if (text[indent] == '\t') fail("a tab in the indentation (spaces only)");
    if (indent == 0 && trim(text) == "---" && !seen_entry_) return;
    place(indent);
    entry(trim(text));
    seen_entry_ = true;
  }

  YamlDocument finish() {
    if (open_section_) fail_at(open_line_, "'" + open_key_ + "' has no value and no entries");
    return std::move(document_);
  }

 private:
  struct Level {
    size_t indent;
    std::string prefix;  // the section's path followed by '.', empty at the top
  };

  [[noreturn]] void fail(const std::string& problem) const { fail_at(number_, problem); }
  [[noreturn]] void fail_at(int number, const std::string& problem) const {
    throw Error(name_ + ":" + std::to_string(number) + ": " + problem);
  }

  static std::string trim(const std::string& text) {
    const size_t first = text.find_first_not_of(" \t\r");
    if (first == std::string::npos) return std::string();
    const size_t last = text.find_last_not_of(" \t\r");
    return text.substr(first, last - first + 1);
  }

  // The line without its comment: a '#' at the start or after a blank, outside quotes.
  static std::string without_comment(const std::string& raw) {
    char quote = 0;
    for (size_t i = 0; i < raw.size(); ++i) {
      const char c = raw[i];
      if (quote) {
        if (c == quote) quote = 0;
      } else if (c == '"' || c == '\'') {
        quote = c;
      } else if (c == '#' && (i == 0 || raw[i - 1] == ' ' || raw[i - 1] == '\t')) {
        return raw.substr(0, i);
      }
    }
    return raw;
  }

  // Makes the level with this indentation the current one (a new section's first entry opens
  // its level; a smaller indentation closes sections down to the one it matches).
  void place(size_t indent) {
    if (open_section_) {
      if (indent <= levels_.back().indent) {
        fail_at(open_line_, "'" + open_key_ + "' has no value and no entries");
      }
      levels_.push_back(Level{indent, open_prefix_});
      open_section_ = false;
      return;
    }
    while (indent < levels_.back().indent) levels_.pop_back();
    if (indent != levels_.back().indent) {
      fail("the indentation matches no open section (" + std::to_string(indent) + " spaces)");
    }
  }

  void entry(const std::string& text) {
    if (text[0] == '-') fail("lists ('- item') are not supported: one `key: value` a line");
    const size_t colon = text.find(':');
    if (colon == std::string::npos || (colon + 1 < text.size() && text[colon + 1] != ' ')) {
      fail("expected `key: value` or `key:` opening a section, got '" + text + "'");
    }
    const std::string key = trim(text.substr(0, colon));
    check_key(key);
    const std::string path = levels_.back().prefix + key;
    const auto [previous, added] = lines_.emplace(path, number_);
    if (!added) {
      fail("'" + path + "' is given twice (first on line " + std::to_string(previous->second) +
           ")");
    }
    const std::string value = trim(text.substr(colon + 1));
    if (value.empty()) {
      open_section_ = true;
      open_key_ = path;
      open_prefix_ = path + ".";
      open_line_ = number_;
      return;
    }
    document_.entries.push_back(YamlEntry{path, scalar(path, value), number_});
  }

  void check_key(const std::string& key) const {
    if (key.empty()) fail("a key is empty");
    for (const char c : key) {
      const bool plain = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                         (c >= '0' && c <= '9') || c == '_' || c == '-';
      if (!plain) fail("key '" + key + "': only letters, digits, '_' and '-' are supported");
    }
  }

  std::string scalar(const std::string& key, const std::string& value) const {
    const char first = value[0];
    if (first == '"' || first == '\'') return quoted(key, value);
    if (first == '[') return flow_list(key, value);
    if (first == '{') fail("'" + key + "': flow mappings ({...}) are not supported");
    if (first == '&' || first == '*' || first == '!' || first == '|' || first == '>' ||
        first == '%' || first == '@' || first == '`') {
      fail("'" + key + "': anchors, aliases, tags and block scalars are not supported");
    }
    return value;
  }

  std::string quoted(const std::string& key, const std::string& value) const {
    const char quote = value[0];
    const size_t end = value.find(quote, 1);
    if (end == std::string::npos) fail("'" + key + "': the quoted value is not closed");
    if (end + 1 != value.size()) fail("'" + key + "': text after the closing quote");
    const std::string inner = value.substr(1, end - 1);
    if (quote == '"' && inner.find('\\') != std::string::npos) {
      fail("'" + key + "': escapes in double quotes are not supported");
    }
    return inner;
  }

  std::string flow_list(const std::string& key, const std::string& value) const {
    if (value.back() != ']') fail("'" + key + "': the list is not closed by ']' on its line");
    const std::string inner = value.substr(1, value.size() - 2);
    if (inner.find_first_of("[]{}\"'") != std::string::npos) {
      fail("'" + key + "': a list holds plain scalars only");
    }
    return value;
  }

  std::string name_;
  int number_ = 0;
  bool seen_entry_ = false;
  std::vector<Level> levels_{Level{0, std::string()}};
  bool open_section_ = false;
  std::string open_key_, open_prefix_;
  int open_line_ = 0;
  std::map<std::string, int> lines_;  // every key path (sections too) -> its line
  YamlDocument document_;
};

}  // namespace

std::string YamlDocument::where(const YamlEntry& entry) const {
  return name + ":" + std::to_string(entry.line);
}

YamlDocument parse_yaml_subset(const std::string& text, const std::string& name) {
  Parser parser(name);
  std::istringstream stream(text);
  std::string line;
  for (int number = 1; std::getline(stream, line); ++number) parser.line(line, number);
  return parser.finish();
}

YamlDocument read_yaml_subset(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw Error("cannot open configuration file '" + path + "'");
  std::stringstream text;
  text << file.rdbuf();
  if (file.bad()) throw Error("cannot read configuration file '" + path + "'");
  return parse_yaml_subset(text.str(), path);
}

}  // namespace io
}  // namespace covox

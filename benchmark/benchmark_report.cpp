#include "benchmark/benchmark_report.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <system_error>
#include <thread>
#include <utility>

#include "covoxslam/core/error.h"
#include "covoxslam/io/file_bytes.h"

namespace covox {
namespace tools {
namespace {

// Columns are measured in characters, not bytes, so "µs" or "m³" do not shift the table.
size_t display_width(const std::string& text) {
  size_t width = 0;
  for (unsigned char c : text) {
    if ((c & 0xC0) != 0x80) ++width;  // count every byte that is not a UTF-8 continuation byte
  }
  return width;
}

std::string pad_right(const std::string& text, size_t width) {
  const size_t w = display_width(text);
  return w >= width ? text : text + std::string(width - w, ' ');
}

std::string pad_left(const std::string& text, size_t width) {
  const size_t w = display_width(text);
  return w >= width ? text : std::string(width - w, ' ') + text;
}

// Table values: integers as integers, otherwise enough digits to read a ratio off the table.
std::string table_number(double value) {
  if (!std::isfinite(value)) return std::isnan(value) ? "nan" : (value > 0 ? "inf" : "-inf");
  char text[64];
  const double magnitude = std::fabs(value);
  if (value == std::trunc(value) && magnitude < 1e15) {
    std::snprintf(text, sizeof(text), "%.0f", value);
  } else if (magnitude >= 100.0) {
    std::snprintf(text, sizeof(text), "%.1f", value);
  } else if (magnitude >= 1.0) {
    std::snprintf(text, sizeof(text), "%.3f", value);
  } else {
    std::snprintf(text, sizeof(text), "%.4g", value);
  }
  return text;
}

bool needs_shell_quoting(const std::string& argument) {
  if (argument.empty()) return true;
  for (unsigned char c : argument) {
    const bool plain = std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '/' ||
                       c == '=' || c == ',' || c == ':' || c == '+' || c == '@' || c == '%';
    if (!plain) return true;
  }
  return false;
}

}  // namespace

std::string json_string(const std::string& text) {
  std::string out;
  out.reserve(text.size() + 2);
  out += '"';
  for (unsigned char c : text) {
    switch (c) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\b':
        out += "\\b";
        break;
      case '\f':
        out += "\\f";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\r':
        out += "\\r";
        break;
      case '\t':
        out += "\\t";
        break;
      default:
        if (c < 0x20) {
          char escaped[8];
          std::snprintf(escaped, sizeof(escaped), "\\u%04x", static_cast<unsigned>(c));
          out += escaped;
        } else {
          out += static_cast<char>(c);
        }
    }
  }
  out += '"';
  return out;
}

std::string json_number(double value) {
  if (!std::isfinite(value)) return "null";
  if (value == 0.0) return "0";  // also turns -0 into 0
  // The fewest significant digits that read back bit-exactly (at most 17 for a double).
  char text[64];
  for (int precision = 1; precision <= 17; ++precision) {
    std::snprintf(text, sizeof(text), "%.*g", precision, value);
    if (std::strtod(text, nullptr) == value) break;
  }
  // printf follows the C locale: never let a decimal comma into JSON.
  std::string out(text);
  std::replace(out.begin(), out.end(), ',', '.');
  return out;
}

std::string command_line(int argc, const char* const* argv) {
  std::string out;
  for (int i = 0; i < argc; ++i) {
    if (argv[i] == nullptr) break;
    const std::string argument = argv[i];
    if (!out.empty()) out += ' ';
    if (!needs_shell_quoting(argument)) {
      out += argument;
      continue;
    }
    out += '\'';
    for (char c : argument) {
      if (c == '\'') {
        out += "'\\''";  // close the quote, an escaped quote, reopen
      } else {
        out += c;
      }
    }
    out += '\'';
  }
  return out;
}

std::string iso8601_utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text;
}

BenchmarkReport::BenchmarkReport(std::string benchmark, std::string device, int argc,
                                 const char* const* argv)
    : BenchmarkReport(std::move(benchmark), std::move(device), command_line(argc, argv)) {}

BenchmarkReport::BenchmarkReport(std::string benchmark, std::string device, std::string command,
                                 std::string date)
    : benchmark_(std::move(benchmark)),
      device_(std::move(device)),
      command_(std::move(command)),
      date_(date.empty() ? iso8601_utc_now() : std::move(date)) {
  if (benchmark_.empty()) throw Error("BenchmarkReport: the benchmark name must not be empty");
}

void BenchmarkReport::add(const std::string& case_name, const std::string& metric, double value,
                          const std::string& unit) {
  rows_.push_back(BenchmarkRow{case_name, metric, value, unit});
}

std::string BenchmarkReport::default_json_path() const {
  if (device_.rfind("cpu", 0) == 0) {
    return "docs/benchmarks/" + benchmark_ + "_cpu_" +
           std::to_string(std::thread::hardware_concurrency()) + "core.json";
  }
  return "docs/benchmarks/" + benchmark_ + ".json";
}

std::string BenchmarkReport::table() const {
  const std::string headers[4] = {"case", "metric", "value", "unit"};
  std::vector<std::string> values;
  values.reserve(rows_.size());
  size_t width[4];
  for (int c = 0; c < 4; ++c) width[c] = display_width(headers[c]);
  for (const BenchmarkRow& row : rows_) {
    values.push_back(table_number(row.value));
    width[0] = std::max(width[0], display_width(row.case_name));
    width[1] = std::max(width[1], display_width(row.metric));
    width[2] = std::max(width[2], display_width(values.back()));
    width[3] = std::max(width[3], display_width(row.unit));
  }
  auto line = [&](const std::string& c0, const std::string& c1, const std::string& c2,
                  const std::string& c3) {
    std::string text = pad_right(c0, width[0]) + "  " + pad_right(c1, width[1]) + "  " +
                       pad_left(c2, width[2]) + "  " + c3;
    while (!text.empty() && text.back() == ' ') text.pop_back();
    return text + "\n";
  };
  std::string out = line(headers[0], headers[1], headers[2], headers[3]);
  out += std::string(width[0], '-') + "  " + std::string(width[1], '-') + "  " +
         std::string(width[2], '-') + "  " + std::string(width[3], '-') + "\n";
  for (size_t i = 0; i < rows_.size(); ++i) {
    out += line(rows_[i].case_name, rows_[i].metric, values[i], rows_[i].unit);
  }
  return out;
}

void BenchmarkReport::print_table(std::ostream& out) const {
  out << benchmark_ << " on " << device_ << " (" << date_ << ")\n" << table();
  out.flush();
}

std::string BenchmarkReport::to_json() const {
  std::string out = "{\n";
  out += "  \"benchmark\": " + json_string(benchmark_) + ",\n";
  out += "  \"device\": " + json_string(device_) + ",\n";
  out += "  \"date\": " + json_string(date_) + ",\n";
  out += "  \"command\": " + json_string(command_) + ",\n";
  out += "  \"results\": [";
  for (size_t i = 0; i < rows_.size(); ++i) {
    const BenchmarkRow& row = rows_[i];
    out += i == 0 ? "\n" : ",\n";
    out += "    {\"case\": " + json_string(row.case_name) +
           ", \"metric\": " + json_string(row.metric) + ", \"value\": " + json_number(row.value) +
           ", \"unit\": " + json_string(row.unit) + "}";
  }
  out += rows_.empty() ? "]\n" : "\n  ]\n";
  out += "}\n";
  return out;
}

void BenchmarkReport::write_json(const std::string& path) const {
  namespace fs = std::filesystem;
  const fs::path target = path.empty() ? fs::path(default_json_path()) : fs::path(path);
  auto fail = [&](const std::string& why) -> void {
    throw Error("BenchmarkReport: cannot write " + target.string() + ": " + why);
  };
  if (target.filename().empty()) fail("the path names a folder, not a file");
  std::error_code error;
  if (target.has_parent_path()) {
    fs::create_directories(target.parent_path(), error);
    if (error) fail("cannot create its folder (" + error.message() + ")");
  }
  // Through a temporary in the same folder and a rename (io::write_file_replacing), so a reader
  // never sees half a report.
  const std::string text = to_json();
  io::write_file_replacing(target.string(), "BenchmarkReport", /*binary=*/true,
                           [&](std::ostream& file) {
                             file.write(text.data(), static_cast<std::streamsize>(text.size()));
                           });
}

}  // namespace tools
}  // namespace covox

#pragma once
// The one way every benchmark in tools/ reports its figures: rows of (case, metric, value, unit),
// printed as an aligned plain-text table and written as JSON together with the device, the date
// and the exact command line, so that every figure in docs/performance.md can be traced back to
// a run and repeated (tools/scripts/performance_tables.py builds its tables from the JSON).
//
//   tools::BenchmarkReport report("hash_table", describe_device(device), argc, argv);
//   report.add("cuda lf=0.70", "find", 1234.5, "Mkeys/s");
//   report.print_table(std::cout);
//   report.write_json(options.output);  // "" -> docs/benchmarks/hash_table.json
#include <ostream>
#include <string>
#include <vector>

namespace covox {
namespace tools {

struct BenchmarkRow {
  std::string case_name;  // what was measured, e.g. "cuda lf=0.70" (JSON key "case")
  std::string metric;     // e.g. "find"
  double value = 0.0;
  std::string unit;  // e.g. "Mkeys/s", "ms"
};

class BenchmarkReport {
 public:
  // `benchmark` names the benchmark (also the default JSON file name), `device` says what it ran
  // on (the caller's words, e.g. describe_device()), argv is recorded as the command line.
  BenchmarkReport(std::string benchmark, std::string device, int argc, const char* const* argv);
  // Same with an explicit command line and date (tests, re-recorded runs). An empty date means
  // now.
  BenchmarkReport(std::string benchmark, std::string device, std::string command,
                  std::string date = std::string());

  void add(const std::string& case_name, const std::string& metric, double value,
           const std::string& unit);

  const std::string& benchmark() const { return benchmark_; }
  const std::string& device() const { return device_; }
  const std::string& command() const { return command_; }
  const std::string& date() const { return date_; }
  const std::vector<BenchmarkRow>& rows() const { return rows_; }

  // docs/benchmarks/<benchmark>.json, relative to the working directory (the repository root
  // when run as `build/benchmark_<name>` from there); docs/benchmarks/<benchmark>_cpu_<N>core.json
  // for a CPU-only report on an N-core machine, so that a CPU run never overwrites the GPU table.
  std::string default_json_path() const;

  // The aligned table: header, a rule, one line per row; the value column is right-aligned.
  std::string table() const;
  void print_table(std::ostream& out) const;

  // The JSON document, one result per line so that recorded files diff well:
  //   {
  //     "benchmark": "hash_table",
  //     "device": "...",
  //     "date": "2026-11-22T17:04:33Z",
  //     "command": "build/benchmark_hash_table --keys 2000000",
  //     "results": [
  //       {"case": "...", "metric": "...", "value": 1234.5, "unit": "Mkeys/s"}
  //     ]
  //   }
  // A value that is not finite (NaN, infinity) is written as null: JSON has no number for it.
  std::string to_json() const;
  // Writes to_json() to `path` (empty: default_json_path()), creating missing folders. The file
  // is written next to its final name and renamed over it, so a reader never sees half a file.
  // Throws covox::Error naming the path when it cannot be written.
  void write_json(const std::string& path = std::string()) const;

 private:
  std::string benchmark_;
  std::string device_;
  std::string command_;
  std::string date_;
  std::vector<BenchmarkRow> rows_;
};

// `"text"` with quotes, backslashes and control characters escaped (RFC 8259); bytes >= 0x80 pass
// through unchanged, so UTF-8 stays UTF-8.
std::string json_string(const std::string& text);
// The shortest decimal that reads back as exactly `value`; "null" when it is not finite.
std::string json_number(double value);
// argv joined by spaces; an argument with characters a shell would interpret is single-quoted,
// so the recorded command can be pasted back into a shell.
std::string command_line(int argc, const char* const* argv);
// The current UTC time as ISO 8601, e.g. "2026-11-22T17:04:33Z".
std::string iso8601_utc_now();

}  // namespace tools
}  // namespace covox

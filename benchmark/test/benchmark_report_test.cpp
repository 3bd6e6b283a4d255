// The benchmark results format: what every tools/benchmark_* writes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include "benchmark/benchmark_report.h"
#include "cli/command_line.h"

namespace covox {
namespace tools {
namespace {

TEST(BenchmarkReport, JsonHasTheAgreedShapeAndExactValues) {
  BenchmarkReport report("hash_table", "NVIDIA H100", "build/benchmark_hash_table --keys 10",
                         "2026-11-22T10:00:00Z");
  report.add("cuda load 0.85", "insert", 1234.5, "Mkeys/s");
  report.add("cpu \"quoted\"", "find", 0.1, "ms");
  const std::string json = report.to_json();
  EXPECT_NE(json.find("\"benchmark\": \"hash_table\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"device\": \"NVIDIA H100\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"date\": \"2026-11-22T10:00:00Z\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"command\": \"build/benchmark_hash_table --keys 10\""), std::string::npos)
      << json;
  EXPECT_NE(json.find("{\"case\": \"cuda load 0.85\", \"metric\": \"insert\", \"value\": 1234.5, "
                      "\"unit\": \"Mkeys/s\"}"),
            std::string::npos)
      << json;
  EXPECT_NE(json.find("\"cpu \\\"quoted\\\"\""), std::string::npos) << json;
}

TEST(BenchmarkReport, NumbersReadBackBitExactly) {
  for (double value : {0.1, 1.0 / 3.0, 1e-300, 123456789.125, -2.5e17}) {
    EXPECT_EQ(std::strtod(json_number(value).c_str(), nullptr), value) << json_number(value);
  }
  EXPECT_EQ(json_number(0.1), "0.1");
  EXPECT_EQ(json_number(std::numeric_limits<double>::quiet_NaN()), "null");
}

TEST(BenchmarkReport, CommandLineCanBePastedBackIntoAShell) {
  const char* argv[] = {"build/benchmark_tsdf", "--data", "/data with space", "it's"};
  EXPECT_EQ(command_line(4, argv), "build/benchmark_tsdf --data '/data with space' 'it'\\''s'");
}

TEST(BenchmarkReport, TableAlignsTheValueColumn) {
  BenchmarkReport report("t", "cpu", "cmd", "2026-01-01T00:00:00Z");
  report.add("a", "m", 1.0, "ms");
  report.add("longer case", "metric", 12345.678, "ms");
  std::istringstream lines(report.table());
  std::string line;
  std::vector<size_t> unit_columns;
  while (std::getline(lines, line)) {
    const size_t unit = line.rfind("ms");
    if (unit != std::string::npos) unit_columns.push_back(unit);
  }
  ASSERT_EQ(unit_columns.size(), 2u) << report.table();
  EXPECT_EQ(unit_columns[0], unit_columns[1]) << report.table();
}

TEST(BenchmarkReport, CpuOnlyReportsDefaultToTheirOwnFile) {
  EXPECT_EQ(BenchmarkReport("tsdf", "cuda:0 NVIDIA H100; cpu (16 OpenMP threads)", "c")
                .default_json_path(),
            "docs/benchmarks/tsdf.json");
  const std::string cpu =
      BenchmarkReport("tsdf", "cpu (2 OpenMP threads)", "c").default_json_path();
  EXPECT_EQ(cpu.rfind("docs/benchmarks/tsdf_cpu_", 0), 0u) << cpu;
  EXPECT_EQ(cpu.substr(cpu.size() - 9), "core.json") << cpu;
}

TEST(BenchmarkReport, WriteJsonCreatesFoldersAndReplacesTheFile) {
  const std::filesystem::path folder =
      std::filesystem::temp_directory_path() / "covox_report_test" / "nested";
  std::filesystem::remove_all(folder.parent_path());
  const std::string path = (folder / "x.json").string();
  BenchmarkReport first("x", "cpu", "cmd", "2026-01-01T00:00:00Z");
  first.add("c", "m", 1.0, "u");
  first.write_json(path);
  BenchmarkReport second("x", "cpu", "cmd", "2026-01-01T00:00:00Z");
  second.add("c", "m", 2.0, "u");
  second.write_json(path);
  std::ifstream in(path);
  std::stringstream content;
  content << in.rdbuf();
  EXPECT_EQ(content.str(), second.to_json());
  std::filesystem::remove_all(folder.parent_path());
}

TEST(CommandLine, ReadsOptionsAndRejectsUnknownOnes) {
  const char* argv[] = {"tool", "--keys", "42", "--fast", "--lf", "0.5,0.7"};
  CommandLine args(6, argv, "usage: tool");
  EXPECT_EQ(args.integer("--keys", 1), 42);
  EXPECT_TRUE(args.flag("--fast"));
  EXPECT_EQ(args.numbers("--lf", {}), (std::vector<double>{0.5, 0.7}));
  EXPECT_EQ(args.text("--missing", "default"), "default");
  args.finish();
  const char* bad[] = {"tool", "--typo", "1"};
  EXPECT_EXIT(CommandLine(3, bad, "usage: tool").finish(), ::testing::ExitedWithCode(2),
              "unknown option '--typo'");
  const char* not_a_number[] = {"tool", "--keys", "many"};
  EXPECT_EXIT(CommandLine(3, not_a_number, "usage: tool").integer("--keys", 1),
              ::testing::ExitedWithCode(2), "--keys takes an integer in");
}

}  // namespace
}  // namespace tools
}  // namespace covox

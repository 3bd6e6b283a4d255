// The YAML subset of the configuration files: what it reads (nested mappings, comments, quotes,
// flow lists of scalars) against entries written out by hand, and that everything else is refused
// with the file and line of the offending entry.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/io/yaml_subset.h"

namespace covox {
namespace io {
namespace {

TEST(YamlSubset, ReadsNestedMappingsCommentsQuotesAndFlowLists) {
  const std::string text =
      "---\n"
      "# a whole-line comment\n"
      "device: auto   # a trailing comment\n"
      "\n"
      "registration:\n"
      "  enabled: true\n"
      "  gate:\n"
      "      max_residual_vox: 2.0\n"
      "      worst_fraction: 0.7 #\n"
      "  mode: 'pairwise'\n"
      "ros:\n"
      "  base_frame: \"imu # not a comment\"\n"
      "  label: a#b\n"
      "  T_base_sensor: [0.0, 0.0, 0.1, 0, 0, 0, 1]\n"
      "solver:\n"
      "   max_iterations: 100\n";
  const YamlDocument document = parse_yaml_subset(text, "memory.yaml");
  const std::vector<YamlEntry> expected = {
      {"device", "auto", 3},
      {"registration.enabled", "true", 6},
      {"registration.gate.max_residual_vox", "2.0", 8},
      {"registration.gate.worst_fraction", "0.7", 9},
      {"registration.mode", "pairwise", 10},
      {"ros.base_frame", "imu # not a comment", 12},
      {"ros.label", "a#b", 13},
      {"ros.T_base_sensor", "[0.0, 0.0, 0.1, 0, 0, 0, 1]", 14},
      {"solver.max_iterations", "100", 16},
  };
  ASSERT_EQ(document.entries.size(), expected.size());
  for (size_t k = 0; k < expected.size(); ++k) {
    EXPECT_EQ(document.entries[k].key, expected[k].key) << k;
    EXPECT_EQ(document.entries[k].value, expected[k].value) << k;
    EXPECT_EQ(document.entries[k].line, expected[k].line) << k;
  }
  EXPECT_EQ(document.where(document.entries[2]), "memory.yaml:8");
}

// The error for `text` must start with "test.yaml:<line>: " and contain `words`.
void expect_refused(const std::string& text, int line, const std::string& words) {
  try {
    parse_yaml_subset(text, "test.yaml");
    ADD_FAILURE() << "accepted:\n" << text;
  } catch (const Error& error) {
    const std::string message = error.what();
    EXPECT_EQ(message.rfind("test.yaml:" + std::to_string(line) + ": ", 0), 0u) << message;
    EXPECT_NE(message.find(words), std::string::npos) << message;
  }
}

TEST(YamlSubset, RefusesWhatItDoesNotReadWithFileAndLine) {
  expect_refused("a:\n  - 1\n  - 2\n", 2, "lists");
  expect_refused("a:\n\tb: 1\n", 2, "tab");
  expect_refused("a: 1\nb: 2\na: 3\n", 3, "'a' is given twice (first on line 1)");
  expect_refused("s:\n  a: 1\ns:\n  b: 2\n", 3, "'s' is given twice");
  expect_refused("s:\n  a: 1\n  a: 2\n", 3, "'s.a' is given twice");
  expect_refused("a:\nb: 1\n", 1, "'a' has no value");
  expect_refused("x: 1\na:\n", 2, "'a' has no value");
  expect_refused("s:\n    a: 1\n  b: 2\n", 3, "indentation");
  expect_refused("  a: 1\n", 1, "indentation");
  expect_refused("a: {b: 1}\n", 1, "flow mappings");
  expect_refused("a: &anchor 1\n", 1, "anchors");
  expect_refused("a: |\n  text\n", 1, "block scalars");
  expect_refused("a: \"open\n", 1, "not closed");
  expect_refused("a: 'x' y\n", 1, "after the closing quote");
  expect_refused("a: \"x\\ty\"\n", 1, "escapes");
  expect_refused("a: [1, [2]]\n", 1, "plain scalars");
  expect_refused("a: [1, 2\n", 1, "not closed");
  expect_refused("just text\n", 1, "expected `key: value`");
  expect_refused("a:b\n", 1, "expected `key: value`");
  expect_refused("\"a\": 1\n", 1, "only letters");
}

TEST(YamlSubset, ReadsAFileAndNamesAMissingOne) {
  const std::string path = ::testing::TempDir() + "/yaml_subset_test.yaml";
  {
    FILE* file = std::fopen(path.c_str(), "w");
    ASSERT_NE(file, nullptr);
    std::fputs("map:\n  voxel_size_m: 0.1\n", file);
    std::fclose(file);
  }
  const YamlDocument document = read_yaml_subset(path);
  ASSERT_EQ(document.entries.size(), 1u);
  EXPECT_EQ(document.where(document.entries[0]), path + ":2");
  std::remove(path.c_str());
  EXPECT_THROW(read_yaml_subset(path), Error);
}

}  // namespace
}  // namespace io
}  // namespace covox

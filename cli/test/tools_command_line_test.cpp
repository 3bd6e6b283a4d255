// The tools' option parser (cli/command_line.h) and the value parsing it shares with the
// configuration files and the node (io/setting_values.h): each kind of bad value is refused with
// the option's name and the accepted range, and a seeded fuzz over random values, long numbers,
// NaN, repeated options and random bytes - through the parser and through the YAML reader -
// finds no crash and no silent acceptance: every accepted value equals what strtod / strtoll
// read from the same text, and every text outside the number grammar is refused with a message.
#include <gtest/gtest.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/setting_values.h"
#include "covoxslam/io/yaml_subset.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "covoxslam/pipeline/slam_parameters.h"
#include "support/error_message.h"
#include "support/scratch_folder.h"

namespace covox {
namespace tools {
namespace {

// A CommandLine over `arguments` (after the program name) that throws instead of exiting.
CommandLine parse(const std::vector<std::string>& arguments) {
  std::vector<const char*> argv = {"tool"};
  for (const std::string& argument : arguments) argv.push_back(argument.c_str());
  return CommandLine(static_cast<int>(argv.size()), argv.data(), "usage: tool",
                     CommandLine::OnFailure::kThrow);
}

using testing_support::error_message_of;

void expect_refused(const std::vector<std::string>& arguments,
                    const std::function<void(CommandLine&)>& read,
                    const std::vector<std::string>& words) {
  CommandLine args = parse(arguments);
  const std::string message = error_message_of([&] { read(args); });
  ASSERT_FALSE(message.empty()) << "accepted: " << ::testing::PrintToString(arguments);
  for (const std::string& word : words)
    EXPECT_NE(message.find(word), std::string::npos) << "'" << word << "' not in: " << message;
}

TEST(ToolsCommandLine, OverflowNanGarbageAndRepeatsAreRefusedByName) {
  auto columns = [](CommandLine& a) { a.positive_integer("--columns", 256, 8192); };
  expect_refused({"--columns", "99999999999"}, columns, {"--columns", "[1, 8192]", "99999999999"});
  expect_refused({"--columns", "12x"}, columns, {"--columns", "12x"});
  expect_refused({"--columns", " 12"}, columns, {"--columns"});
  expect_refused({"--columns", "0"}, columns, {"--columns", "[1, 8192]"});
  expect_refused({"--columns", "1e3"}, columns, {"--columns"});
  auto voxel = [](CommandLine& a) { a.number("--voxel-size-m", std::nan(""), 0.005, 10.0); };
  expect_refused({"--voxel-size-m", "nan"}, voxel, {"--voxel-size-m", "finite", "nan"});
  expect_refused({"--voxel-size-m", "inf"}, voxel, {"--voxel-size-m"});
  expect_refused({"--voxel-size-m", "1e999"}, voxel, {"--voxel-size-m", "range"});
  expect_refused({"--voxel-size-m", "0x1p-3"}, voxel, {"--voxel-size-m"});
  expect_refused({"--voxel-size-m", "0.2m"}, voxel, {"--voxel-size-m", "0.2m"});
  expect_refused({"--voxel-size-m", "0.001"}, voxel, {"--voxel-size-m", "[0.005, 10]", "0.001"});
  expect_refused({"--voxel-size-m", "0.2", "--voxel-size-m", "0.3"}, voxel,
                 {"--voxel-size-m", "given twice"});
  expect_refused({"--quiet", "--quiet"}, [](CommandLine& a) { a.flag("--quiet"); },
                 {"--quiet", "given twice"});
  expect_refused({"--mesh", "--trajectory", "t.tum"}, [](CommandLine& a) { a.text("--mesh", ""); },
                 {"--mesh", "--trajectory"});
  expect_refused({"--load", "0.5,,0.7"}, [](CommandLine& a) { a.numbers("--load", {}, 0.0, 1.0); },
                 {"--load"});
  expect_refused({"--load", "0.5,1.5"}, [](CommandLine& a) { a.numbers("--load", {}, 0.0, 1.0); },
                 {"--load", "[0, 1]", "1.5"});
  expect_refused({"--bogus", "1"}, [](CommandLine& a) { a.finish(); },
                 {"unknown option '--bogus'"});

  CommandLine good = parse({"--columns", "+64", "--voxel-size-m", "1e-1", "--load", "0.5,.7"});
  EXPECT_EQ(good.positive_integer("--columns", 256, 8192), 64);
  EXPECT_EQ(good.number("--voxel-size-m", 0.2, 0.005, 10.0), 0.1);
  EXPECT_EQ(good.numbers("--load", {}, 0.0, 1.0), (std::vector<double>{0.5, 0.7}));
  EXPECT_NO_THROW(good.finish());
}

TEST(ToolsCommandLine, OutputFilesAreCheckedWhenRead) {
  ScratchFolder scratch;
  auto mesh = [](CommandLine& a) { a.output_file("--mesh", ""); };
  const std::string missing = scratch.file("no/such/folder/mesh.ply");
  expect_refused({"--mesh", missing}, mesh, {"--mesh", missing, "No such file"});
  expect_refused({"--mesh", scratch.path().string()}, mesh, {"--mesh", "is a folder"});
  CommandLine good = parse({"--mesh", scratch.file("mesh.ply")});
  EXPECT_EQ(good.output_file("--mesh", ""), scratch.file("mesh.ply"));
  EXPECT_TRUE(std::filesystem::is_empty(scratch.path())) << "the probe left a file behind";
}

// The configuration files read by run_slam: a quoted number and an exponent are numbers, and a bad
// value is named with its file and line (the node's rostest checks the same files and message).
TEST(ToolsConfigurationFiles, QuotedAndExponentNumbersReadAsInTheNode) {
  ScratchFolder scratch;
  std::ofstream(scratch.file("good.yaml"))
      << "map:\n  voxel_size_m: \"0.25\"\ntsdf:\n  truncation_distance_m: 75e-2\n";
  std::ofstream(scratch.file("bad.yaml")) << "map:\n  voxel_size_m: 0.2x\n";
  pipeline::SlamConfig config;
  pipeline::load_slam_config(scratch.file("good.yaml"), &config);
  EXPECT_EQ(config.map.voxel_size_m, 0.25f);
  EXPECT_EQ(config.tsdf.truncation_distance_m, 0.75f);
  EXPECT_EQ(
      error_message_of([&] { pipeline::load_slam_config(scratch.file("bad.yaml"), &config); }),
      scratch.file("bad.yaml") +
          ":2: parameter 'map.voxel_size_m': expected a finite decimal number, got '0.2x'");
}

// ---- Fuzz ----

// Independent references: the grammar as a regular expression, the value as the C library reads
// it.
const std::regex kNumberGrammar("[+-]?([0-9]+\\.?[0-9]*|\\.[0-9]+)([eE][+-]?[0-9]+)?");
const std::regex kIntegerGrammar("[+-]?[0-9]+");

class Fuzz {
 public:
  explicit Fuzz(uint64_t seed) : random_(seed) {}
  size_t below(size_t n) { return static_cast<size_t>(random_() % n); }
  std::string digits(size_t count) {
    std::string text;
    for (size_t i = 0; i < count; ++i) text += static_cast<char>('0' + below(10));
    return text;
  }
  std::string bytes(size_t count) {
    std::string text;
    for (size_t i = 0; i < count; ++i) text += static_cast<char>(below(256));
    return text;
  }
  // A number-like text: well-formed most of the time, otherwise with a defect, or noise.
  std::string number_text() {
    static const char* const kSpecial[] = {
        "nan",   "NaN", "inf", "-inf", "1e",  "e5",   ".",     "-",      "+",      "",  "1,5",
        "0x1p3", " 1",  "1 ",  "1e+",  "--1", "1..2", "1e999", "-1e999", "1e-999", "١", "1\n"};
    switch (below(8)) {
      case 0:
        return kSpecial[below(sizeof(kSpecial) / sizeof(kSpecial[0]))];
      case 1:
        return bytes(1 + below(12));
      case 2:
        return digits(1 + below(400));  // long numbers
      case 3: {
        char text[64];
        std::snprintf(text, sizeof(text), "%.17g", std::ldexp(double(random_()), -int(below(80))));
        return text;
      }
      default: {
        std::string text = below(3) == 0 ? (below(2) ? "-" : "+") : "";
        text += digits(below(6));
        if (below(2)) text += "." + digits(below(6));
        if (below(3) == 0)
          text += (below(2) ? "e" : "E") + std::string(below(2) ? "-" : "") + digits(below(4));
        if (below(6) == 0) text.insert(below(text.size() + 1), 1, "x, #'\"e."[below(8)]);
        return text;
      }
    }
  }

 private:
  std::mt19937_64 random_;
};

TEST(ToolsCommandLineFuzz, NumbersAreReadExactlyOrRefusedWithAMessage) {
  Fuzz fuzz(0xC0FFEE);
  int accepted = 0, refused = 0;
  for (int i = 0; i < 4000; ++i) {
    const std::string text = fuzz.number_text();
    const bool grammatical = std::regex_match(text, kNumberGrammar);
    errno = 0;
    char* end = nullptr;
    const double reference = std::strtod(text.c_str(), &end);
    const bool in_range = errno != ERANGE && std::isfinite(reference);
    CommandLine args = parse({"--value-m", text});
    double value = 0.0;
    const std::string message = error_message_of([&] { value = args.number("--value-m", -1.0); });
    if (message.empty()) {
      ++accepted;
      ASSERT_TRUE(grammatical) << "accepted '" << text << "'";
      ASSERT_EQ(value, reference) << "'" << text << "' read as " << value;
    } else {
      ++refused;
      ASSERT_NE(message.find("--value-m"), std::string::npos) << message;
      ASSERT_FALSE(grammatical && in_range && text.size() < 300) << "refused '" << text << "'";
    }
  }
  EXPECT_GT(accepted, 1000);
  EXPECT_GT(refused, 500);
}

TEST(ToolsCommandLineFuzz, IntegersAreReadExactlyOrRefusedWithTheRange) {
  Fuzz fuzz(0xBEEF);
  for (int i = 0; i < 4000; ++i) {
    const std::string text = fuzz.number_text();
    errno = 0;
    const long long reference = std::strtoll(text.c_str(), nullptr, 10);
    const bool exact = std::regex_match(text, kIntegerGrammar) && errno != ERANGE;
    const int64_t maximum = 1 + static_cast<int64_t>(fuzz.below(100000));
    CommandLine args = parse({"--count", text});
    int64_t value = 0;
    const std::string message =
        error_message_of([&] { value = args.integer("--count", 1, 0, maximum); });
    if (message.empty()) {
      ASSERT_TRUE(exact) << "accepted '" << text << "'";
      ASSERT_EQ(value, reference);
      ASSERT_LE(value, maximum);
    } else {
      ASSERT_NE(message.find("--count"), std::string::npos) << message;
      ASSERT_FALSE(exact && reference >= 0 && reference <= maximum) << "refused '" << text << "'";
      if (exact) {
        ASSERT_NE(message.find("in [0, " + std::to_string(maximum) + "]"), std::string::npos)
            << message;
      }
    }
  }
}

TEST(ToolsCommandLineFuzz, RandomArgumentListsEndInAValueOrAMessage) {
  Fuzz fuzz(7);
  const std::vector<std::string> names = {"--a", "--b", "--flag", "--c"};
  for (int i = 0; i < 3000; ++i) {
    std::vector<std::string> arguments;
    std::map<std::string, int> given;
    for (size_t k = fuzz.below(7); k > 0; --k) {
      const std::string name = names[fuzz.below(names.size())];
      arguments.push_back(fuzz.below(10) == 0 ? fuzz.bytes(3) : name);
      ++given[arguments.back()];
      if (name != "--flag" && fuzz.below(8) != 0) arguments.push_back(fuzz.number_text());
    }
    CommandLine args = parse(arguments);
    const std::string message = error_message_of([&] {
      args.number("--a", 0.0);
      args.integer("--b", 0);
      args.flag("--flag");
      args.text("--c", "");
      args.finish();
    });
    for (const std::string& name : names) {
      if (given[name] > 1) {
        ASSERT_FALSE(message.empty()) << name << " given twice was accepted";
      }
    }
  }
}

// Configuration files: random documents from YAML-like pieces and random bytes. A document the
// reader accepts gives back, for every number written with 17 digits, exactly that number.
TEST(ToolsCommandLineFuzz, TheYamlReaderReadsBackWhatWasWrittenOrRefusesWithALine) {
  Fuzz fuzz(42);
  const std::vector<std::string> keys = {"voxel_size_m", "a", "b-c", "x_1", "map", "ros"};
  int documents_read = 0;
  for (int i = 0; i < 3000; ++i) {
    std::string text;
    std::map<std::string, double> written;
    bool plain = true;  // only unique top-level `key: number` lines
    for (size_t line = fuzz.below(8); line > 0; --line) {
      const std::string key = keys[fuzz.below(keys.size())];
      switch (fuzz.below(6)) {
        case 0:
          text += fuzz.bytes(1 + fuzz.below(20)) + "\n";
          plain = false;
          break;
        case 1:
          text += "  " + key + ": " + fuzz.number_text() + "\n";
          plain = false;
          break;
        case 2:
          text += key + ": \"" + fuzz.number_text() + "\" # note\n";
          plain = false;
          break;
        default: {
          const double value = std::ldexp(double(fuzz.below(1u << 30)), -int(fuzz.below(40))) *
                               (fuzz.below(2) ? 1 : -1);
          char number[64];
          std::snprintf(number, sizeof(number), "%.17g", value);
          if (written.count(key)) plain = false;
          written[key] = value;
          text += key + ": " + number + "\n";
        }
      }
    }
    io::YamlDocument document;
    const std::string message =
        error_message_of([&] { document = io::parse_yaml_subset(text, "fuzz.yaml"); });
    if (!message.empty()) {
      ASSERT_EQ(message.rfind("fuzz.yaml", 0), 0u) << message;
      ASSERT_FALSE(plain) << "refused a plain document:\n" << text << message;
      continue;
    }
    ++documents_read;
    std::map<std::string, std::string> values;
    for (const io::YamlEntry& entry : document.entries) values[entry.key] = entry.value;
    const pipeline::TextParameterSource source(values);
    for (const io::YamlEntry& entry : document.entries) {
      double value = 0.0;
      const std::string problem = error_message_of([&] { source.get_number(entry.key, &value); });
      if (!problem.empty()) {
        ASSERT_NE(problem.find(entry.key), std::string::npos) << problem;
        continue;
      }
      ASSERT_TRUE(std::regex_match(entry.value, kNumberGrammar)) << entry.value;
      ASSERT_EQ(value, std::strtod(entry.value.c_str(), nullptr)) << entry.value;
    }
    if (plain) {
      for (const auto& [key, value] : written) {
        double read = 0.0;
        ASSERT_TRUE(source.get_number(key, &read)) << key;
        ASSERT_EQ(read, value) << text;
      }
    }
  }
  EXPECT_GT(documents_read, 500);
}

}  // namespace
}  // namespace tools
}  // namespace covox

// covox::parse_double: whole-token, locale-independent parsing of the text formats' numbers,
// checked against the compiler's own reading of the same literals and against printf's
// shortest round-trip text of random doubles.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>

#include "covoxslam/core/number_text.h"

namespace covox {
namespace {

double parsed(const std::string& token) {
  double value = -12345.0;
  EXPECT_TRUE(parse_double(token, &value)) << "'" << token << "'";
  return value;
}

TEST(NumberText, ReadsDecimalAndExponentNotationExactly) {
  EXPECT_EQ(parsed("0.1"), 0.1);
  EXPECT_EQ(parsed("-2.5e-3"), -2.5e-3);
  EXPECT_EQ(parsed("+7"), 7.0);
  EXPECT_EQ(parsed("1E10"), 1e10);
  EXPECT_EQ(parsed(".5"), 0.5);
  EXPECT_EQ(parsed("1.7976931348623157e308"), std::numeric_limits<double>::max());
  EXPECT_EQ(parsed("4.9406564584124654e-324"), std::numeric_limits<double>::denorm_min());
  EXPECT_TRUE(std::isnan(parsed("nan")));
  EXPECT_EQ(parsed("-inf"), -std::numeric_limits<double>::infinity());
  EXPECT_EQ(parsed("Infinity"), std::numeric_limits<double>::infinity());
}

TEST(NumberText, RoundTripsPrintfsShortestExactText) {
  std::mt19937_64 random(7);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-300, 300);
  for (int i = 0; i < 2000; ++i) {
    const double value = std::ldexp(mantissa(random), exponent(random));
    char text[64];
    std::snprintf(text, sizeof(text), "%.17g", value);
    ASSERT_EQ(parsed(text), value) << text;
  }
}

TEST(NumberText, ReadsTokensLongerThanTheStackCopy) {
  const std::string token = "0." + std::string(100, '0') + "1";
  EXPECT_EQ(parsed(token), 1e-101);
}

TEST(NumberText, RefusesWhatIsNotExactlyOneNumber) {
  for (const char* token :
       {"", " 1", "1 ", "1,5", "0x1p3", "1.5e", "++1", "abc", "1e400", "-1e400", "1.0.0", "nan1"}) {
    double value = 3.0;
    EXPECT_FALSE(parse_double(token, &value)) << "'" << token << "'";
    EXPECT_EQ(value, 3.0) << "'" << token << "' changed the output on failure";
  }
}

TEST(NumberText, ReadsOnlyTheViewNotTheCharactersAfterIt) {
  const std::string line = "2.5 3.75";
  double value = 0.0;
  ASSERT_TRUE(parse_double(std::string_view(line).substr(0, 3), &value));
  EXPECT_EQ(value, 2.5);
}

TEST(NumberText, FormatsTheShortestTextThatReadsBack) {
  EXPECT_EQ(format_double(0.1), "0.1");
  EXPECT_EQ(format_double(100.0), "100");
  EXPECT_EQ(format_double(1e6), "1e+06");
  EXPECT_EQ(format_double(-2.5e-7), "-2.5e-07");
  EXPECT_EQ(format_double(std::numeric_limits<double>::infinity()), "inf");
  std::mt19937_64 random(11);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0);
  for (int i = 0; i < 500; ++i) {
    const double value = std::ldexp(mantissa(random), i % 200 - 100);
    double back = 0.0;
    ASSERT_TRUE(parse_double(format_double(value), &back));
    EXPECT_EQ(back, value) << format_double(value);
  }
}

}  // namespace
}  // namespace covox

#pragma once
// Strict reading of one setting's text - a command-line option's value, a configuration file's
// scalar, a ROS parameter - shared by the offline tools and the node, so a value is read the same
// way wherever it is written. The whole text must be the value: no leading or trailing spaces or
// characters, no hexadecimal, no NaN or infinity, nothing that overflows. Each function returns
// an empty string when the text is a value, else what is wrong with it (without the setting's
// name, which the caller adds).
#include <cstdint>
#include <string>
#include <string_view>

namespace covox {
namespace io {

// A finite decimal number: an optional sign, digits with an optional '.' (at least one digit on
// either side), an optional exponent (e/E, optional sign, digits). Read locale-independently.
std::string parse_number_value(std::string_view text, double* value);
// A decimal integer (optional sign, digits) within int64_t.
std::string parse_integer_value(std::string_view text, int64_t* value);
// "true" or "false".
std::string parse_bool_value(std::string_view text, bool* value);

// A number for messages, shortest form that reads back the same ("0.1", "1e+06").
std::string format_setting_number(double value);

}  // namespace io
}  // namespace covox

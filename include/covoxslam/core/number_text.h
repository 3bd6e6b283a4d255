#pragma once
// Locale-independent parsing of a floating-point token, for every text format the library reads
// (pose files, g2o graphs, intrinsics, ASCII PCD and PLY).
//
// strtod reads "0,5" under a German LC_NUMERIC that a ROS node may have set, and GCC 9's
// libstdc++ (Ubuntu 20.04, JetPack 5) has no floating-point std::from_chars. The parser hands a
// null-terminated copy of the token to strtod_l with the "C" locale, which has neither problem.
#include <string>
#include <string_view>

namespace covox {

// Parses the whole token as a double: decimal or exponent notation, "nan", "inf", "infinity"
// (any case), an optional sign ('+' included). False on anything else: an empty token, leading
// white space, hexadecimal floats, trailing characters, and magnitudes beyond double's range
// (e.g. 1e400); values below its smallest normal magnitude are read as strtod rounds them.
bool parse_double(std::string_view token, double* value);

// The shortest text that parse_double reads back as `value` ("0.1", "100", "1e+06", "nan"), in
// printf's %g forms with a '.' whatever the locale (GCC 9 has no floating-point std::to_chars).
std::string format_double(double value);

}  // namespace covox

#pragma once
// Whole-file reads with errors that name the file: every reader starts here, so a missing or
// unreadable file always gives the same clear covox::Error.
#include <cstdint>
#include <string>
#include <vector>

namespace covox {
namespace io {

std::vector<uint8_t> read_file_bytes(const std::string& path);
std::string read_text_file(const std::string& path);

}  // namespace io
}  // namespace covox

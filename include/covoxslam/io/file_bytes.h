#pragma once
// Whole-file reads and writes with errors that name the file: every reader and writer starts
// here, so a missing, unreadable or unwritable file always gives the same clear covox::Error.
#include <cstdint>
#include <functional>
#include <ostream>
#include <string>
#include <vector>

namespace covox {
namespace io {

std::vector<uint8_t> read_file_bytes(const std::string& path);
std::string read_text_file(const std::string& path);

// Writes a whole file through `write`, so that a reader never sees half of it: an AtomicFile
// (io/atomic_file.h) in the folder of `path`, created exclusively under a random name without
// following links, then renamed over `path`. A path that exists and is not a regular file
// (/dev/null, a FIFO) is written in place instead: renaming over it would replace the device or
// pipe with a plain file. `what` starts the error messages (the writer's name); a failed write,
// or an exception thrown by `write`, removes the temporary and leaves an existing `path` as it
// was.
void write_file_replacing(const std::string& path, const std::string& what, bool binary,
                          const std::function<void(std::ostream&)>& write);

}  // namespace io
}  // namespace covox

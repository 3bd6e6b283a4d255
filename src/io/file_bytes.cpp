#include "covoxslam/io/file_bytes.h"

#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "covoxslam/core/error.h"
#include "covoxslam/io/atomic_file.h"

namespace covox {
namespace io {
namespace {

// Reads in chunks rather than trusting a size from seek/tell, so pipes and files that change
// size while being read still give exactly what was read. A folder is refused by name (read()
// on it fails with EISDIR, fopen() would not).
template <class Container>
Container read_all(const std::string& path) {
  const FileDescriptor file(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (!file.valid()) throw Error("cannot open '" + path + "': " + std::strerror(errno));
  struct stat status {};
  if (::fstat(file.get(), &status) == 0 && S_ISDIR(status.st_mode))
    throw Error("cannot read '" + path + "': it is a folder, not a file");
  Container contents;
  char chunk[1 << 16];
  for (;;) {
    const ssize_t got = ::read(file.get(), chunk, sizeof(chunk));
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) throw Error("error while reading '" + path + "': " + std::strerror(errno));
    if (got == 0) break;
    contents.insert(contents.end(), chunk, chunk + got);
  }
  return contents;
}

}  // namespace

std::vector<uint8_t> read_file_bytes(const std::string& path) {
  return read_all<std::vector<uint8_t>>(path);
}

std::string read_text_file(const std::string& path) { return read_all<std::string>(path); }

void write_file_replacing(const std::string& path, const std::string& what, bool binary,
                          const std::function<void(std::ostream&)>& write) {
  (void)binary;  // POSIX streams do not translate line ends
  WriteTarget target;
  try {
    target = write_target_for_path(path);
  } catch (const Error& error) {
    throw Error(what + ": " + error.what());
  }
  write_file(target, what, write);
}

}  // namespace io
}  // namespace covox

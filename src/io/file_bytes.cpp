#include "covoxslam/io/file_bytes.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>

#include <sys/stat.h>
#include <unistd.h>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace {

struct FileCloser {
  void operator()(std::FILE* file) const { std::fclose(file); }
};

// Reads in chunks rather than trusting a size from seek/tell, so pipes and files that change
// size while being read still give exactly what was read.
template <class Container>
Container read_all(const std::string& path) {
  std::unique_ptr<std::FILE, FileCloser> file(std::fopen(path.c_str(), "rb"));
  if (!file) throw Error("cannot open '" + path + "': " + std::strerror(errno));
  Container contents;
  char chunk[1 << 16];
  size_t got = 0;
  while ((got = std::fread(chunk, 1, sizeof(chunk), file.get())) > 0) {
    contents.insert(contents.end(), chunk, chunk + got);
  }
  if (std::ferror(file.get()))
    throw Error("error while reading '" + path + "': " + std::strerror(errno));
  return contents;
}

}  // namespace

std::vector<uint8_t> read_file_bytes(const std::string& path) {
  return read_all<std::vector<uint8_t>>(path);
}

std::string read_text_file(const std::string& path) { return read_all<std::string>(path); }

namespace {

// Opens `target`, hands it to `write` and flushes; throws naming `target` when any step fails.
// Returns with the stream closed; on failure `target` may hold part of the output.
void write_stream(const std::string& target, std::ios::openmode mode, const std::string& what,
                  const std::function<void(std::ostream&)>& write) {
  std::ofstream file(target, mode);
  if (!file)
    throw Error(what + ": cannot open " + target + " for writing: " + std::strerror(errno));
  write(file);
  file.flush();
  if (!file) throw Error(what + ": writing " + target + " failed (disk full?)");
}

}  // namespace

void write_file_replacing(const std::string& path, const std::string& what, bool binary,
                          const std::function<void(std::ostream&)>& write) {
  const std::ios::openmode mode =
      std::ios::trunc | std::ios::out | (binary ? std::ios::binary : std::ios::openmode{});
  struct stat status {};
  if (::stat(path.c_str(), &status) == 0 && !S_ISREG(status.st_mode)) {
    write_stream(path, mode, what, write);  // a device or pipe: nothing to replace
    return;
  }
  const std::string temporary = path + ".tmp." + std::to_string(::getpid());
  try {
    write_stream(temporary, mode, what, write);
  } catch (...) {  // a failed write or the writer's own error: no half-written temporary left
    std::remove(temporary.c_str());
    throw;
  }
  if (std::rename(temporary.c_str(), path.c_str()) != 0) {
    const std::string reason = std::strerror(errno);
    std::remove(temporary.c_str());
    throw Error(what + ": cannot move " + temporary + " to " + path + ": " + reason);
  }
}

}  // namespace io
}  // namespace covox

#include "covoxslam/io/file_bytes.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

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
  if (std::ferror(file.get())) throw Error("error while reading '" + path + "': " + std::strerror(errno));
  return contents;
}

}  // namespace

std::vector<uint8_t> read_file_bytes(const std::string& path) { return read_all<std::vector<uint8_t>>(path); }

std::string read_text_file(const std::string& path) { return read_all<std::string>(path); }

}  // namespace io
}  // namespace covox

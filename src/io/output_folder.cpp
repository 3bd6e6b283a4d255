#include "covoxslam/io/output_folder.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <utility>
#include <vector>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace {

// Longer names are refused before any file system call (PATH_MAX on Linux).
constexpr size_t kMaxNameLength = 4096;

std::vector<std::string> components(const std::string& name) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (;;) {
    const size_t slash = name.find('/', start);
    parts.push_back(name.substr(start, slash == std::string::npos ? slash : slash - start));
    if (slash == std::string::npos) return parts;
    start = slash + 1;
  }
}

std::string character_problem(const std::string& name) {
  for (const char c : name) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte < 0x20 || byte == 0x7f) return "contains a control character";
  }
  return std::string();
}

// Characters after which a refused name is cut in messages.
constexpr size_t kShownNameLength = 200;

// `name` for a message: control characters as \xNN (a refusal must not write raw bytes into the
// caller's log), cut after kShownNameLength characters.
std::string printable_name(const std::string& name) {
  std::string shown;
  for (size_t i = 0; i < name.size() && i < kShownNameLength; ++i) {
    const auto byte = static_cast<unsigned char>(name[i]);
    if (byte < 0x20 || byte == 0x7f) {
      char escaped[8];
      std::snprintf(escaped, sizeof(escaped), "\\x%02x", byte);
      shown += escaped;
    } else {
      shown += name[i];
    }
  }
  if (name.size() > kShownNameLength) shown += "...";
  return shown;
}

}  // namespace

std::string relative_name_problem(const std::string& name) {
  if (name.empty()) return "is empty";
  if (name.size() > kMaxNameLength)
    return "is longer than " + std::to_string(kMaxNameLength) + " characters";
  const std::string characters = character_problem(name);
  if (!characters.empty()) return characters;
  if (name.front() == '/') return "is an absolute path";
  for (const std::string& part : components(name)) {
    if (part == "..") return "contains '..'";
    if (part == ".") return "contains '.' as a component";
    if (part.empty()) return "has an empty component ('//' or a trailing '/')";
  }
  return std::string();
}

OutputFolder::OutputFolder(const std::string& path, std::string label)
    : path_(path), label_(std::move(label)) {
  if (path.empty()) throw Error(label_ + " is empty: give the folder for the files");
  std::error_code error;
  std::filesystem::create_directories(path, error);
  if (error) throw Error(label_ + ": cannot create '" + path + "': " + error.message());
  const int fd = ::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) {
    throw Error(label_ + ": cannot open the folder '" + path + "': " + std::strerror(errno));
  }
  folder_ = std::make_shared<const FileDescriptor>(fd);
}

std::string OutputFolder::display(const std::string& name) const {
  return path_ + (!path_.empty() && path_.back() == '/' ? "" : "/") + name;
}

void OutputFolder::refuse(const std::string& name, const std::string& why) const {
  throw Error("refused: '" + printable_name(name) + "' " + why + "; give a name relative to " +
              label_ + " (" + path_ + ")");
}

OutputFolder::Resolved OutputFolder::resolve(const std::string& name) const {
  const std::string problem = relative_name_problem(name);
  if (!problem.empty()) refuse(name, problem);
  std::vector<std::string> parts = components(name);
  Resolved resolved{folder_, parts.back()};
  parts.pop_back();
  std::string walked;
  for (const std::string& part : parts) {
    walked += (walked.empty() ? "" : "/") + part;
    const int fd = ::openat(resolved.parent->get(), part.c_str(),
                            O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0) {
      const int error = errno;
      if (error == ELOOP || error == ENOTDIR)
        refuse(name, "passes through '" + walked + "', a symbolic link or not a folder");
      if (error == ENOENT) refuse(name, "needs the folder '" + walked + "', which does not exist");
      refuse(name, "cannot open the folder '" + walked + "': " + std::strerror(error));
    }
    resolved.parent = std::make_shared<const FileDescriptor>(fd);
  }
  return resolved;
}

WriteTarget OutputFolder::target(const std::string& name, bool overwrite) const {
  Resolved resolved = resolve(name);
  struct stat status {};
  if (::fstatat(resolved.parent->get(), resolved.leaf.c_str(), &status, AT_SYMLINK_NOFOLLOW) == 0) {
    if (S_ISLNK(status.st_mode)) refuse(name, "is a symbolic link");
    if (!S_ISREG(status.st_mode))
      refuse(name, "is not a regular file (a folder, device, FIFO or socket)");
    if (!overwrite) refuse(name, "exists and overwrite was not asked for");
  }
  WriteTarget target;
  target.folder = std::move(resolved.parent);
  target.name = std::move(resolved.leaf);
  target.display = display(name);
  target.overwrite = overwrite;
  return target;
}

FileDescriptor OutputFolder::open_for_reading(const std::string& name) const {
  const Resolved resolved = resolve(name);
  // O_NONBLOCK: a FIFO under the name must not hang the caller before it is refused.
  FileDescriptor file(::openat(resolved.parent->get(), resolved.leaf.c_str(),
                               O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC));
  if (!file.valid()) {
    const int error = errno;
    if (error == ELOOP) refuse(name, "is a symbolic link");
    if (error == ENOENT) refuse(name, "does not exist");
    refuse(name, std::string("cannot be opened: ") + std::strerror(error));
  }
  struct stat status {};
  if (::fstat(file.get(), &status) != 0 || !S_ISREG(status.st_mode))
    refuse(name, "is not a regular file (a folder, device, FIFO or socket)");
  ::fcntl(file.get(), F_SETFL, ::fcntl(file.get(), F_GETFL) & ~O_NONBLOCK);
  return file;
}

}  // namespace io
}  // namespace covox

#include "covoxslam/io/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <ext/stdio_filebuf.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <random>
#include <utility>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace {

// Temporary names are drawn until one is free; a clash means someone plants files there.
constexpr int kTemporaryNameAttempts = 64;
// The name part kept in a temporary's name, so that it stays under NAME_MAX (255).
constexpr size_t kTemporaryNamePrefix = 200;

// 64 bits from the system's random source (getrandom), drawn anew for every name so that one
// temporary's name tells nothing about the next.
std::string random_suffix() {
  std::random_device source;
  const unsigned long long bits =
      (static_cast<unsigned long long>(source()) << 32) ^ static_cast<unsigned long long>(source());
  char text[17];
  std::snprintf(text, sizeof(text), "%016llx", bits);
  return text;
}

std::string errno_text(int error) { return std::strerror(error); }

// Renames `from` onto `to` in `folder` unless `to` exists: renameat2(RENAME_NOREPLACE), or, on a
// file system without it, a hard link (which fails on an existing name) and an unlink.
int rename_no_replace(int folder, const std::string& from, const std::string& to) {
  if (::renameat2(folder, from.c_str(), folder, to.c_str(), RENAME_NOREPLACE) == 0) return 0;
  if (errno != EINVAL && errno != ENOSYS) return -1;
  if (::linkat(folder, from.c_str(), folder, to.c_str(), 0) != 0) return -1;
  ::unlinkat(folder, from.c_str(), 0);
  return 0;
}

}  // namespace

FileDescriptor::~FileDescriptor() {
  if (fd_ >= 0) ::close(fd_);
}

FileDescriptor& FileDescriptor::operator=(FileDescriptor&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = other.release();
  }
  return *this;
}

WriteTarget write_target_for_path(const std::string& path, bool overwrite) {
  if (path.empty()) throw Error("an output path is empty");
  const size_t slash = path.find_last_of('/');
  const std::string folder =
      slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
  WriteTarget target;
  target.name = slash == std::string::npos ? path : path.substr(slash + 1);
  target.display = path;
  target.overwrite = overwrite;
  struct stat status {};
  const bool exists = ::stat(path.c_str(), &status) == 0;
  if (exists && S_ISDIR(status.st_mode)) throw Error("'" + path + "' is a folder, not a file");
  if (target.name.empty() || target.name == "." || target.name == "..")
    throw Error("'" + path + "' names a folder, not a file");
  if (exists && !overwrite) throw Error("'" + path + "' exists and is not replaced");
  target.in_place = exists && !S_ISREG(status.st_mode);
  // Written through a link only when the link is root's or the user's own (/dev/stdout): one
  // planted by another user (a shared /tmp) must not point the write at a device.
  struct stat link {};
  if (target.in_place && ::lstat(path.c_str(), &link) == 0 && S_ISLNK(link.st_mode) &&
      link.st_uid != 0 && link.st_uid != ::geteuid()) {
    throw Error("'" + path + "' is another user's symbolic link to a device or FIFO; not written");
  }
  const int fd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) {
    throw Error("cannot write '" + path + "': its folder '" + folder +
                "' cannot be opened: " + errno_text(errno));
  }
  target.folder = std::make_shared<const FileDescriptor>(fd);
  return target;
}

void probe_output_path(const std::string& path) {
  WriteTarget target = write_target_for_path(path);
  if (target.in_place) {
    if (::access(path.c_str(), W_OK) != 0)
      throw Error("cannot write '" + path + "': " + errno_text(errno));
    return;
  }
  const AtomicFile probe(std::move(target), "cannot write");  // removed uncommitted
}

AtomicFile::AtomicFile(WriteTarget target, std::string what)
    : target_(std::move(target)), what_(std::move(what)) {
  if (target_.in_place) {
    file_ = FileDescriptor(::open(target_.display.c_str(), O_WRONLY | O_CLOEXEC));
    if (!file_.valid()) fail("cannot open for writing");
    return;
  }
  const int folder = target_.folder->get();
  if (!target_.overwrite &&
      ::faccessat(folder, target_.name.c_str(), F_OK, AT_SYMLINK_NOFOLLOW) == 0)
    throw Error(what_ + ": " + target_.display + " exists and overwriting was not asked for");
  for (int attempt = 0; attempt < kTemporaryNameAttempts; ++attempt) {
    temporary_ =
        "." + target_.name.substr(0, kTemporaryNamePrefix) + "." + random_suffix() + ".tmp";
    file_ = FileDescriptor(::openat(folder, temporary_.c_str(),
                                    O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644));
    if (file_.valid()) return;
    if (errno != EEXIST) break;
  }
  const int error = errno;
  temporary_.clear();
  errno = error;
  fail("cannot create a temporary file beside it");
}

AtomicFile::~AtomicFile() {
  if (!file_.valid()) return;
  ::close(file_.release());
  if (!temporary_.empty()) ::unlinkat(target_.folder->get(), temporary_.c_str(), 0);
}

void AtomicFile::fail(const std::string& problem) const {
  throw Error(what_ + ": " + target_.display + ": " + problem + ": " + errno_text(errno));
}

void AtomicFile::commit() {
  if (!file_.valid()) throw Error(what_ + ": " + target_.display + ": committed twice");
  if (target_.in_place) {
    if (::close(file_.release()) != 0) fail("close failed");
    return;
  }
  const int folder = target_.folder->get();
  auto remove_temporary = [&] {
    const int error = errno;
    ::unlinkat(folder, temporary_.c_str(), 0);
    errno = error;
  };
  if (::fsync(file_.get()) != 0) {
    const int error = errno;
    ::close(file_.release());
    errno = error;
    remove_temporary();
    fail("fsync failed");
  }
  if (::close(file_.release()) != 0) {
    remove_temporary();
    fail("close failed (disk full?)");
  }
  const int renamed = target_.overwrite
                          ? ::renameat(folder, temporary_.c_str(), folder, target_.name.c_str())
                          : rename_no_replace(folder, temporary_, target_.name);
  if (renamed != 0) {
    const bool appeared = errno == EEXIST;
    remove_temporary();
    if (appeared)
      throw Error(what_ + ": " + target_.display +
                  " appeared while writing and overwriting was not asked for");
    fail("cannot rename the temporary " + temporary_ + " onto it");
  }
}

void write_file(const WriteTarget& target, const std::string& what,
                const std::function<void(std::ostream&)>& write) {
  AtomicFile file(target, what);
  {
    // The stream writes through its own copy of the descriptor, closed with it.
    const int copy = ::dup(file.fd());
    if (copy < 0) file.fail("cannot duplicate the file descriptor");
    __gnu_cxx::stdio_filebuf<char> buffer(copy, std::ios::out | std::ios::binary, 1 << 16);
    std::ostream stream(&buffer);
    write(stream);
    stream.flush();
    if (!stream) throw Error(what + ": writing " + target.display + " failed (disk full?)");
  }
  file.commit();
}

}  // namespace io
}  // namespace covox

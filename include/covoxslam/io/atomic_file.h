#pragma once
// Files written whole or not at all, and never through a symbolic link. A WriteTarget is a name
// inside an open folder. AtomicFile creates a temporary beside it with a random name, exclusively
// and without following links (O_CREAT | O_EXCL | O_NOFOLLOW: a link planted under that name
// makes the creation fail and another name is drawn), and on commit() syncs it and renames it
// onto the name, which replaces a symbolic link there rather than writing its target. Without
// overwrite the rename refuses an existing name (renameat2 RENAME_NOREPLACE, or link + unlink
// where the file system lacks it), also one that appeared after the first check. A reader never
// sees half a file, and a failure (or no commit) leaves the name as it was.
#include <functional>
#include <memory>
#include <ostream>
#include <string>

namespace covox {
namespace io {

// An open file descriptor, closed when destroyed.
class FileDescriptor {
 public:
  FileDescriptor() = default;
  explicit FileDescriptor(int fd) : fd_(fd) {}
  ~FileDescriptor();
  FileDescriptor(FileDescriptor&& other) noexcept : fd_(other.release()) {}
  FileDescriptor& operator=(FileDescriptor&& other) noexcept;
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  int get() const { return fd_; }
  bool valid() const { return fd_ >= 0; }
  int release() {
    const int fd = fd_;
    fd_ = -1;
    return fd;
  }

 private:
  int fd_ = -1;
};

struct WriteTarget {
  std::shared_ptr<const FileDescriptor> folder;  // the folder, opened with O_DIRECTORY
  std::string name;                              // one path component inside it
  std::string display;                           // the whole path, for messages
  bool overwrite = true;  // false: an existing `name` is never replaced (checked at the rename)
  // An existing device or FIFO the operator named (--mesh /dev/null): written directly, as
  // renaming over it would replace the device with a plain file. Only write_target_for_path()
  // sets it; io/output_folder.h refuses such files.
  bool in_place = false;
};

// The target for a path the operator gave (a command line): the folder part is opened as a shell
// would (links in it are the operator's), the last component is replaced by a rename. An
// existing device or FIFO there is written in place, also through a link that root or the user
// owns (/dev/stdout), never through another user's link. Throws covox::Error naming the path when
// the folder cannot be opened, the path names a folder, or `overwrite` is false and it exists.
WriteTarget write_target_for_path(const std::string& path, bool overwrite = true);

// Checks now, before any work, that `path` can be written later: not a folder, its folder exists
// and takes a new file (a temporary is created there and removed), or an existing device or FIFO
// is writable. Throws covox::Error saying why not.
void probe_output_path(const std::string& path);

class AtomicFile {
 public:
  // Creates the temporary (or opens the device in place); `what` starts the error messages.
  AtomicFile(WriteTarget target, std::string what);
  // Uncommitted: closes and removes the temporary.
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  int fd() const { return file_.get(); }
  const std::string& display() const { return target_.display; }
  const std::string& temporary_name() const { return temporary_; }
  // Syncs, closes and renames the temporary onto the target's name.
  void commit();
  // "<what>: <display>: <problem>: <errno text>", with the errno of the failed call.
  [[noreturn]] void fail(const std::string& problem) const;

 private:
  WriteTarget target_;
  std::string what_;
  std::string temporary_;  // empty when writing in place
  FileDescriptor file_;
};

// Writes a whole file through `write` as an AtomicFile. `write` may throw; the target is then
// left as it was.
void write_file(const WriteTarget& target, const std::string& what,
                const std::function<void(std::ostream&)>& write);

}  // namespace io
}  // namespace covox

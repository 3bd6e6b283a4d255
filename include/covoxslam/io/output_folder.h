#pragma once
// One folder that file names from outside (the node's save/load services, which any client on
// the ROS network may call) cannot leave. A name is accepted only when it is relative and plain:
// no leading '/', no '..' or '.' component, no empty component ("a//b", a trailing '/'), no NUL
// or control character. Its folders are opened one by one below the folder with O_NOFOLLOW, so
// no symbolic link is followed on the way; the file itself must be a regular file or not exist
// (a link, a device, a FIFO, a socket or a folder under the name is refused). Writes go through
// AtomicFile (io/atomic_file.h): an existing file is replaced only when asked for.
#include <memory>
#include <string>

#include "covoxslam/io/atomic_file.h"

namespace covox {
namespace io {

// Every refusal is a covox::Error that says why and where names are taken from, e.g.
//   refused: 'a/../b' contains '..'; give a name relative to ~ros/output_dir (/root/.ros/covoxslam)
// A refused name is judged by its text or by what lies inside the folder, never by a lookup
// outside it, so a refusal does not tell whether some path outside exists.
class OutputFolder {
 public:
  // Creates `path` (and missing parents, mode 0755) and opens it. `label` names the setting it
  // comes from in refusals ("~ros/output_dir"). Throws covox::Error naming the path.
  OutputFolder(const std::string& path, std::string label);

  const std::string& path() const { return path_; }
  // `name` inside the folder, for messages.
  std::string display(const std::string& name) const;

  // Where `name` is to be written; refuses as the file comment says, and refuses an existing
  // file unless `overwrite`.
  WriteTarget target(const std::string& name, bool overwrite) const;
  // `name` opened for reading (a regular file, reached without following a link).
  FileDescriptor open_for_reading(const std::string& name) const;

 private:
  // The checked name's parent folder, opened, and its last component.
  struct Resolved {
    std::shared_ptr<const FileDescriptor> parent;
    std::string leaf;
  };
  Resolved resolve(const std::string& name) const;
  [[noreturn]] void refuse(const std::string& name, const std::string& why) const;

  std::string path_;
  std::string label_;
  std::shared_ptr<const FileDescriptor> folder_;
};

// Why `name` is not a plain relative name (empty when it is one); see OutputFolder.
std::string relative_name_problem(const std::string& name);

}  // namespace io
}  // namespace covox

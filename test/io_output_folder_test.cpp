// The confined folder of the node's file services (io/output_folder.h) and the atomic writer under
// every output (io/atomic_file.h): names that leave the folder, links planted at the target or
// at a temporary's name, devices and FIFOs, and existing files without overwrite are refused,
// and nothing outside the folder is written or revealed.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/io/atomic_file.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/output_folder.h"
#include "support/error_message.h"
#include "support/scratch_folder.h"

namespace covox {
namespace {

namespace fs = std::filesystem;

void write_text(const std::string& path, const std::string& text) {
  std::ofstream file(path, std::ios::trunc);
  file << text;
}

std::string read_text(const std::string& path) {
  std::ifstream file(path);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

using testing_support::error_message_of;

std::vector<std::string> entries(const fs::path& folder) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(folder))
    names.push_back(entry.path().filename().string());
  return names;
}

void write_to(const io::WriteTarget& target, const std::string& text) {
  io::write_file(target, "test", [&](std::ostream& out) { out << text; });
}

struct Folders {
  ScratchFolder scratch;
  fs::path inside = scratch.path() / "output";
  fs::path outside = scratch.path() / "outside";
  Folders() {
    fs::create_directories(outside);
    write_text((outside / "secret").string(), "secret");
  }
};

TEST(IoOutputFolder, NamesThatLeaveTheFolderAreRefusedByTheirText) {
  Folders folders;
  const io::OutputFolder folder(folders.inside.string(), "~ros/output_dir");
  ASSERT_TRUE(fs::is_directory(folders.inside)) << "the folder is created";
  const std::vector<std::pair<std::string, std::string>> refused = {
      {"", "is empty"},
      {"/etc/passwd", "absolute"},
      {(folders.outside / "x.bin").string(), "absolute"},
      {"..", "contains '..'"},
      {"../outside/x.bin", "contains '..'"},
      {"a/../b", "contains '..'"},
      {"./a.bin", "'.'"},
      {"a//b", "empty component"},
      {"a/", "empty component"},
      {std::string("a\nb"), "control character"},
      {std::string("a\0b", 3), "control character"},
      {std::string(5000, 'a'), "longer than"}};
  for (const auto& [name, why] : refused) {
    for (const bool overwrite : {false, true}) {
      const std::string message = error_message_of([&] { folder.target(name, overwrite); });
      EXPECT_NE(message.find("refused: '"), std::string::npos) << name << ": " << message;
      EXPECT_NE(message.find(why), std::string::npos) << name << ": " << message;
      EXPECT_NE(message.find("~ros/output_dir (" + folders.inside.string() + ")"),
                std::string::npos)
          << message;
    }
    EXPECT_NE(error_message_of([&] { folder.open_for_reading(name); }).find(why),
              std::string::npos);
  }
  EXPECT_EQ(error_message_of([&] { folder.target("a/../b", false); }),
            "refused: 'a/../b' contains '..'; give a name relative to ~ros/output_dir (" +
                folders.inside.string() + ")");
  EXPECT_NE(error_message_of([&] {
              folder.target(std::string("a\0b\n", 4), true);
            }).find("'a\\x00b\\x0a'"),
            std::string::npos)
      << "control characters are shown escaped";
  EXPECT_EQ(entries(folders.outside), std::vector<std::string>{"secret"});
  EXPECT_TRUE(entries(folders.inside).empty());
}

TEST(IoOutputFolder, WritesInsideAndOverwritesOnlyWhenAsked) {
  Folders folders;
  const io::OutputFolder folder(folders.inside.string(), "~ros/output_dir");
  write_to(folder.target("map.bin", false), "first");
  EXPECT_EQ(read_text((folders.inside / "map.bin").string()), "first");
  const std::string message = error_message_of([&] { folder.target("map.bin", false); });
  EXPECT_NE(message.find("exists and overwrite was not asked for"), std::string::npos) << message;
  EXPECT_EQ(read_text((folders.inside / "map.bin").string()), "first");
  write_to(folder.target("map.bin", true), "second");
  EXPECT_EQ(read_text((folders.inside / "map.bin").string()), "second");
  // Sub-folders that exist (no link among them) are fine; missing ones are named.
  fs::create_directories(folders.inside / "runs" / "a");
  write_to(folder.target("runs/a/mesh.ply", false), "mesh");
  EXPECT_EQ(read_text((folders.inside / "runs/a/mesh.ply").string()), "mesh");
  EXPECT_NE(error_message_of([&] { folder.target("runs/b/mesh.ply", false); }).find("'runs/b'"),
            std::string::npos);
  const io::FileDescriptor read = folder.open_for_reading("runs/a/mesh.ply");
  EXPECT_TRUE(read.valid());
  EXPECT_EQ(entries(folders.inside).size(), 2u) << "a temporary was left behind";
}

TEST(IoOutputFolder, SymbolicLinksAreNeverFollowed) {
  Folders folders;
  const io::OutputFolder folder(folders.inside.string(), "~ros/output_dir");
  const std::string secret = (folders.outside / "secret").string();
  // A link at the target's name.
  fs::create_symlink(secret, folders.inside / "link.bin");
  for (const bool overwrite : {false, true}) {
    EXPECT_NE(error_message_of([&] { folder.target("link.bin", overwrite); }).find("symbolic link"),
              std::string::npos);
  }
  EXPECT_NE(error_message_of([&] { folder.open_for_reading("link.bin"); }).find("symbolic link"),
            std::string::npos);
  // A link as a folder on the way: refused whether the file behind it exists or not, with the
  // same words, so a refusal does not tell what lies outside.
  fs::create_directory_symlink(folders.outside, folders.inside / "out");
  const std::string existing = error_message_of([&] { folder.open_for_reading("out/secret"); });
  const std::string missing = error_message_of([&] { folder.open_for_reading("out/missing"); });
  EXPECT_NE(existing.find("passes through 'out'"), std::string::npos) << existing;
  EXPECT_EQ(missing.substr(0, missing.find("out/")), existing.substr(0, existing.find("out/")));
  EXPECT_NE(
      error_message_of([&] { folder.target("out/new.bin", true); }).find("passes through 'out'"),
      std::string::npos);
  EXPECT_EQ(read_text(secret), "secret");
  EXPECT_EQ(entries(folders.outside), std::vector<std::string>{"secret"});
}

TEST(IoOutputFolder, DevicesAndFifosAreRefused) {
  Folders folders;
  const io::OutputFolder folder(folders.inside.string(), "~ros/output_dir");
  ASSERT_EQ(::mkfifo((folders.inside / "pipe").c_str(), 0600), 0);
  fs::create_directory(folders.inside / "dir");
  std::vector<std::string> names = {"pipe", "dir"};
  // A character device like /dev/null (1, 3) needs root to create; the FIFO stands in otherwise.
  if (::mknod((folders.inside / "null").c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0)
    names.push_back("null");
  for (const std::string& name : names) {
    for (const bool overwrite : {false, true}) {
      EXPECT_NE(
          error_message_of([&] { folder.target(name, overwrite); }).find("not a regular file"),
          std::string::npos)
          << name;
    }
    EXPECT_NE(error_message_of([&] { folder.open_for_reading(name); }).find("not a regular file"),
              std::string::npos)
        << name;
  }
  struct stat status {};
  ASSERT_EQ(::stat((folders.inside / "pipe").c_str(), &status), 0);
  EXPECT_TRUE(S_ISFIFO(status.st_mode));
}

TEST(IoAtomicFile, ALinkAtTheOldTemporaryNameOrTheTargetIsNotWrittenThrough) {
  Folders folders;
  const std::string secret = (folders.outside / "secret").string();
  const std::string path = (folders.inside / "out.txt").string();
  fs::create_directories(folders.inside);
  // The temporary name of earlier versions (<path>.tmp.<pid>), planted as a link.
  fs::create_symlink(secret, path + ".tmp." + std::to_string(::getpid()));
  io::write_file_replacing(path, "test", false, [](std::ostream& out) { out << "mine"; });
  EXPECT_EQ(read_text(secret), "secret");
  EXPECT_EQ(read_text(path), "mine");
  // A link at the target of an operator's path is replaced, its target is not written.
  const std::string linked = (folders.inside / "linked.txt").string();
  fs::create_symlink(secret, linked);
  io::write_file_replacing(linked, "test", false, [](std::ostream& out) { out << "new"; });
  EXPECT_EQ(read_text(secret), "secret");
  EXPECT_FALSE(fs::is_symlink(linked));
  EXPECT_EQ(read_text(linked), "new");
}

// An operator's path that is another user's link to a device or FIFO (planted in a shared
// folder) is not written through; the user's own link is (as /dev/stdout is root's).
TEST(IoAtomicFile, AnotherUsersLinkToADeviceIsNotWrittenThrough) {
  Folders folders;
  fs::create_directories(folders.inside);
  const std::string fifo = (folders.outside / "pipe").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0666), 0);
  // A reader first: a wrong open for writing returns at once instead of hanging.
  const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0);
  const std::string planted = (folders.inside / "planted.ply").string();
  fs::create_symlink(fifo, planted);
  if (::lchown(planted.c_str(), 65534, 65534) != 0) {
    ::close(reader);
    GTEST_SKIP() << "changing a link's owner needs root";
  }
  const std::string message = error_message_of([&] {
    io::write_file_replacing(planted, "test", false, [](std::ostream& out) { out << "data"; });
  });
  EXPECT_NE(message.find("another user's symbolic link"), std::string::npos) << message;
  char byte = 0;
  EXPECT_LE(::read(reader, &byte, 1), 0) << "written through the link";
  ::close(reader);
  EXPECT_TRUE(fs::is_symlink(planted));
}

TEST(IoAtomicFile, TemporariesAreFreshAndAFileThatAppearsIsNotReplaced) {
  Folders folders;
  const io::OutputFolder folder(folders.inside.string(), "~ros/output_dir");
  io::AtomicFile first(folder.target("a.bin", false), "test");
  io::AtomicFile second(folder.target("a.bin", false), "test");
  EXPECT_NE(first.temporary_name(), second.temporary_name());
  // O_EXCL: a name that exists cannot be the temporary.
  struct stat status {};
  ASSERT_EQ(::fstat(first.fd(), &status), 0);
  EXPECT_EQ(status.st_nlink, 1u);
  EXPECT_TRUE(S_ISREG(status.st_mode));
  ASSERT_EQ(::write(first.fd(), "late", 4), 4);
  // Someone else's file appears under the name while the temporary is written.
  write_text((folders.inside / "a.bin").string(), "theirs");
  const std::string message = error_message_of([&] { first.commit(); });
  EXPECT_NE(message.find("appeared while writing"), std::string::npos) << message;
  EXPECT_EQ(read_text((folders.inside / "a.bin").string()), "theirs");
  // With overwrite the rename replaces it.
  io::AtomicFile third(folder.target("a.bin", true), "test");
  ASSERT_EQ(::write(third.fd(), "ours", 4), 4);
  third.commit();
  EXPECT_EQ(read_text((folders.inside / "a.bin").string()), "ours");
}

TEST(IoAtomicFile, ReadingAFolderIsRefusedByName) {
  ScratchFolder scratch;
  const std::string message =
      error_message_of([&] { io::read_text_file(scratch.path().string()); });
  EXPECT_NE(message.find("is a folder"), std::string::npos) << message;
  EXPECT_NE(message.find(scratch.path().string()), std::string::npos) << message;
}

}  // namespace
}  // namespace covox

#include "covoxslam/io/data_directory.h"

#include <cstdlib>
#include <filesystem>

namespace covox {
namespace io {
namespace {

// The repository root as the compiler saw it: this file is <root>/src/io/data_directory.cpp and
// CMake hands the compiler absolute paths. Using it instead of the working directory lets tests
// find the data whether they are started from the repository, the build folder or by CTest.
std::filesystem::path repository_root_at_build_time() {
  return std::filesystem::path(__FILE__).parent_path().parent_path().parent_path();
}

}  // namespace

std::string data_directory() {
  const char* from_environment = std::getenv("COVOX_DATA_DIR");
  if (from_environment != nullptr && from_environment[0] != '\0') return from_environment;

  const std::filesystem::path root = repository_root_at_build_time();
  if (root.is_absolute()) return (root / ".." / "shared" / "data").lexically_normal().string();
  // A relative __FILE__ (unusual build setups): fall back to the documented relative default,
  // which is right when the program runs from the repository root.
  return "../shared/data";
}

}  // namespace io
}  // namespace covox

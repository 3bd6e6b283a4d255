#pragma once
// Where the shared real sensor data lives (the folder COVOX_DATA_DIR names; its README.md
// describes each dataset). The data is never copied into the repository, so tests, benchmarks
// and tools find it through one setting.
#include <string>

namespace covox {
namespace io {

// The folder named by the environment variable COVOX_DATA_DIR when it is set and not empty;
// otherwise the build's default, relative to the repository root this library was built from.
// The result may not exist: callers check (tests skip with a message naming the path).
std::string data_directory();

}  // namespace io
}  // namespace covox

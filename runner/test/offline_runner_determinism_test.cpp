// The offline runner is deterministic: one input mapped twice, with different OpenMP thread counts
// and queue sizes (so the threads hand over at different moments and, with one-entry queues,
// wait on each other all the time), gives byte-identical trajectories, and drops nothing. (The
// combined mesh holds the same triangles; their order follows the threads that extracted them.)
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace covox {
namespace {

namespace fs = std::filesystem;

std::string file_text(const fs::path& path) {
  std::ifstream file(path, std::ios::binary);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

// Runs run_slam on a simulated flight of 30 s (a small figure 8, 96 columns, 2 s submaps: 15
// submaps with registrations and optimisations) with `threads` OpenMP threads and the given
// queue sizes; returns the exit status, the log in `log`.
int map_flight(const fs::path& out, int threads, int sensor_queue, int submap_queue,
               std::string* log) {
  fs::create_directories(out);
  const fs::path program = fs::read_symlink("/proc/self/exe").parent_path() / "run_slam";
  const std::string command =
      "OMP_NUM_THREADS=" + std::to_string(threads) + " " + program.string() +
      " --simulate --duration-s 30 --lobe-half-length-m 12 --columns 96 --seed 4 --device cpu"
      " --quiet --submap-interval-s 2 --sensor-queue " +
      std::to_string(sensor_queue) + " --submap-queue " + std::to_string(submap_queue) +
      " --trajectory " + (out / "trajectory.tum").string() + " --mesh " +
      (out / "mesh.ply").string() + " > " + (out / "log.txt").string() + " 2>&1";
  const int raw = std::system(command.c_str());
  *log = file_text(out / "log.txt");
  return WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
}

TEST(OfflineRunnerDeterminism, ThreadCountAndQueueSizesDoNotChangeTheResult) {
  const fs::path program = fs::read_symlink("/proc/self/exe").parent_path() / "run_slam";
  if (!fs::exists(program)) GTEST_SKIP() << "run_slam is not built next to the tests";
  const fs::path folder =
      fs::temp_directory_path() / ("covoxslam_determinism_" + std::to_string(::getpid()));
  std::string log_a, log_b;
  ASSERT_EQ(map_flight(folder / "a", 1, 1, 1, &log_a), 0) << log_a;
  ASSERT_EQ(map_flight(folder / "b", 2, 20, 4, &log_b), 0) << log_b;
  for (const std::string* log : {&log_a, &log_b}) {
    EXPECT_NE(log->find(" 0 dropped by the pipeline"), std::string::npos) << *log;
    EXPECT_NE(log->find("submaps dropped 0"), std::string::npos) << *log;
  }
  const std::string trajectory = file_text(folder / "a" / "trajectory.tum");
  EXPECT_GT(trajectory.size(), 1000u);
  EXPECT_TRUE(trajectory == file_text(folder / "b" / "trajectory.tum"))
      << "the trajectories differ: " << (folder / "a").string() << " and "
      << (folder / "b").string();
  EXPECT_EQ(file_text(folder / "a" / "mesh.ply").size(),
            file_text(folder / "b" / "mesh.ply").size());
  if (::testing::Test::HasFailure()) return;  // the outputs stay for a look
  fs::remove_all(folder);
}

}  // namespace
}  // namespace covox

// Hash table insert / find / erase throughput at fixed load factors, and SoA vs AoS voxel lookup
// time, on every available device. Prints a table and writes docs/benchmarks/hash_table.json.
//
//   benchmark_hash_table [--keys 50000000] [--device all|cuda|cpu] [--repeats 3]
//                        [--load-factors 0.5,0.7,0.85] [--lookup-blocks 100000]
//                        [--output docs/benchmarks/hash_table.json]
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "benchmark/benchmark_datasets.h"
#include "benchmark/benchmark_report.h"
#include "benchmark/benchmark_run.h"
#include "cli/command_line.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/soa_container.h"
#include "covoxslam/map/block_hash_table.h"
#include "covoxslam/map/voxel_pool_ops.h"
#include "covoxslam/map/voxels.h"

namespace covox {
namespace {

struct Options {
  int64_t keys = 50000000;
  std::string device = "all";
  int repeats = 3;
  std::vector<double> load_factors = {0.5, 0.7, 0.85};
  int64_t lookup_blocks = 100000;
  int64_t lookups = 50000000;
  std::string output;  // empty: docs/benchmarks/hash_table.json
};

Options parse(int argc, char** argv) {
  tools::CommandLine args(
      argc, argv,
      "usage: benchmark_hash_table [--keys N] [--device all|cuda|cpu] [--repeats N]\n"
      "       [--load-factors 0.5,0.7,0.85] [--lookup-blocks N] [--lookups N]\n"
      "       [--output docs/benchmarks/hash_table.json]");
  Options options;
  options.keys = args.positive_integer("--keys", options.keys);
  options.device = args.text("--device", options.device);
  options.repeats = static_cast<int>(args.positive_integer("--repeats", options.repeats));
  options.load_factors = args.numbers("--load-factors", options.load_factors, 1e-6, 0.999999);
  options.lookup_blocks = args.integer("--lookup-blocks", options.lookup_blocks);
  options.lookups = args.integer("--lookups", options.lookups);
  options.output = args.output_file("--output", "");
  args.finish();
  for (double lf : options.load_factors) {
    if (!(lf > 0.0 && lf < 1.0)) args.fail("load factors must be in (0, 1)");
  }
  return options;
}

// `count` distinct block indices scattered over a 400^3 cube: i -> (i * 7919) mod 400^3 is a
// bijection (7919 is prime and does not divide 400^3), so no key repeats and neighbouring i land
// far apart.
std::vector<Index3D> distinct_keys(int64_t count) {
  constexpr int64_t kSide = 400, kCells = kSide * kSide * kSide;
  if (count > kCells) throw Error("benchmark_hash_table: at most 64000000 keys");
  std::vector<Index3D> keys(static_cast<size_t>(count));
#pragma omp parallel for
  for (int64_t i = 0; i < count; ++i) {
    const int64_t j = (i * 7919) % kCells;
    keys[i] = Index3D(static_cast<int32_t>(j % kSide) - 200,
                      static_cast<int32_t>((j / kSide) % kSide) - 200,
                      static_cast<int32_t>(j / (kSide * kSide)) - 200);
  }
  return keys;
}

// The median over `repeats` runs of function(repeat).
template <class Function>
double median_milliseconds(int repeats, const Stream& stream, Function&& function) {
  std::vector<double> times;
  for (int r = 0; r < repeats; ++r)
    times.push_back(tools::stream_milliseconds(stream, [&] { function(r); }));
  return tools::median_of(times);
}

void benchmark_table(Device device, const Options& options, const std::vector<Index3D>& host_keys,
                     tools::BenchmarkReport* report) {
  const Stream stream(device);
  auto keys = Buffer<Index3D>::from_host(device, host_keys);
  Buffer<uint32_t> slots(device, host_keys.size());
  const int64_t n = options.keys;
  for (double load_factor : options.load_factors) {
    const uint64_t buckets = static_cast<uint64_t>(static_cast<double>(n) / load_factor);
    map::BlockHashTable table(device, map::BlockHashTableConfig{buckets, 0.95, false});
    std::ostringstream name;
    name << to_string(device) << " load " << load_factor;
    bool all_ok = true;
    const double insert_ms = median_milliseconds(options.repeats, stream, [&](int) {
      table.clear();
      all_ok &= table.activate(keys.data(), n, slots.data(), nullptr, stream).ok();
    });
    if (!all_ok || table.size() != n) throw Error("benchmark_hash_table: inserts failed");
    int64_t found = 0;
    const double find_ms = median_milliseconds(options.repeats, stream, [&](int) {
      found = table.find(keys.data(), n, slots.data(), stream);
    });
    if (found != n) throw Error("benchmark_hash_table: find missed keys");
    // Each erase repeat needs a full table: re-fill outside the timed region.
    std::vector<double> erase_times;
    for (int r = 0; r < options.repeats; ++r) {
      table.clear();
      table.activate(keys.data(), n, slots.data(), nullptr, stream);
      erase_times.push_back(
          tools::stream_milliseconds(stream, [&] { table.erase(keys.data(), n, stream); }));
    }
    const double erase_ms = tools::median_of(erase_times);
    report->add(name.str(), "insert (activate)", n / (insert_ms * 1e3), "Mkeys/s");
    report->add(name.str(), "find", n / (find_ms * 1e3), "Mkeys/s");
    report->add(name.str(), "erase", n / (erase_ms * 1e3), "Mkeys/s");
    report->add(name.str(), "insert time", insert_ms, "ms");
    report->add(name.str(), "find time", find_ms, "ms");
    report->add(name.str(), "erase time", erase_ms, "ms");
  }
}

// Random voxel lookups reading only distance_m, for one voxel type in both layouts.
template <class Voxel>
void benchmark_layout(Device device, const Options& options, const std::string& voxel_name,
                      tools::BenchmarkReport* report) {
  constexpr int64_t kVoxelsPerBlock = 512;  // 8^3
  const int64_t voxel_count = options.lookup_blocks * kVoxelsPerBlock;
  const Stream stream(device);
  std::vector<uint32_t> random_queries(static_cast<size_t>(options.lookups));
  std::vector<uint32_t> block_queries(static_cast<size_t>(options.lookups));
  uint64_t state = 88172645463325252ull;
  for (int64_t i = 0; i < options.lookups; ++i) {
    state ^= state << 13, state ^= state >> 7, state ^= state << 17;  // xorshift64
    random_queries[i] = static_cast<uint32_t>(state % voxel_count);
  }
  // Block-coherent: whole blocks in voxel order, blocks in random order (a raycast or a mesh
  // pass reads neighbouring voxels together).
  for (int64_t i = 0; i < options.lookups; i += kVoxelsPerBlock) {
    state ^= state << 13, state ^= state >> 7, state ^= state << 17;
    const uint32_t block = static_cast<uint32_t>(state % options.lookup_blocks);
    for (int64_t v = 0; v < kVoxelsPerBlock && i + v < options.lookups; ++v) {
      block_queries[i + v] = static_cast<uint32_t>(block * kVoxelsPerBlock + v);
    }
  }
  auto random_device = Buffer<uint32_t>::from_host(device, random_queries);
  auto block_device = Buffer<uint32_t>::from_host(device, block_queries);
  Buffer<float> out(device, random_queries.size());

  auto measure = [&](auto& storage, const char* layout_name) {
    for (auto* queries : {&random_device, &block_device}) {
      const double ms = median_milliseconds(options.repeats, stream, [&](int) {
        dispatch(device, [&](auto backend) {
          map::gather_voxel_distances(backend, stream, storage.view(), queries->data(),
                                      options.lookups, out.data());
        });
      });
      const char* pattern = queries == &random_device ? "random voxels" : "block-coherent";
      report->add(
          std::string(to_string(device)) + " " + voxel_name + " " + layout_name + " " + pattern,
          "lookup time per voxel", ms * 1e6 / options.lookups, "ns");
    }
  };
  VoxelStorage<Voxel, Layout::kSoA> soa(device, static_cast<size_t>(voxel_count));
  measure(soa, "SoA");
  soa.resize(0);
  VoxelStorage<Voxel, Layout::kAoS> aos(device, static_cast<size_t>(voxel_count));
  measure(aos, "AoS");
}

}  // namespace
}  // namespace covox

int main(int argc, char** argv) {
  using namespace covox;
  const Options options = parse(argc, argv);
  return tools::run_benchmark("benchmark_hash_table", [&] {
    const std::vector<Device> devices = tools::benchmark_devices(options.device);
    tools::BenchmarkReport report("hash_table", tools::describe_devices(devices), argc, argv);
    std::cout << "generating " << options.keys << " distinct keys..." << std::endl;
    const auto keys = distinct_keys(options.keys);
    for (Device device : devices) {
      std::cout << "hash table on " << describe_device(device) << "..." << std::endl;
      benchmark_table(device, options, keys, &report);
      std::cout << "voxel layouts on " << describe_device(device) << "..." << std::endl;
      benchmark_layout<map::TsdfVoxel>(device, options, "TsdfVoxel(8B)", &report);
      benchmark_layout<map::ColoredTsdfVoxel>(device, options, "ColoredTsdfVoxel(16B)", &report);
    }
    tools::publish_reports({&report}, options.output);
  });
}

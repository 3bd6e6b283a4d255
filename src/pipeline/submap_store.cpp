#include "covoxslam/pipeline/submap_store.h"

#include <fcntl.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <future>
#include <string>
#include <utility>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/io/mesh_codec.h"
#include "covoxslam/io/submap_codec.h"

namespace covox {
namespace pipeline {

namespace {

constexpr double kBytesPerMb = 1024.0 * 1024.0;

// Hands the heap's free pages back to the system. A compaction frees a map's pools (host memory
// on the CPU backend) and the encoder's per-block temporaries, but glibc keeps freed heap memory
// that lies below live allocations (the compact bytes themselves), so without this the process's
// resident memory would keep what the budget released.
void return_freed_host_memory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

}  // namespace

void validate(const MemoryBudgetConfig& config) {
  if (!(std::isfinite(config.device_budget_mb) && config.device_budget_mb >= 0.0))
    throw Error("memory.device_budget_mb must be >= 0, got " +
                std::to_string(config.device_budget_mb));
  if (!(std::isfinite(config.host_budget_mb) && config.host_budget_mb >= 0.0))
    throw Error("memory.host_budget_mb must be >= 0, got " + std::to_string(config.host_budget_mb));
  if (!(std::isfinite(config.device_cache_mb) && config.device_cache_mb >= 0.0))
    throw Error("memory.device_cache_mb must be >= 0, got " +
                std::to_string(config.device_cache_mb));
}

SubmapStore::SubmapStore(const MemoryBudgetConfig& config, float distance_scale_m,
                         float mesh_step_m)
    : config_(config), distance_scale_m_(distance_scale_m), mesh_step_m_(mesh_step_m) {
  validate(config_);
}

SubmapStore::~SubmapStore() {
  if (spill_fd_ >= 0) ::close(spill_fd_);
}

void SubmapStore::add(Submap& submap) {
  Entry entry;
  entry.resident_bytes = submap.map().device_bytes();
  entry.mesh = submap.take_mesh();
  const int64_t mesh_bytes = static_cast<int64_t>(io::mesh_bytes_in_memory(entry.mesh));
  std::lock_guard<std::mutex> lock(mutex_);
  entry.last_use = ++use_clock_;
  const int64_t resident_bytes = entry.resident_bytes;
  if (!entries_.emplace(submap.id(), std::move(entry)).second)
    throw Error("SubmapStore: submap " + std::to_string(submap.id()) + " added twice");
  ++counters_.submaps_resident;
  counters_.resident_bytes += resident_bytes;
  counters_.peak_resident_bytes = std::max(counters_.peak_resident_bytes, counters_.resident_bytes);
  counters_.mesh_bytes += mesh_bytes;
}

void SubmapStore::add_compact(Submap& submap, std::vector<uint8_t> encoded) {
  if (!enabled() || submap.map().block_count() != 0 || encoded.empty())
    throw Error("SubmapStore: submap " + std::to_string(submap.id()) +
                " cannot be added compact (no budget, blocks still resident or no bytes)");
  Entry entry;
  entry.bytes = std::move(encoded);
  entry.size = entry.bytes.size();
  entry.mesh_bytes = io::encode_mesh(submap.take_mesh(), mesh_step_m_);
  entry.mesh_size = entry.mesh_bytes.size();
  entry.resident = false;
  const int64_t held = static_cast<int64_t>(entry.size + entry.mesh_size);
  const int64_t mesh_bytes = static_cast<int64_t>(entry.mesh_size);
  std::lock_guard<std::mutex> lock(mutex_);
  entry.last_use = ++use_clock_;
  if (!entries_.emplace(submap.id(), std::move(entry)).second)
    throw Error("SubmapStore: submap " + std::to_string(submap.id()) + " added twice");
  ++counters_.submaps_compact;
  counters_.compact_bytes += held;
  counters_.mesh_bytes += mesh_bytes;
}

bool SubmapStore::mesh(int64_t id, map::Mesh* mesh) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(id);
  if (it == entries_.end()) return false;
  Entry& entry = it->second;
  finish_mesh_locked(entry);
  if (entry.mesh_size == 0) {
    *mesh = entry.mesh;
  } else if (!entry.mesh_bytes.empty()) {
    *mesh = io::decode_mesh(entry.mesh_bytes, "a submap's encoded mesh");
  } else {
    *mesh = io::decode_mesh(read_back_locked(id, entry, entry.size, entry.mesh_size),
                            "a submap's mesh from the spill file");
  }
  return true;
}

bool SubmapStore::acquire(Submap& submap, integrators::EsdfIntegrator& esdf, const Stream& stream,
                          bool mark_used) {
  if (!enabled()) return false;
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(submap.id());
  if (it == entries_.end()) return false;
  Entry& entry = it->second;
  if (mark_used) entry.last_use = ++use_clock_;
  if (entry.resident) return false;
  const auto start = std::chrono::steady_clock::now();
  StageProfiler::Scope profile("restore", stream);
  const bool from_disk = entry.bytes.empty();
  std::vector<uint8_t> read_back;
  if (from_disk) read_back = read_back_locked(submap.id(), entry, 0, entry.size);
  const std::vector<uint8_t>& bytes = from_disk ? read_back : entry.bytes;
  profile.mark("read back");
  submap.map() = map::TsdfMap(submap.map().device(), submap.map().config());
  io::load_encoded_submap(bytes, &submap.map(), stream);
  profile.mark("decode");
  esdf.update_all(submap.map(), stream);
  stream.synchronize();
  profile.mark("esdf");
  entry.resident = true;
  entry.resident_bytes = submap.map().device_bytes();
  if (from_disk) {
    --counters_.submaps_on_disk;
  } else {
    --counters_.submaps_compact;
  }
  ++counters_.submaps_resident;
  counters_.resident_bytes += entry.resident_bytes;
  counters_.peak_resident_bytes = std::max(counters_.peak_resident_bytes, counters_.resident_bytes);
  ++counters_.restores;
  counters_.restore_s +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return true;
}

void SubmapStore::enforce(const std::vector<Submap*>& candidates, int64_t keep,
                          bool return_memory) {
  if (!enabled()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  finish_ready_meshes_locked();
  std::vector<std::pair<Submap*, Entry*>> least_recent_first;
  least_recent_first.reserve(candidates.size());
  for (Submap* submap : candidates) {
    auto it = entries_.find(submap->id());
    if (submap->id() != keep && it != entries_.end())
      least_recent_first.emplace_back(submap, &it->second);
  }
  std::stable_sort(
      least_recent_first.begin(), least_recent_first.end(),
      [](const auto& a, const auto& b) { return a.second->last_use < b.second->last_use; });
  const int64_t compactions_before = counters_.compactions;
  const double device_budget = config_.device_budget_mb * kBytesPerMb;
  for (auto& [submap, entry] : least_recent_first) {
    if (static_cast<double>(counters_.resident_bytes) <= device_budget) break;
    if (entry->resident) compact_locked(*submap, *entry);
  }
  const double host_budget = config_.host_budget_mb * kBytesPerMb;
  for (auto& [submap, entry] : least_recent_first) {
    if (static_cast<double>(counters_.compact_bytes) <= host_budget) break;
    if (entry->resident || entry->bytes.empty()) continue;
    if (!spill_locked(submap->id(), *entry)) break;  // no disk: keep everything in memory
  }
  memory_to_return_ = memory_to_return_ || counters_.compactions != compactions_before;
  if (return_memory && memory_to_return_) {
    return_freed_host_memory();
    memory_to_return_ = false;
  }
}

void SubmapStore::compact_locked(Submap& submap, Entry& entry) {
  const Stream device_stream(submap.map().device());
  StageProfiler::Scope profile("compact", device_stream);
  if (entry.size == 0) {  // first compaction: the one lossy step (see the header)
    entry.bytes = io::encode_submap(submap.map(), distance_scale_m_);
    entry.size = entry.bytes.size();
    counters_.compact_bytes += static_cast<int64_t>(entry.size);
    profile.mark("encode voxels");
    // The mesh, host work only, is encoded on a worker thread: the registration that made room
    // goes on meanwhile, and the bytes are taken when first needed (finish_mesh_locked). Until
    // then the mesh as made is what it holds, and what mesh_bytes counts.
    entry.pending_mesh_bytes = static_cast<int64_t>(io::mesh_bytes_in_memory(entry.mesh));
    entry.pending_mesh =
        std::async(std::launch::async, [mesh = std::move(entry.mesh), step_m = mesh_step_m_]() {
          return io::encode_mesh(mesh, step_m);
        });
    entry.mesh = map::Mesh();
    pending_meshes_.push_back(submap.id());
  }
  // Pools and block table freed; acquire() rebuilds the map with its configured table.
  submap.map().release();
  profile.mark("release");
  entry.resident = false;
  counters_.resident_bytes -= entry.resident_bytes;
  entry.resident_bytes = 0;
  --counters_.submaps_resident;
  ++counters_.compactions;
  if (entry.bytes.empty()) {
    ++counters_.submaps_on_disk;  // came back from disk for a while; its copy there is current
  } else {
    ++counters_.submaps_compact;
  }
}

void SubmapStore::finish_mesh_locked(Entry& entry) {
  if (!entry.pending_mesh.valid()) return;
  entry.mesh_bytes = entry.pending_mesh.get();  // rethrows the encoder's error
  entry.mesh_size = entry.mesh_bytes.size();
  counters_.mesh_bytes += static_cast<int64_t>(entry.mesh_size) - entry.pending_mesh_bytes;
  counters_.compact_bytes += static_cast<int64_t>(entry.mesh_size);
  entry.pending_mesh_bytes = 0;
}

void SubmapStore::finish_ready_meshes_locked() {
  std::vector<int64_t> still_pending;
  for (int64_t id : pending_meshes_) {
    auto it = entries_.find(id);
    if (it == entries_.end() || !it->second.pending_mesh.valid()) continue;
    if (it->second.pending_mesh.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
      finish_mesh_locked(it->second);
    } else {
      still_pending.push_back(id);
    }
  }
  pending_meshes_.swap(still_pending);
}

bool SubmapStore::spill_locked(int64_t id, Entry& entry) {
  finish_mesh_locked(entry);
  try {
    if (entry.file_offset < 0) {
      open_spill_file_locked();
      write_at_locked(entry.bytes, spill_end_);
      write_at_locked(entry.mesh_bytes, spill_end_ + static_cast<int64_t>(entry.size));
      entry.file_offset = spill_end_;
      const int64_t written = static_cast<int64_t>(entry.size + entry.mesh_size);
      spill_end_ += written;
      counters_.disk_bytes += written;
      ++counters_.spills;
    }
  } catch (const std::exception& error) {
    // The first failure and then every 100th: a full disk cannot flood the log, the counter
    // says how many there were.
    if (++counters_.spill_failures % 100 != 1) return false;
    log_error("SLAM memory: could not write submap ", id, " to the spill file in '",
              config_.spill_directory, "': ", error.what(), " (it stays in memory; ",
              counters_.spill_failures, " such failures)");
    return false;
  }
  counters_.compact_bytes -= static_cast<int64_t>(entry.size + entry.mesh_size);
  counters_.mesh_bytes -= static_cast<int64_t>(entry.mesh_size);
  std::vector<uint8_t>().swap(entry.bytes);
  std::vector<uint8_t>().swap(entry.mesh_bytes);
  --counters_.submaps_compact;
  ++counters_.submaps_on_disk;
  return true;
}

void SubmapStore::write_at_locked(const std::vector<uint8_t>& bytes, int64_t offset) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t wrote = ::pwrite(spill_fd_, bytes.data() + done, bytes.size() - done,
                                   offset + static_cast<int64_t>(done));
    if (wrote < 0 && errno == EINTR) continue;
    if (wrote <= 0) throw Error(std::string("write failed: ") + std::strerror(errno));
    done += static_cast<size_t>(wrote);
  }
}

std::vector<uint8_t> SubmapStore::read_back_locked(int64_t id, const Entry& entry, uint64_t offset,
                                                   uint64_t size) {
  std::vector<uint8_t> bytes(static_cast<size_t>(size));
  const int64_t start = entry.file_offset + static_cast<int64_t>(offset);
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t got = ::pread(spill_fd_, bytes.data() + done, bytes.size() - done,
                                start + static_cast<int64_t>(done));
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0)
      throw Error("SLAM memory: reading submap " + std::to_string(id) +
                  " back from the spill file failed: " + std::strerror(errno));
    done += static_cast<size_t>(got);
  }
  ++counters_.spill_reads;
  return bytes;
}

void SubmapStore::open_spill_file_locked() {
  if (spill_fd_ >= 0) return;
  const std::filesystem::path folder = config_.spill_directory.empty()
                                           ? std::filesystem::temp_directory_path()
                                           : std::filesystem::path(config_.spill_directory);
  std::string path = (folder / "covoxslam_spill_XXXXXX").string();
  const int fd = ::mkstemp(path.data());
  if (fd < 0)
    throw Error("cannot create a spill file in '" + folder.string() + "': " + std::strerror(errno));
  // Unlinked at once: the space is freed when the process closes it, even after a crash.
  ::unlink(path.c_str());
  spill_fd_ = fd;
  spill_end_ = 0;
}

std::vector<uint8_t> SubmapStore::encoded(int64_t id) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(id);
  if (it == entries_.end() || it->second.size == 0) return {};
  if (!it->second.bytes.empty()) return it->second.bytes;
  return read_back_locked(id, it->second, 0, it->second.size);
}

void SubmapStore::remove(int64_t id) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(id);
  if (it == entries_.end()) return;
  Entry& entry = it->second;
  finish_mesh_locked(entry);
  if (entry.resident) {
    --counters_.submaps_resident;
    counters_.resident_bytes -= entry.resident_bytes;
  } else if (entry.bytes.empty()) {
    --counters_.submaps_on_disk;
  } else {
    --counters_.submaps_compact;
  }
  if (!entry.bytes.empty())
    counters_.compact_bytes -= static_cast<int64_t>(entry.size + entry.mesh_size);
  counters_.mesh_bytes -= static_cast<int64_t>(
      entry.mesh_size == 0 ? io::mesh_bytes_in_memory(entry.mesh) : entry.mesh_bytes.size());
  entries_.erase(it);
}

void SubmapStore::clear() {
  std::lock_guard<std::mutex> lock(mutex_);
  entries_.clear();  // waits for the meshes still being encoded
  pending_meshes_.clear();
  const SubmapStoreCounters totals = counters_;
  counters_ = SubmapStoreCounters();
  // What moving submaps cost stays counted across resets; where they are starts afresh.
  counters_.compactions = totals.compactions;
  counters_.restores = totals.restores;
  counters_.spills = totals.spills;
  counters_.spill_reads = totals.spill_reads;
  counters_.spill_failures = totals.spill_failures;
  counters_.restore_s = totals.restore_s;
  counters_.peak_resident_bytes = totals.peak_resident_bytes;
  if (spill_fd_ >= 0 && ::ftruncate(spill_fd_, 0) == 0) spill_end_ = 0;
}

SubmapStoreCounters SubmapStore::counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return counters_;
}

}  // namespace pipeline
}  // namespace covox

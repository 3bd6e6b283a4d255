#pragma once
// SubmapStore: where finished submaps' voxels and meshes live under a memory budget. A submap is
// resident (its full TsdfMap on the map's device), compact (its io/submap_codec.h bytes in host
// memory) or on disk (those bytes in the spill file). Over device_budget_mb the least recently
// used resident submaps are encoded and released; over host_budget_mb the least recently used
// compact ones go to disk. The first compaction is the one step that changes a submap (later ones
// reuse the bytes it came back from); a failed spill write is logged and counted and the submap
// stays in memory. Meshes are kept as made, then encoded (io/mesh_codec.h) on a worker thread at
// the first compaction and budgeted and spilled with the voxels. Driven by SlamSystem under its
// backend_mutex_; the store's own mutex guards its counters and bytes. docs/design.md ("Submaps").
#include <cstdint>
#include <future>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {

struct MemoryBudgetConfig {
  // Full (resident) finished submaps, in MiB on the map's device (voxel pools and block table:
  // map::TsdfMap::device_bytes()). 0: no budget and no compact form: finished submaps keep their
  // voxels exactly as integrated.
  double device_budget_mb = 1536.0;
  // Compact submaps held in host memory, MiB; beyond it the least recently used go to the spill
  // file.
  double host_budget_mb = 1536.0;
  // Freed GPU memory kept for reuse instead of handed back to the driver (core/memory.h: a
  // restore and a compaction allocate and free whole maps), MiB, outside device_budget_mb. It is
  // process-wide: the last SlamSystem created sets it. 0: none kept.
  double device_cache_mb = 256.0;
  // Folder of the spill file (created when first needed, removed from the folder at once so it
  // disappears with the process). Empty: the system's temporary folder.
  std::string spill_directory;
};
// Throws covox::Error naming the first invalid parameter (prefix "memory.").
void validate(const MemoryBudgetConfig& config);

// Where the finished submaps' voxels are, and what moving them cost.
struct SubmapStoreCounters {
  int64_t submaps_resident = 0;
  int64_t submaps_compact = 0;  // compact bytes in host memory only
  int64_t submaps_on_disk = 0;
  int64_t resident_bytes = 0;       // device memory of the resident submaps' maps
  int64_t peak_resident_bytes = 0;  // the most resident_bytes has been (over resets too)
  int64_t compact_bytes = 0;        // compact forms held in host memory (resident ones' included),
                                    // their encoded meshes included
  int64_t disk_bytes = 0;           // compact forms written to the spill file
  int64_t compactions = 0;          // a resident submap's voxels released
  int64_t restores = 0;             // a submap's voxels rebuilt from its compact form
  int64_t spills = 0;               // compact forms written to the spill file
  int64_t spill_reads = 0;          // compact forms read back from it
  int64_t spill_failures = 0;       // spill writes that failed (the submap stayed in memory)
  double restore_s = 0.0;           // wall time spent rebuilding submaps (decode, load, ESDF)
  int64_t mesh_bytes = 0;           // meshes in host memory: as made (resident submaps) and encoded
};

class SubmapStore {
 public:
  // `mesh_step_m`: the grid an encoded mesh's vertices are rounded to (io/mesh_codec.h).
  SubmapStore(const MemoryBudgetConfig& config, float distance_scale_m, float mesh_step_m);
  ~SubmapStore();
  SubmapStore(const SubmapStore&) = delete;
  SubmapStore& operator=(const SubmapStore&) = delete;

  // False with device_budget_mb 0: the store does nothing and submaps stay resident.
  bool enabled() const { return config_.device_budget_mb > 0.0; }

  // A finished or loaded submap (after Submap::finish()), resident with its voxels as they are; it
  // is encoded when it is first compacted. Takes the submap's mesh (Submap::take_mesh()).
  void add(Submap& submap);
  // A finished submap whose voxels were released (map::TsdfMap::release(), a loaded submap past
  // the budget) kept as `encoded`, its compact form, as if it had been compacted: its mesh is
  // taken and encoded. Throws covox::Error without a budget or while the map holds blocks.
  void add_compact(Submap& submap, std::vector<uint8_t> encoded);
  // A copy of the submap's mesh (decoded, read back from the spill file if needed); false when
  // the store does not know the id.
  bool mesh(int64_t id, map::Mesh* mesh);
  // Makes the submap's voxels resident again (decoded, ESDF recomputed; a no-op if they are) and,
  // with `mark_used`, marks it used. A sweep over every submap (a slice, a snapshot) passes false:
  // a submap brought back only for the sweep keeps its old use, so it is the first to leave
  // again, and the resident ones the sweep has yet to read stay. True when the voxels came back.
  bool acquire(Submap& submap, integrators::EsdfIntegrator& esdf, const Stream& stream,
               bool mark_used = true);
  // Compacts resident submaps among `candidates`, least recently used first, until the resident
  // bytes fit the device budget, then spills compact ones, least recently used first, until the
  // bytes in host memory fit the host budget. `keep` (an id, or -1) stays resident.
  // `return_memory` false defers handing freed host memory back to the system to the next call
  // with true (a caller about to restore more submaps reuses it at once).
  void enforce(const std::vector<Submap*>& candidates, int64_t keep, bool return_memory = true);
  // The compact form of a submap the store holds (read back from the spill file if needed);
  // empty when the store does not know the id or the submap has never been compacted (its
  // voxels are resident: encode them).
  std::vector<uint8_t> encoded(int64_t id);
  // Forgets every submap (reset, load): their bytes and the spill file's contents.
  void clear();
  // Forgets one submap.
  void remove(int64_t id);
  SubmapStoreCounters counters() const;

 private:
  struct Entry {
    std::vector<uint8_t> bytes;  // empty while on disk only, or before the first compaction
    uint64_t size = 0;           // of the compact form; 0 until the first compaction encodes it
    map::Mesh mesh;              // as made, until the first compaction encodes it
    std::vector<uint8_t> mesh_bytes;  // the encoded mesh, held and spilled beside `bytes`
    uint64_t mesh_size = 0;           // of the encoded mesh; 0 until encoded
    // The mesh being encoded since the first compaction, and the bytes of the mesh as made it
    // holds meanwhile (counted in mesh_bytes until finish_mesh_locked).
    std::future<std::vector<uint8_t>> pending_mesh;
    int64_t pending_mesh_bytes = 0;
    int64_t file_offset = -1;  // in the spill file, once written there: `bytes`, then the mesh's
    bool resident = true;
    int64_t resident_bytes = 0;
    uint64_t last_use = 0;  // use_clock_ at the latest add or acquire
  };
  // Encodes the submap on its first compaction and releases its voxels.
  void compact_locked(Submap& submap, Entry& entry);
  // Takes the entry's encoded mesh once its encoding is done (waits for it), with the counters.
  void finish_mesh_locked(Entry& entry);
  // finish_mesh_locked for every pending mesh whose encoding is done, without waiting.
  void finish_ready_meshes_locked();
  // Appends the entry's bytes to the spill file; false (logged, counted) when that fails.
  bool spill_locked(int64_t id, Entry& entry);
  // Writes `bytes` at `offset` of the spill file; throws covox::Error when that fails.
  void write_at_locked(const std::vector<uint8_t>& bytes, int64_t offset);
  // `size` bytes at `offset` past the entry's place in the spill file.
  std::vector<uint8_t> read_back_locked(int64_t id, const Entry& entry, uint64_t offset,
                                        uint64_t size);
  void open_spill_file_locked();

  const MemoryBudgetConfig config_;
  const float distance_scale_m_;
  const float mesh_step_m_;
  mutable std::mutex mutex_;
  std::unordered_map<int64_t, Entry> entries_;
  std::vector<int64_t> pending_meshes_;  // ids whose mesh is being encoded
  SubmapStoreCounters counters_;
  uint64_t use_clock_ = 0;
  bool memory_to_return_ = false;  // compactions since freed memory was last handed back
  int spill_fd_ = -1;
  int64_t spill_end_ = 0;
};

}  // namespace pipeline
}  // namespace covox

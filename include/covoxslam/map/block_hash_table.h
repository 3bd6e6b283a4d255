#pragma once
// BlockHashTable: maps 3-D block indices to slots in pre-allocated voxel pools, on the GPU or
// the CPU twin. One open-addressing table, no second index, no double indirection.
//
// Batch operations take arrays that live on the table's device:
//   activate(keys)  insert-if-absent; every key gets its slot and whether this call created it
//   find(keys)      slot or kInvalidSlot
//   erase(keys)     removes; freed slots are reused by later activations
// Slots are dense integers [0, slot_count()): the owner of the voxel pool keeps the pool at
// least slot_count() blocks large. Rehashing (growth) moves keys between buckets but never
// changes a key's slot.
#include <cstdint>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/index3d.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/block_activator.h"
#include "covoxslam/map/block_hash_table_state.h"

namespace covox::map {

class BlockHashTable {
 public:
  explicit BlockHashTable(Device device, const BlockHashTableConfig& config = {});

  BlockHashTable(const BlockHashTable&) = delete;
  BlockHashTable& operator=(const BlockHashTable&) = delete;
  BlockHashTable(BlockHashTable&&) noexcept = default;
  BlockHashTable& operator=(BlockHashTable&&) noexcept = default;

  // Insert-if-absent for `count` keys at `keys` (device memory of this table's device).
  // slots_out[i] receives the key's slot (kInvalidSlot if the key was rejected), is_new_out[i]
  // (optional) is 1 for exactly one occurrence of each key this call inserted. Correct when a
  // batch holds the same key many times. Out-of-range keys and keys that found the table full are
  // counted in the result and logged; the table stays consistent.
  ActivateResult activate(const Index3D* keys, int64_t count, uint32_t* slots_out,
                          uint8_t* is_new_out = nullptr);
  ActivateResult activate(const Index3D* keys, int64_t count, uint32_t* slots_out,
                          uint8_t* is_new_out, const Stream& stream);

  // activate() without waiting for the device: for a caller that reads figures back anyway and
  // can take the table's with them (one wait instead of two). The keys are the first
  // *count_on_device (device memory) of `keys`, at most count_bound; slots_out and is_new_out hold
  // count_bound entries, those past the count get kInvalidSlot and 0. totals_out (device memory)
  // receives the number of new keys and of rejected keys once the queued work has run; pass them
  // to finish_queued_activation() before any other call on this table. Returns false, queuing
  // nothing, when the table might have to grow for count_bound new keys (growth needs the exact
  // count): call activate() then.
  bool activate_queued(const Index3D* keys, const uint32_t* count_on_device, int64_t count_bound,
                       uint32_t* slots_out, uint8_t* is_new_out, uint32_t* totals_out,
                       const Stream& stream);
  ActivateResult finish_queued_activation(uint32_t num_new, uint32_t num_rejected,
                                          const Stream& stream);

  // An activation of at most `count_bound` distinct keys made from inside the caller's kernels
  // (block_activator.h): fills *activator and returns true, or returns false when the table might
  // have to grow (call activate() then). Until finish_in_kernel_activation() gets the totals that
  // BlockActivator::hand_over_totals() wrote, other calls on this table are refused.
  bool begin_in_kernel_activation(int64_t count_bound, BlockActivator* activator,
                                  const Stream& stream);
  ActivateResult finish_in_kernel_activation(uint32_t num_new, uint32_t num_out_of_range,
                                             uint32_t num_table_full);
  // For a caller that stops (an exception) before it finishes a pending activation: waits for the
  // stream and finishes it from what the device holds, an in-kernel activation from its counters
  // (cleared again), a queued one from the totals it wrote to `queued_totals` (the caller's
  // totals_out; null: unknown), so that the table takes later calls and hands out no slot twice.
  // Nothing to do when no activation is pending. Does not throw: if the device cannot be read, the
  // activation is dropped from the books and a warning logged (a slot may then be handed out
  // twice).
  void abandon_pending_activation(const uint32_t* queued_totals, const Stream& stream) noexcept;

  // slots_out[i] = slot of keys[i] or kInvalidSlot. Returns how many were found.
  int64_t find(const Index3D* keys, int64_t count, uint32_t* slots_out) const;
  int64_t find(const Index3D* keys, int64_t count, uint32_t* slots_out, const Stream& stream) const;

  // Removes the keys (absent and duplicate keys are ignored). Returns how many were removed.
  int64_t erase(const Index3D* keys, int64_t count);
  int64_t erase(const Index3D* keys, int64_t count, const Stream& stream);

  // Makes room for `key_count` live keys below the maximum load factor (rehashes if needed).
  void reserve(int64_t key_count);
  // Rebuilds the table with `bucket_count` buckets (dropping tombstones); slots are preserved.
  // Throws covox::Error if the live keys do not fit.
  void rehash(uint64_t bucket_count);
  // Removes every key and forgets every slot.
  void clear();

  // All live keys and their slots (on this table's device), in bucket order.
  void export_entries(Buffer<Index3D>* keys, Buffer<uint32_t>* slots) const;

  // Plain pointers for lookups inside kernels (find() on the device); valid until the next
  // activate/erase/rehash/clear.
  BlockHashTableView device_view() const { return const_cast<BlockHashTableState&>(state_).view(); }

  Device device() const { return state_.device; }
  const BlockHashTableConfig& config() const { return state_.config; }
  int64_t size() const { return state_.live_count; }
  uint64_t bucket_count() const { return state_.bucket_count(); }
  // Live keys per bucket.
  double load_factor() const;
  // Live keys plus tombstones per bucket: what probe lengths depend on, and what growth watches.
  double occupancy() const;
  // Slots handed out so far (live or freed): the voxel pool needs at least this many blocks.
  uint32_t slot_count() const { return state_.next_unused_slot; }
  int64_t total_out_of_range() const { return state_.total_out_of_range; }
  int64_t total_failed_full() const { return state_.total_failed_full; }
  int64_t rehash_count() const { return state_.rehash_count; }

 private:
  const Stream& default_stream() const { return default_stream_; }
  // Throws covox::Error while an activate_queued() awaits its finish.
  void require_nothing_queued(const char* operation) const;

  BlockHashTableState state_;
  Stream default_stream_;
};

}  // namespace covox::map

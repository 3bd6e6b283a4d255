#include "covoxslam/map/block_hash_table.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/map/internal/block_hash_table_ops.h"

namespace covox::map {
namespace {

void validate(const BlockHashTableConfig& config) {
  if (!(config.max_load_factor > 0.0 && config.max_load_factor < 1.0)) {
    throw Error("BlockHashTable: max_load_factor must be in (0, 1), got " +
                std::to_string(config.max_load_factor));
  }
  if (config.initial_bucket_count < 2) {
    throw Error("BlockHashTable: initial_bucket_count must be at least 2, got " +
                std::to_string(config.initial_bucket_count));
  }
}

}  // namespace

BlockHashTable::BlockHashTable(Device device, const BlockHashTableConfig& config)
    : state_(device), default_stream_(device) {
  validate(config);
  state_.config = config;
  state_.keys.resize_discard(config.initial_bucket_count);
  state_.slots.resize_discard(config.initial_bucket_count);
  state_.keys.fill_bytes(0xff, default_stream_);  // all buckets empty
  default_stream_.synchronize();
}

ActivateResult BlockHashTable::activate(const Index3D* keys, int64_t count, uint32_t* slots_out,
                                        uint8_t* is_new_out) {
  return activate(keys, count, slots_out, is_new_out, default_stream());
}

ActivateResult BlockHashTable::activate(const Index3D* keys, int64_t count, uint32_t* slots_out,
                                        uint8_t* is_new_out, const Stream& stream) {
  require_nothing_queued("activate");
  return dispatch(state_.device, [&](auto backend) {
    return hash_table_activate(backend, state_, keys, count, slots_out, is_new_out, stream);
  });
}

bool BlockHashTable::activate_queued(const Index3D* keys, const uint32_t* count_on_device,
                                     int64_t count_bound, uint32_t* slots_out, uint8_t* is_new_out,
                                     uint32_t* totals_out, const Stream& stream) {
  return dispatch(state_.device, [&](auto backend) {
    return hash_table_activate_queued(backend, state_, keys, count_on_device, count_bound,
                                      slots_out, is_new_out, totals_out, stream);
  });
}

ActivateResult BlockHashTable::finish_queued_activation(uint32_t num_new, uint32_t num_rejected,
                                                        const Stream& stream) {
  return dispatch(state_.device, [&](auto backend) {
    return hash_table_finish_queued(backend, state_, num_new, num_rejected, stream);
  });
}

// The same growth check as activate_queued.
bool BlockHashTable::begin_in_kernel_activation(int64_t count_bound, BlockActivator* activator,
                                                const Stream& stream) {
  require_nothing_queued("begin_in_kernel_activation");
  if (count_bound <= 0 || state_.might_grow_for(count_bound)) return false;
  activator->table = state_.view();
  activator->free_stack = state_.free_slots.data();
  activator->free_count = state_.free_count;
  activator->next_unused = state_.next_unused_slot;
  activator->counters = state_.activation_failures(stream) + 3;
  state_.pending_count = count_bound;
  state_.pending_in_kernel = true;
  return true;
}

void BlockHashTable::abandon_pending_activation(const uint32_t* queued_totals,
                                                const Stream& stream) noexcept {
  if (state_.pending_count < 0) return;
  try {
    if (state_.pending_in_kernel) {
      uint32_t counters[3] = {0u, 0u, 0u};
      uint32_t* words = state_.activation_words.data() + 3;
      copy_bytes(counters, Device::kCpu, words, state_.device, sizeof(counters), stream);
      const uint32_t zeros[3] = {0u, 0u, 0u};
      copy_bytes(words, state_.device, zeros, Device::kCpu, sizeof(zeros), stream);
      finish_in_kernel_activation(counters[0], counters[1], counters[2]);
      return;
    }
    if (!queued_totals) throw Error("the queued activation's totals were not given");
    uint32_t totals[2] = {0u, 0u};
    copy_bytes(totals, Device::kCpu, queued_totals, state_.device, sizeof(totals), stream);
    finish_queued_activation(totals[0], totals[1], stream);
  } catch (const std::exception& error) {
    state_.pending_count = -1;
    state_.pending_in_kernel = false;
    log_warning("BlockHashTable: an abandoned activation could not be read back (", error.what(),
                "); its new keys' slots are not accounted for");
  }
}

ActivateResult BlockHashTable::finish_in_kernel_activation(uint32_t num_new,
                                                           uint32_t num_out_of_range,
                                                           uint32_t num_table_full) {
  if (state_.pending_count < 0) {
    throw Error("BlockHashTable::finish_in_kernel_activation: no activation is pending");
  }
  state_.pending_count = -1;
  state_.pending_in_kernel = false;
  return internal::activate_finish_counted(state_, num_new, num_out_of_range, num_table_full);
}

void BlockHashTable::require_nothing_queued(const char* operation) const {
  if (state_.pending_count >= 0) {
    throw Error(std::string("BlockHashTable::") + operation +
                ": an activation is pending; finish it first (finish_queued_activation or "
                "finish_in_kernel_activation)");
  }
}

int64_t BlockHashTable::find(const Index3D* keys, int64_t count, uint32_t* slots_out) const {
  return find(keys, count, slots_out, default_stream());
}

int64_t BlockHashTable::find(const Index3D* keys, int64_t count, uint32_t* slots_out,
                             const Stream& stream) const {
  // find() changes nothing; the state is only non-const because the algorithms share a signature.
  auto& state = const_cast<BlockHashTableState&>(state_);
  return dispatch(state_.device, [&](auto backend) {
    return hash_table_find(backend, state, keys, count, slots_out, stream);
  });
}

int64_t BlockHashTable::erase(const Index3D* keys, int64_t count) {
  return erase(keys, count, default_stream());
}

int64_t BlockHashTable::erase(const Index3D* keys, int64_t count, const Stream& stream) {
  require_nothing_queued("erase");
  return dispatch(state_.device, [&](auto backend) {
    return hash_table_erase(backend, state_, keys, count, stream);
  });
}

void BlockHashTable::reserve(int64_t key_count) {
  const double wanted = static_cast<double>(key_count) / state_.config.max_load_factor;
  if (wanted <= static_cast<double>(bucket_count())) return;
  rehash(static_cast<uint64_t>(std::ceil(wanted)) + 1);
}

void BlockHashTable::rehash(uint64_t new_bucket_count) {
  require_nothing_queued("rehash");
  dispatch(state_.device, [&](auto backend) {
    hash_table_rehash(backend, state_, new_bucket_count, default_stream());
  });
}

void BlockHashTable::clear() {
  require_nothing_queued("clear");
  state_.keys.fill_bytes(0xff, default_stream_);
  default_stream_.synchronize();
  state_.free_count = 0;
  state_.next_unused_slot = 0;
  state_.live_count = 0;
  state_.occupied_count = 0;
}

void BlockHashTable::export_entries(Buffer<Index3D>* keys, Buffer<uint32_t>* slots) const {
  require_nothing_queued("export_entries");
  auto& state = const_cast<BlockHashTableState&>(state_);  // scratch only
  dispatch(state_.device,
           [&](auto backend) { hash_table_export(backend, state, keys, slots, default_stream()); });
}

double BlockHashTable::load_factor() const {
  return static_cast<double>(state_.live_count) / static_cast<double>(bucket_count());
}

double BlockHashTable::occupancy() const {
  return static_cast<double>(state_.occupied_count) / static_cast<double>(bucket_count());
}

namespace internal {
ActivateResult activate_finish_counted(BlockHashTableState& state, int64_t num_new,
                                       int64_t num_out_of_range, int64_t num_failed_full) {
  ActivateResult result;
  const uint32_t reused = static_cast<uint32_t>(std::min<int64_t>(num_new, state.free_count));
  state.free_count -= reused;
  state.next_unused_slot += static_cast<uint32_t>(num_new - reused);
  state.live_count += num_new;
  state.occupied_count += num_new;
  result.num_new = num_new;
  result.num_failed_full = num_failed_full;
  result.num_out_of_range = num_out_of_range;
  state.total_out_of_range += num_out_of_range;
  state.total_failed_full += num_failed_full;
  if (num_out_of_range > 0) {
    log_warning("BlockHashTable: rejected ", num_out_of_range,
                " block indices outside the key range [", kMinBlockIndex, ", ", kMaxBlockIndex,
                "] per axis (", state.total_out_of_range,
                " so far); points that far from the map origin are dropped");
  }
  if (num_failed_full > 0) {
    log_warning("BlockHashTable is full: ", num_failed_full, " keys not inserted (",
                state.bucket_count(), " buckets, occupancy ",
                static_cast<double>(state.occupied_count) / state.bucket_count(),
                "). Enable allow_growth or raise initial_bucket_count.");
  }
  return result;
}
}  // namespace internal

}  // namespace covox::map

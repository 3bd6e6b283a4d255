#pragma once
// Declarations of the backend-templated BlockHashTable algorithms. Definitions live in
// block_hash_table_impl.h and are instantiated for CpuBackend in src/ and CudaBackend in cuda/.
#include <cstdint>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/index3d.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/block_hash_table_state.h"

namespace covox::map {

namespace internal {
// An activation's host part once its totals are known: slot bookkeeping, the failure totals and
// their warnings (block_hash_table.cpp).
ActivateResult activate_finish_counted(BlockHashTableState& state, int64_t num_new,
                                       int64_t num_out_of_range, int64_t num_failed_full);
}  // namespace internal

template <class Backend>
void hash_table_rehash(Backend backend, BlockHashTableState& state, uint64_t new_bucket_count,
                       const Stream& stream);
template <class Backend>
ActivateResult hash_table_activate(Backend backend, BlockHashTableState& state, const Index3D* keys,
                                   int64_t count, uint32_t* slots_out, uint8_t* is_new_out,
                                   const Stream& stream);
template <class Backend>
bool hash_table_activate_queued(Backend backend, BlockHashTableState& state, const Index3D* keys,
                                const uint32_t* count_on_device, int64_t count_bound,
                                uint32_t* slots_out, uint8_t* is_new_out, uint32_t* totals_out,
                                const Stream& stream);
template <class Backend>
ActivateResult hash_table_finish_queued(Backend backend, BlockHashTableState& state,
                                        uint32_t num_new, uint32_t failed, const Stream& stream);
template <class Backend>
int64_t hash_table_find(Backend backend, BlockHashTableState& state, const Index3D* keys,
                        int64_t count, uint32_t* slots_out, const Stream& stream);
template <class Backend>
int64_t hash_table_erase(Backend backend, BlockHashTableState& state, const Index3D* keys,
                         int64_t count, const Stream& stream);
template <class Backend>
void hash_table_export(Backend backend, BlockHashTableState& state, Buffer<Index3D>* keys_out,
                       Buffer<uint32_t>* slots_out, const Stream& stream);

}  // namespace covox::map

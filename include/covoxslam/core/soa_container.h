#pragma once
// VoxelStorage<Voxel, Layout>: an array of voxels whose fields are stored either as separate
// arrays (SoA: one contiguous array per field) or as an array of structs (AoS), behind the same
// accessors. Kernels take the trivially copyable view(): view.load(i), view.store(i, voxel), and
// view.template get<&Voxel::m>(i), a reference to one field (in SoA only that field's array is
// touched, which makes lookups of one field cheap). A voxel type opts in by listing its fields
// once (VoxelFields<TsdfVoxel>::type = FieldList<&TsdfVoxel::distance_m, &TsdfVoxel::weight>).
// Everything is resolved at compile time (member pointers are template arguments), so the
// abstraction costs nothing at run time.
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/macros.h"

namespace covox {

enum class Layout { kSoA, kAoS };

template <auto... Members>
struct FieldList {};

// Specialise for each voxel type: `using type = FieldList<&Voxel::a, &Voxel::b, ...>;`
template <class Voxel>
struct VoxelFields;

namespace internal {

template <class MemberPointer>
struct member_pointer_traits;
template <class Owner, class Field>
struct member_pointer_traits<Field Owner::*> {
  using owner = Owner;
  using field = Field;
};
template <auto Member>
using field_type = typename member_pointer_traits<decltype(Member)>::field;

template <auto A, auto B>
constexpr bool same_member() {
  if constexpr (std::is_same<decltype(A), decltype(B)>::value) {
    return A == B;
  } else {
    return false;
  }
}

// Position of `Target` in `Members...`, or -1.
template <auto Target, auto... Members>
constexpr int field_index() {
  int index = 0;
  int found = -1;
  ((found = (found < 0 && same_member<Target, Members>()) ? index : found, ++index), ...);
  return found;
}

}  // namespace internal

template <class Voxel, Layout L, class Fields = typename VoxelFields<Voxel>::type>
struct VoxelView;

// Structure of arrays: fields[f] points at an array of field f.
template <class Voxel, auto... Members>
struct VoxelView<Voxel, Layout::kSoA, FieldList<Members...>> {
  static constexpr int kFieldCount = sizeof...(Members);
  void* fields[kFieldCount] = {};
  int64_t size = 0;

  template <auto Member>
  COVOX_HD_INLINE internal::field_type<Member>& get(int64_t i) const {
    constexpr int kIndex = internal::field_index<Member, Members...>();
    static_assert(kIndex >= 0, "this member is not listed in VoxelFields<Voxel>");
    return static_cast<internal::field_type<Member>*>(fields[kIndex])[i];
  }
  COVOX_HD_INLINE Voxel load(int64_t i) const {
    Voxel voxel;
    ((voxel.*Members = get<Members>(i)), ...);
    return voxel;
  }
  COVOX_HD_INLINE void store(int64_t i, const Voxel& voxel) const {
    ((get<Members>(i) = voxel.*Members), ...);
  }
};

// Array of structs.
template <class Voxel, auto... Members>
struct VoxelView<Voxel, Layout::kAoS, FieldList<Members...>> {
  Voxel* voxels = nullptr;
  int64_t size = 0;

  template <auto Member>
  COVOX_HD_INLINE internal::field_type<Member>& get(int64_t i) const {
    return voxels[i].*Member;
  }
  COVOX_HD_INLINE Voxel load(int64_t i) const { return voxels[i]; }
  COVOX_HD_INLINE void store(int64_t i, const Voxel& voxel) const { voxels[i] = voxel; }
};

template <class Voxel, Layout L, class Fields = typename VoxelFields<Voxel>::type>
class VoxelStorage;

// Owner of SoA voxel memory: one buffer per field.
template <class Voxel, auto... Members>
class VoxelStorage<Voxel, Layout::kSoA, FieldList<Members...>> {
 public:
  using View = VoxelView<Voxel, Layout::kSoA>;
  static constexpr Layout kLayout = Layout::kSoA;

  explicit VoxelStorage(Device device = Device::kCpu, size_t size = 0)
      : device_(device), fields_{Buffer<unsigned char>((static_cast<void>(Members), device))...} {
    resize(size);
  }

  Device device() const { return device_; }
  size_t size() const { return size_; }
  size_t bytes_per_voxel() const { return (sizeof(internal::field_type<Members>) + ...); }

  // Keeps the first min(old, new) voxels; new voxels are zero (the default voxel).
  void resize(size_t size, const Stream& stream = Stream()) {
    const size_t old_size = size_;
    size_t f = 0;
    ((resize_field(fields_[f++], size, old_size, sizeof(internal::field_type<Members>), stream)),
     ...);
    size_ = size;
  }
  void set_zero(const Stream& stream = Stream()) {
    for (auto& field : fields_) field.fill_bytes(0, stream);
  }
  View view() {
    View view;
    for (int f = 0; f < View::kFieldCount; ++f) view.fields[f] = fields_[f].data();
    view.size = static_cast<int64_t>(size_);
    return view;
  }
  // Copies every voxel to the host, assembled as structs.
  std::vector<Voxel> to_host(const Stream& stream = Stream()) const {
    std::vector<std::vector<unsigned char>> host_fields;
    for (const auto& field : fields_) host_fields.push_back(field.to_host(stream));
    View host_view;
    for (int f = 0; f < View::kFieldCount; ++f) host_view.fields[f] = host_fields[f].data();
    host_view.size = static_cast<int64_t>(size_);
    std::vector<Voxel> voxels(size_);
    for (size_t i = 0; i < size_; ++i) voxels[i] = host_view.load(static_cast<int64_t>(i));
    return voxels;
  }
  // Replaces the contents with `voxels` (size changes to voxels.size()).
  void copy_from_host(const std::vector<Voxel>& voxels, const Stream& stream = Stream()) {
    std::vector<std::vector<unsigned char>> host_fields{
        std::vector<unsigned char>(voxels.size() * sizeof(internal::field_type<Members>))...};
    View host_view;
    for (int f = 0; f < View::kFieldCount; ++f) host_view.fields[f] = host_fields[f].data();
    for (size_t i = 0; i < voxels.size(); ++i) host_view.store(static_cast<int64_t>(i), voxels[i]);
    for (int f = 0; f < View::kFieldCount; ++f) fields_[f].copy_from_host(host_fields[f], stream);
    size_ = voxels.size();
  }

 private:
  static void resize_field(Buffer<unsigned char>& field, size_t size, size_t old_size,
                           size_t field_bytes, const Stream& stream) {
    field.resize(size * field_bytes, stream);
    if (size > old_size) {
      set_bytes(field.data() + old_size * field_bytes, field.device(), 0,
                (size - old_size) * field_bytes, stream);
    }
  }

  Device device_;
  size_t size_ = 0;
  Buffer<unsigned char> fields_[sizeof...(Members)];
};

// Owner of AoS voxel memory: one buffer of structs.
template <class Voxel, auto... Members>
class VoxelStorage<Voxel, Layout::kAoS, FieldList<Members...>> {
 public:
  using View = VoxelView<Voxel, Layout::kAoS>;
  static constexpr Layout kLayout = Layout::kAoS;

  explicit VoxelStorage(Device device = Device::kCpu, size_t size = 0) : voxels_(device) {
    resize(size);
  }

  Device device() const { return voxels_.device(); }
  size_t size() const { return voxels_.size(); }
  size_t bytes_per_voxel() const { return sizeof(Voxel); }

  void resize(size_t size, const Stream& stream = Stream()) {
    const size_t old_size = voxels_.size();
    voxels_.resize(size, stream);
    if (size > old_size) {
      set_bytes(voxels_.data() + old_size, voxels_.device(), 0, (size - old_size) * sizeof(Voxel),
                stream);
    }
  }
  void set_zero(const Stream& stream = Stream()) { voxels_.fill_bytes(0, stream); }
  View view() { return View{voxels_.data(), static_cast<int64_t>(voxels_.size())}; }
  std::vector<Voxel> to_host(const Stream& stream = Stream()) const {
    return voxels_.to_host(stream);
  }
  void copy_from_host(const std::vector<Voxel>& voxels, const Stream& stream = Stream()) {
    voxels_.copy_from_host(voxels, stream);
  }

 private:
  Buffer<Voxel> voxels_;
};

}  // namespace covox

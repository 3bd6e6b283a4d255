#include "covoxslam/io/mesh_codec.h"

#include <cmath>
#include <cstring>
#include <string>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace {

constexpr char kMagic[4] = {'C', 'V', 'X', 'M'};
constexpr uint8_t kFlagColors = 1;
// Quantised coordinates stay within +-2^62 so that the difference of two fits an int64.
constexpr double kLargestQuantised = 4.0e18;

uint64_t zigzag(int64_t value) {
  return (static_cast<uint64_t>(value) << 1) ^ static_cast<uint64_t>(value >> 63);
}

int64_t unzigzag(uint64_t value) {
  return static_cast<int64_t>(value >> 1) ^ -static_cast<int64_t>(value & 1);
}

void put_varint(uint64_t value, std::vector<uint8_t>* out) {
  while (value >= 0x80) {
    out->push_back(static_cast<uint8_t>(value | 0x80));
    value >>= 7;
  }
  out->push_back(static_cast<uint8_t>(value));
}

template <class T>
void put_raw(const T& value, std::vector<uint8_t>* out) {
  const auto* bytes = reinterpret_cast<const uint8_t*>(&value);
  out->insert(out->end(), bytes, bytes + sizeof(T));
}

int64_t quantise(float coordinate_m, double step_m) {
  const double steps = std::nearbyint(static_cast<double>(coordinate_m) / step_m);
  if (!(std::fabs(steps) <= kLargestQuantised))
    throw Error("encode_mesh: vertex coordinate " + std::to_string(coordinate_m) +
                " m does not fit the quantisation grid of " + std::to_string(step_m) + " m");
  return static_cast<int64_t>(steps);
}

// Reads the encoded fields in order; every read checks the remaining length.
class Reader {
 public:
  Reader(const uint8_t* data, size_t size, const char* what)
      : data_(data), size_(size), what_(what) {}

  template <class T>
  T raw(const char* field) {
    need(sizeof(T), field);
    T value;
    std::memcpy(&value, data_ + position_, sizeof(T));
    position_ += sizeof(T);
    return value;
  }
  uint64_t varint(const char* field) {
    uint64_t value = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      const uint8_t byte = raw<uint8_t>(field);
      value |= static_cast<uint64_t>(byte & 0x7f) << shift;
      if ((byte & 0x80) == 0) return value;
    }
    fail(std::string("a varint of ") + field + " longer than 10 bytes");
  }
  const uint8_t* bytes(size_t size, const char* field) {
    need(size, field);
    const uint8_t* start = data_ + position_;
    position_ += size;
    return start;
  }
  size_t remaining() const { return size_ - position_; }
  [[noreturn]] void fail(const std::string& message) const {
    throw Error(std::string(what_) + ": " + message + " at byte " + std::to_string(position_));
  }

 private:
  void need(size_t size, const char* field) const {
    if (size > size_ - position_) fail(std::string("truncated ") + field);
  }
  const uint8_t* data_;
  size_t size_;
  size_t position_ = 0;
  const char* what_;
};

}  // namespace

size_t mesh_bytes_in_memory(const map::Mesh& mesh) {
  return mesh.vertices_m.size() * sizeof(Vec3f) + mesh.colors.size() * sizeof(Rgb8) +
         mesh.triangles.size() * sizeof(uint32_t);
}

std::vector<uint8_t> encode_mesh(const map::Mesh& mesh, float step_m) {
  if (!(std::isfinite(step_m) && step_m > 0.0f))
    throw Error("encode_mesh: the step must be a positive finite number, got " +
                std::to_string(step_m));
  const bool colored = !mesh.colors.empty();
  if (colored && mesh.colors.size() != mesh.vertices_m.size())
    throw Error("encode_mesh: " + std::to_string(mesh.colors.size()) + " colours for " +
                std::to_string(mesh.vertices_m.size()) + " vertices");
  if (mesh.triangles.size() % 3 != 0)
    throw Error("encode_mesh: " + std::to_string(mesh.triangles.size()) +
                " triangle indices, not a multiple of 3");
  std::vector<uint8_t> out;
  out.reserve(32 + mesh.vertices_m.size() * 6 + mesh.colors.size() * 3 + mesh.triangles.size() * 2);
  for (const char c : kMagic) out.push_back(static_cast<uint8_t>(c));
  put_raw(kMeshCodecVersion, &out);
  put_raw(step_m, &out);
  put_raw(static_cast<uint64_t>(mesh.vertices_m.size()), &out);
  put_raw(static_cast<uint64_t>(mesh.triangle_count()), &out);
  out.push_back(colored ? kFlagColors : 0);
  int64_t previous[3] = {0, 0, 0};
  for (const Vec3f& vertex : mesh.vertices_m) {
    const int64_t current[3] = {quantise(vertex.x, step_m), quantise(vertex.y, step_m),
                                quantise(vertex.z, step_m)};
    for (int axis = 0; axis < 3; ++axis) {
      put_varint(zigzag(current[axis] - previous[axis]), &out);
      previous[axis] = current[axis];
    }
  }
  for (const Rgb8& color : mesh.colors) {
    out.push_back(color.r);
    out.push_back(color.g);
    out.push_back(color.b);
  }
  int64_t previous_index = 0;
  for (uint32_t index : mesh.triangles) {
    if (index >= mesh.vertices_m.size())
      throw Error("encode_mesh: triangle index " + std::to_string(index) + " past the " +
                  std::to_string(mesh.vertices_m.size()) + " vertices");
    put_varint(zigzag(static_cast<int64_t>(index) - previous_index), &out);
    previous_index = index;
  }
  return out;
}

map::Mesh decode_mesh(const uint8_t* data, size_t size, const char* what) {
  Reader in(data, size, what);
  if (std::memcmp(in.bytes(4, "magic"), kMagic, 4) != 0) in.fail("not an encoded mesh");
  const uint32_t version = in.raw<uint32_t>("version");
  if (version != kMeshCodecVersion)
    in.fail("mesh codec version " + std::to_string(version) + ", this build reads " +
            std::to_string(kMeshCodecVersion));
  const float step_m = in.raw<float>("step");
  if (!(std::isfinite(step_m) && step_m > 0.0f)) in.fail("invalid step");
  const uint64_t vertices = in.raw<uint64_t>("vertex count");
  const uint64_t triangles = in.raw<uint64_t>("triangle count");
  const uint8_t flags = in.raw<uint8_t>("flags");
  // Every vertex takes at least three bytes and every index one: counts beyond that are corrupt
  // and must not size an allocation.
  if (vertices > in.remaining() / 3 || triangles > in.remaining() / 3)
    in.fail("counts larger than the bytes that follow");
  map::Mesh mesh;
  mesh.vertices_m.reserve(vertices);
  int64_t current[3] = {0, 0, 0};
  for (uint64_t k = 0; k < vertices; ++k) {
    for (int64_t& coordinate : current) coordinate += unzigzag(in.varint("vertex"));
    mesh.vertices_m.emplace_back(static_cast<float>(current[0] * static_cast<double>(step_m)),
                                 static_cast<float>(current[1] * static_cast<double>(step_m)),
                                 static_cast<float>(current[2] * static_cast<double>(step_m)));
  }
  if (flags & kFlagColors) {
    const uint8_t* rgb = in.bytes(3 * vertices, "colours");
    mesh.colors.resize(vertices);
    for (uint64_t k = 0; k < vertices; ++k)
      mesh.colors[k] = Rgb8{rgb[3 * k], rgb[3 * k + 1], rgb[3 * k + 2]};
  }
  mesh.triangles.reserve(3 * triangles);
  int64_t index = 0;
  for (uint64_t k = 0; k < 3 * triangles; ++k) {
    index += unzigzag(in.varint("triangle index"));
    if (index < 0 || static_cast<uint64_t>(index) >= vertices)
      in.fail("triangle index " + std::to_string(index) + " past the " + std::to_string(vertices) +
              " vertices");
    mesh.triangles.push_back(static_cast<uint32_t>(index));
  }
  if (in.remaining() != 0) in.fail(std::to_string(in.remaining()) + " trailing bytes");
  return mesh;
}

}  // namespace io
}  // namespace covox

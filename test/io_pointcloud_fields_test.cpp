// Decoding PointCloud2 bytes and depth images without ROS: any field order and point step,
// optional colour or intensity, organised clouds with row padding; clouds without x/y/z, with a
// point step too small for their fields, too short, big-endian, or full of NaNs give a clear
// error or a counted drop, never a crash or a wrong point.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "covoxslam/io/depth_image_points.h"
#include "covoxslam/io/pointcloud_fields.h"

namespace covox {
namespace io {
namespace {

constexpr uint8_t kFloat32 = 7;
constexpr uint8_t kUint16 = 4;
constexpr uint8_t kUint32 = 6;

// Writes `value` at byte `offset` of point `index` in a packed buffer.
template <class T>
void put(std::vector<uint8_t>* data, size_t point_start, uint32_t offset, T value) {
  std::memcpy(data->data() + point_start + offset, &value, sizeof(T));
}

struct ReferencePoint {
  float x, y, z;
  uint8_t r, g, b;
  uint16_t intensity;
};

std::vector<ReferencePoint> random_points(int count, uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> coordinate(-20.0f, 20.0f);
  std::uniform_int_distribution<int> byte(0, 255);
  std::uniform_int_distribution<int> intensity(0, 4000);
  std::vector<ReferencePoint> points(count);
  for (ReferencePoint& p : points) {
    p = {coordinate(random),
         coordinate(random),
         coordinate(random),
         static_cast<uint8_t>(byte(random)),
         static_cast<uint8_t>(byte(random)),
         static_cast<uint8_t>(byte(random)),
         static_cast<uint16_t>(intensity(random))};
  }
  return points;
}

// An Ouster-like layout: z before x, padding, intensity as uint16, a 48-byte point step.
PointCloudLayout scrambled_layout(uint32_t width, uint32_t height, uint32_t row_padding) {
  PointCloudLayout layout;
  layout.fields = {{"z", 0, kFloat32, 1}, {"intensity", 6, kUint16, 1}, {"x", 12, kFloat32, 1},
                   {"ring", 16, 2, 1},    {"y", 24, kFloat32, 1},       {"rgb", 32, kUint32, 1}};
  layout.width = width;
  layout.height = height;
  layout.point_step = 48;
  layout.row_step = width * layout.point_step + row_padding;
  return layout;
}

std::vector<uint8_t> encode(const PointCloudLayout& layout,
                            const std::vector<ReferencePoint>& points) {
  std::vector<uint8_t> data(static_cast<size_t>(layout.row_step) * layout.height, 0xAB);
  for (size_t i = 0; i < points.size(); ++i) {
    const size_t row = i / layout.width, column = i % layout.width;
    const size_t start = row * layout.row_step + column * layout.point_step;
    put(&data, start, 12, points[i].x);
    put(&data, start, 24, points[i].y);
    put(&data, start, 0, points[i].z);
    put(&data, start, 6, points[i].intensity);
    const uint32_t packed =
        (uint32_t{points[i].r} << 16) | (uint32_t{points[i].g} << 8) | points[i].b;
    put(&data, start, 32, packed);
  }
  return data;
}

TEST(PointCloudFields, DecodesAnyFieldOrderPointStepAndRowPadding) {
  const std::vector<ReferencePoint> points = random_points(6 * 7, 3);
  const PointCloudLayout layout = scrambled_layout(7, 6, 20);
  const std::vector<uint8_t> data = encode(layout, points);
  DecodedCloud cloud;
  const CloudDecodeResult result = decode_point_cloud(layout, data.data(), data.size(), {}, &cloud);
  ASSERT_TRUE(result.ok()) << result.message;
  ASSERT_EQ(cloud.points_m.size(), points.size());
  ASSERT_EQ(cloud.colors.size(), points.size());
  EXPECT_TRUE(cloud.has_color);
  EXPECT_FALSE(cloud.has_intensity);
  EXPECT_EQ(cloud.points_in, 42);
  EXPECT_EQ(cloud.dropped_non_finite, 0);
  for (size_t i = 0; i < points.size(); ++i) {
    EXPECT_EQ(cloud.points_m[i].x, points[i].x);
    EXPECT_EQ(cloud.points_m[i].y, points[i].y);
    EXPECT_EQ(cloud.points_m[i].z, points[i].z);
    EXPECT_EQ(cloud.colors[i].r, points[i].r);
    EXPECT_EQ(cloud.colors[i].g, points[i].g);
    EXPECT_EQ(cloud.colors[i].b, points[i].b);
  }
}

TEST(PointCloudFields, IntensityBecomesGreyWhenThereIsNoColour) {
  const std::vector<ReferencePoint> points = random_points(50, 4);
  PointCloudLayout layout = scrambled_layout(50, 1, 0);
  const std::vector<uint8_t> data = encode(layout, points);
  layout.fields.pop_back();  // no rgb
  CloudDecodeOptions options;
  options.intensity_max_value = 4000.0f;
  DecodedCloud cloud;
  ASSERT_TRUE(decode_point_cloud(layout, data.data(), data.size(), options, &cloud).ok());
  EXPECT_FALSE(cloud.has_color);
  EXPECT_TRUE(cloud.has_intensity);
  ASSERT_EQ(cloud.colors.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const int expected =
        static_cast<int>(std::lround(std::min(255.0, points[i].intensity * 255.0 / 4000.0)));
    EXPECT_EQ(cloud.colors[i].r, expected);
    EXPECT_EQ(cloud.colors[i].g, expected);
  }
  // Asked not to use intensity: no colours at all.
  options.use_intensity = false;
  ASSERT_TRUE(decode_point_cloud(layout, data.data(), data.size(), options, &cloud).ok());
  EXPECT_TRUE(cloud.colors.empty());
}

TEST(PointCloudFields, MissingXyzIsAClearError) {
  const std::vector<ReferencePoint> points = random_points(10, 5);
  for (const char* missing : {"x", "y", "z"}) {
    PointCloudLayout layout = scrambled_layout(10, 1, 0);
    const std::vector<uint8_t> data = encode(layout, points);
    for (auto it = layout.fields.begin(); it != layout.fields.end(); ++it) {
      if (it->name == missing) {
        layout.fields.erase(it);
        break;
      }
    }
    DecodedCloud cloud;
    const CloudDecodeResult result =
        decode_point_cloud(layout, data.data(), data.size(), {}, &cloud);
    EXPECT_EQ(result.status, CloudDecodeStatus::kMissingXyz);
    EXPECT_NE(result.message.find(std::string("'") + missing + "'"), std::string::npos)
        << result.message;
    EXPECT_TRUE(cloud.points_m.empty());
  }
}

TEST(PointCloudFields, WrongPointStepRowStepOrShortDataAreClearErrors) {
  const std::vector<ReferencePoint> points = random_points(12, 6);
  const PointCloudLayout good = scrambled_layout(4, 3, 8);
  const std::vector<uint8_t> data = encode(good, points);
  DecodedCloud cloud;

  PointCloudLayout layout = good;
  layout.point_step = 28;  // y (24..28) fits, rgb (32..36) does not
  CloudDecodeResult result = decode_point_cloud(layout, data.data(), data.size(), {}, &cloud);
  EXPECT_EQ(result.status, CloudDecodeStatus::kPointStepTooSmall);
  EXPECT_NE(result.message.find("'rgb'"), std::string::npos) << result.message;
  EXPECT_NE(result.message.find("28"), std::string::npos) << result.message;

  layout = good;
  layout.row_step = 4 * 48 - 1;
  EXPECT_EQ(decode_point_cloud(layout, data.data(), data.size(), {}, &cloud).status,
            CloudDecodeStatus::kRowStepTooSmall);

  // The last row may omit its padding, but not a point.
  const size_t exact = 2 * good.row_step + 4 * 48;
  EXPECT_TRUE(decode_point_cloud(good, data.data(), exact, {}, &cloud).ok());
  EXPECT_EQ(cloud.points_m.size(), 12u);
  result = decode_point_cloud(good, data.data(), exact - 1, {}, &cloud);
  EXPECT_EQ(result.status, CloudDecodeStatus::kDataTooShort);
  EXPECT_TRUE(cloud.points_m.empty());

  layout = good;
  layout.is_bigendian = true;
  EXPECT_EQ(decode_point_cloud(layout, data.data(), data.size(), {}, &cloud).status,
            CloudDecodeStatus::kBigEndian);

  layout = good;
  layout.fields[2].datatype = 8;  // x as FLOAT64 (still inside the point)
  EXPECT_EQ(decode_point_cloud(layout, data.data(), data.size(), {}, &cloud).status,
            CloudDecodeStatus::kXyzNotFloat32);

  layout = good;
  layout.fields[3].datatype = 42;
  result = decode_point_cloud(layout, data.data(), data.size(), {}, &cloud);
  EXPECT_EQ(result.status, CloudDecodeStatus::kUnknownFieldType);
  EXPECT_NE(result.message.find("'ring'"), std::string::npos) << result.message;
}

TEST(PointCloudFields, NonFinitePointsAreDroppedAndCounted) {
  std::vector<ReferencePoint> points = random_points(20, 7);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  points[0].x = nan;
  points[5].y = inf;
  points[19].z = -inf;
  const PointCloudLayout layout = scrambled_layout(20, 1, 0);
  const std::vector<uint8_t> data = encode(layout, points);
  DecodedCloud cloud;
  ASSERT_TRUE(decode_point_cloud(layout, data.data(), data.size(), {}, &cloud).ok());
  EXPECT_EQ(cloud.dropped_non_finite, 3);
  EXPECT_EQ(cloud.points_m.size(), 17u);
  EXPECT_EQ(cloud.colors.size(), 17u);
  EXPECT_EQ(cloud.points_m[0].x, points[1].x);
  EXPECT_EQ(cloud.colors[0].r, points[1].r);

  // An all-NaN cloud decodes to nothing, all counted.
  for (ReferencePoint& p : points) p.x = nan;
  const std::vector<uint8_t> nan_data = encode(layout, points);
  ASSERT_TRUE(decode_point_cloud(layout, nan_data.data(), nan_data.size(), {}, &cloud).ok());
  EXPECT_TRUE(cloud.points_m.empty());
  EXPECT_EQ(cloud.dropped_non_finite, 20);
}

TEST(PointCloudFields, EmptyCloudIsFine) {
  PointCloudLayout layout = scrambled_layout(0, 0, 0);
  DecodedCloud cloud;
  EXPECT_TRUE(decode_point_cloud(layout, nullptr, 0, {}, &cloud).ok());
  EXPECT_TRUE(cloud.points_m.empty());
}

// ---- Depth images ------------------------------------------------------------------------------

TEST(DepthImagePoints, UnprojectsMillimetresAndMetresWithColour) {
  const uint32_t width = 5, height = 4;
  CameraIntrinsics k;
  k.fx = 100.0;
  k.fy = 120.0;
  k.cx = 2.0;
  k.cy = 1.5;
  ImageLayout depth{width, height, width * 2 + 6, "16UC1", false};  // 6 bytes of row padding
  std::vector<uint8_t> depth_data(depth.step * height, 0);
  ImageLayout color{width, height, width * 3, "bgr8", false};
  std::vector<uint8_t> color_data(color.step * height);
  for (uint32_t v = 0; v < height; ++v) {
    for (uint32_t u = 0; u < width; ++u) {
      const uint16_t mm = (u == 1 && v == 2) ? 0 : static_cast<uint16_t>(1000 + 100 * u + 10 * v);
      std::memcpy(depth_data.data() + v * depth.step + 2 * u, &mm, 2);
      uint8_t* pixel = color_data.data() + v * color.step + 3 * u;
      pixel[0] = static_cast<uint8_t>(u);      // blue
      pixel[1] = static_cast<uint8_t>(v);      // green
      pixel[2] = static_cast<uint8_t>(u + v);  // red
    }
  }
  DepthPoints points;
  const std::string problem =
      depth_image_to_points(depth, depth_data.data(), depth_data.size(), k, &color,
                            color_data.data(), color_data.size(), {}, &points);
  ASSERT_EQ(problem, "");
  EXPECT_EQ(points.pixels_used, 20);
  EXPECT_EQ(points.pixels_invalid, 1);
  ASSERT_EQ(points.points_m.size(), 19u);
  ASSERT_EQ(points.colors.size(), 19u);
  size_t i = 0;
  for (uint32_t v = 0; v < height; ++v) {
    for (uint32_t u = 0; u < width; ++u) {
      if (u == 1 && v == 2) continue;
      const float z = (1000 + 100 * u + 10 * v) * 0.001f;
      EXPECT_NEAR(points.points_m[i].z, z, 1e-6);
      EXPECT_NEAR(points.points_m[i].x, (u - 2.0) * z / 100.0, 1e-6);
      EXPECT_NEAR(points.points_m[i].y, (v - 1.5) * z / 120.0, 1e-6);
      EXPECT_EQ(points.colors[i].r, u + v);
      EXPECT_EQ(points.colors[i].g, v);
      EXPECT_EQ(points.colors[i].b, u);
      ++i;
    }
  }

  // The same in metres, with NaN holes and a stride of 2.
  ImageLayout metres{width, height, width * 4, "32FC1", false};
  std::vector<float> values(width * height, 2.0f);
  values[0] = std::numeric_limits<float>::quiet_NaN();
  DepthToPointsOptions options;
  options.pixel_stride = 2;
  ASSERT_EQ(depth_image_to_points(metres, reinterpret_cast<const uint8_t*>(values.data()),
                                  values.size() * 4, k, nullptr, nullptr, 0, options, &points),
            "");
  EXPECT_EQ(points.pixels_used, 3 * 2);
  EXPECT_EQ(points.pixels_invalid, 1);
  EXPECT_EQ(points.points_m.size(), 5u);
  EXPECT_TRUE(points.colors.empty());
}

TEST(DepthImagePoints, BadImagesAreClearErrors) {
  CameraIntrinsics k;
  k.fx = k.fy = 100.0;
  ImageLayout depth{4, 4, 8, "16UC1", false};
  std::vector<uint8_t> data(32, 0);
  DepthPoints points;
  ImageLayout bad = depth;
  bad.encoding = "8UC3";
  EXPECT_NE(
      depth_image_to_points(bad, data.data(), data.size(), k, nullptr, nullptr, 0, {}, &points)
          .find("unsupported encoding '8UC3'"),
      std::string::npos);
  bad = depth;
  bad.step = 7;
  EXPECT_NE(
      depth_image_to_points(bad, data.data(), data.size(), k, nullptr, nullptr, 0, {}, &points)
          .find("step"),
      std::string::npos);
  EXPECT_NE(depth_image_to_points(depth, data.data(), 31, k, nullptr, nullptr, 0, {}, &points)
                .find("bytes"),
            std::string::npos);
  CameraIntrinsics zero;
  EXPECT_NE(
      depth_image_to_points(depth, data.data(), data.size(), zero, nullptr, nullptr, 0, {}, &points)
          .find("intrinsics"),
      std::string::npos);
  ImageLayout color{3, 4, 9, "rgb8", false};
  std::vector<uint8_t> color_data(36, 0);
  EXPECT_NE(depth_image_to_points(depth, data.data(), data.size(), k, &color, color_data.data(),
                                  color_data.size(), {}, &points)
                .find("registered"),
            std::string::npos);
  EXPECT_TRUE(points.points_m.empty());
}

}  // namespace
}  // namespace io
}  // namespace covox

// Per-point times of PointCloud2 clouds (io/point_times.h) through both decoders, the ROS layer's
// (decode_point_cloud) and the bag reader's (extract_points): Ouster's `t` in nanoseconds,
// Velodyne's `time` in seconds, an organised cloud's column order, none; the times of dropped
// (non-finite) points are dropped with them.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "covoxslam/io/pointcloud_fields.h"
#include "covoxslam/io/rosbag_messages.h"

namespace covox {
namespace io {
namespace {

// A cloud of `width` x `height` points at x = index, y = z = 0, 20 bytes each: x y z at 0 4 8,
// the time field (if any) at 12 as `datatype`, a spare 4 bytes at 16. Point index 2 is NaN.
struct TestCloud {
  PointCloudLayout layout;
  std::vector<uint8_t> data;
};
TestCloud make_cloud(uint32_t width, uint32_t height, const char* time_name, uint8_t datatype,
                     double units_per_point) {
  TestCloud cloud;
  cloud.layout.fields = {{"x", 0, kFloat32, 1}, {"y", 4, kFloat32, 1}, {"z", 8, kFloat32, 1}};
  if (time_name) cloud.layout.fields.push_back({time_name, 12, datatype, 1});
  cloud.layout.width = width;
  cloud.layout.height = height;
  cloud.layout.point_step = 20;
  cloud.layout.row_step = 20 * width;
  cloud.data.assign(size_t(20) * width * height, 0);
  for (uint32_t i = 0; i < width * height; ++i) {
    uint8_t* point = cloud.data.data() + size_t(20) * i;
    const float x = i == 2 ? NAN : static_cast<float>(i);
    std::memcpy(point, &x, 4);
    const double value = units_per_point * i;
    if (datatype == kUint32) {
      const uint32_t v = static_cast<uint32_t>(value);
      std::memcpy(point + 12, &v, 4);
    } else {
      const float v = static_cast<float>(value);
      std::memcpy(point + 12, &v, 4);
    }
  }
  return cloud;
}

rosbag::PointCloud2Message as_message(const TestCloud& cloud) {
  rosbag::PointCloud2Message message;
  for (const PointFieldDescription& field : cloud.layout.fields)
    message.fields.push_back({field.name, field.offset, field.datatype, field.count});
  message.width = cloud.layout.width;
  message.height = cloud.layout.height;
  message.point_step = cloud.layout.point_step;
  message.row_step = cloud.layout.row_step;
  message.data = cloud.data;
  return message;
}

// Both decoders' times for `cloud`, which must agree; returns them.
std::vector<float> decoded_times(const TestCloud& cloud, PointTimeSource expected_source) {
  DecodedCloud decoded;
  CloudDecodeOptions options;
  options.column_sweep_duration_s = 0.1;
  EXPECT_TRUE(
      decode_point_cloud(cloud.layout, cloud.data.data(), cloud.data.size(), options, &decoded)
          .ok());
  EXPECT_EQ(decoded.time_source, expected_source);
  const PointCloud extracted = rosbag::extract_points(as_message(cloud), "test", nullptr, 0.1);
  EXPECT_EQ(extracted.times_s, decoded.point_times_s);
  EXPECT_EQ(decoded.point_times_s.empty() ? 0 : decoded.points_m.size(),
            decoded.point_times_s.size());
  return decoded.point_times_s;
}

TEST(PointTimes, OusterNanosecondsField) {
  const std::vector<float> times =
      decoded_times(make_cloud(8, 1, "t", kUint32, 1e6), PointTimeSource::kNanosecondsField);
  ASSERT_EQ(times.size(), 7u);  // point 2 is NaN: dropped with its time
  EXPECT_FLOAT_EQ(times[0], 0.0f);
  EXPECT_FLOAT_EQ(times[2], 0.003f);  // point 3: 3 ms
  EXPECT_FLOAT_EQ(times[6], 0.007f);
}

TEST(PointTimes, VelodyneSecondsField) {
  const std::vector<float> times =
      decoded_times(make_cloud(8, 1, "time", kFloat32, -0.01), PointTimeSource::kSecondsField);
  ASSERT_EQ(times.size(), 7u);
  EXPECT_FLOAT_EQ(times[1], -0.01f);
  EXPECT_FLOAT_EQ(times[6], -0.07f);
}

TEST(PointTimes, OrganisedCloudWithoutFieldUsesTheColumnOrder) {
  const std::vector<float> times =
      decoded_times(make_cloud(4, 2, nullptr, kFloat32, 0.0), PointTimeSource::kColumnOrder);
  ASSERT_EQ(times.size(), 7u);
  // Columns 0 1 (2 is NaN) 3 of row 0, then 0 1 2 3 of row 1, over 0.1 s.
  const std::vector<float> expected = {0.0f, 0.025f, 0.075f, 0.0f, 0.025f, 0.05f, 0.075f};
  for (size_t i = 0; i < expected.size(); ++i) EXPECT_FLOAT_EQ(times[i], expected[i]) << i;
}

TEST(PointTimes, UnorganisedCloudWithoutFieldHasNone) {
  EXPECT_TRUE(
      decoded_times(make_cloud(8, 1, nullptr, kFloat32, 0.0), PointTimeSource::kNone).empty());
}

TEST(PointTimes, TimeFieldPastThePointStepIsRefused) {
  TestCloud cloud = make_cloud(8, 1, "t", kUint32, 1e6);
  cloud.layout.fields.back().offset = 18;  // 4 bytes from 18 pass the 20-byte point
  DecodedCloud decoded;
  EXPECT_FALSE(decode_point_cloud(cloud.layout, cloud.data.data(), cloud.data.size(),
                                  CloudDecodeOptions(), &decoded)
                   .ok());
  EXPECT_THROW(rosbag::extract_points(as_message(cloud), "test"), std::exception);
}

}  // namespace
}  // namespace io
}  // namespace covox

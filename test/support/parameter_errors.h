#pragma once
// Start-up checks of the SLAM parameters: a bad value must throw an error that names it.
#include <gtest/gtest.h>

#include <map>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/slam_parameters.h"

namespace covox {
namespace testing_support {

// Reads `values` into a default SlamConfig and expects a covox::Error whose message names `name`.
inline void expect_error_names(const std::map<std::string, std::string>& values,
                               const std::string& name) {
  pipeline::SlamConfig config;
  try {
    pipeline::read_slam_config(pipeline::TextParameterSource(values), &config);
    ADD_FAILURE() << "no error for " << name;
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find(name), std::string::npos) << error.what();
  }
}

}  // namespace testing_support
}  // namespace covox

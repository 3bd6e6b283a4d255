#pragma once
// The message of the covox::Error an action throws, for tests that check what a refusal says.
#include <string>

#include "covoxslam/core/error.h"

namespace covox {
namespace testing_support {

// The what() of the covox::Error that `action` throws; empty when it throws none.
template <class Action>
std::string error_message_of(Action action) {
  try {
    action();
  } catch (const Error& error) {
    return error.what();
  }
  return std::string();
}

}  // namespace testing_support
}  // namespace covox

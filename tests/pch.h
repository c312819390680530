// The headers most test units share, compiled once into a precompiled header
// that every kinemo_test() target reuses (CMakeLists.txt, KINEMO_TEST_PCH):
// parsing them was about a quarter of each test unit's compile time. Only
// system, third-party and generated headers belong here, never ours (a change
// to one would rebuild the precompiled header and so every test).
#pragma once

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <variant>
#include <vector>

// The generated messages and services (proto/).
#include "grpc/health/v1/health.grpc.pb.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "kinemo/coordinator/v1/allinone.pb.h"
#include "kinemo/coordinator/v1/options.pb.h"
#include "kinemo/studio/v1/studio.pb.h"

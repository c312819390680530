// The headers the service and integration tests share (gRPC, the generated
// protos, Eigen, OpenCV core, JSON, on top of tests/pch_base.h), compiled once
// into the precompiled header their kinemo_test() targets reuse
// (CMakeLists.txt, KINEMO_TEST_PCH): parsing them was about a quarter of each
// such unit's compile time. Unit tests reuse the smaller tests/pch_base.h.
// Only system, third-party and generated headers belong here, never ours (a
// change to one would rebuild the precompiled header and so every test).
#pragma once

#include "tests/pch_base.h"

#include <grpcpp/grpcpp.h>
#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

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

// What every test unit parses: GoogleTest, GoogleMock and the standard
// library, compiled once into the precompiled header the unit tests reuse
// (CMakeLists.txt, KINEMO_TEST_PCH; tests/pch.h adds gRPC, the generated
// protos and the rest for the service and integration tests). It stays small
// on purpose: GCC reads a precompiled header whole into every unit that uses
// it, 0.7 s for this one against 3 s for tests/pch.h, while most unit tests
// include no gRPC at all. Only system and third-party headers belong here.
#pragma once

#include <gmock/gmock.h>
#include <gtest/gtest.h>
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
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <variant>
#include <vector>

// Integration-test harness: start real binaries, wait until they are ready,
// stop exactly the processes that were started.
//
//   auto svc = ServiceProcess::Start({.binary = ProsodyBinary(), .args = {"--config", cfg}});
//   ASSERT_TRUE(svc.ok()) << svc.status();
//   auto stub = Prosody::NewStub((*svc)->Channel());
//
// The launching itself is common/process/process.h (kinemo_process, which the
// user binaries link too); this header gives the tests its names in
// kinemo::testing and adds what only tests need. kinemo_testing is built for
// tests only: no user executable may link it (cmake/kinemo_layout.cmake).
#pragma once

#include <string>

#include "common/process/process.h"

namespace kinemo::testing {

using process::ChildProcess;
using process::ServiceProcess;
using process::ServiceProcessOptions;
using process::WaitForPortFile;
using process::WaitForServing;

// A scratch directory named kinemo-test-XXXXXX, removed on destruction.
class TempDir : public process::TempDir {
 public:
  TempDir() : process::TempDir("kinemo-test") {}
};

// Path of a binary built in this CMake tree (KINEMO_BINARY_DIR), searched
// recursively by file name. Empty if not found.
std::string FindBuiltBinary(const std::string& binary_dir, const std::string& name);

}  // namespace kinemo::testing

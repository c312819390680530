// Clients in another language: Debian's python3 with python3-grpcio, and
// proto/ compiled to Python at test time (protoc with Debian's
// grpc_python_plugin). Tests skip when python3-grpcio is missing.
#pragma once

#include <string>
#include <vector>

#include "common/status/status.h"

namespace kinemo::testing {

inline constexpr const char* kPython = "/usr/bin/python3";  // Debian's, where python3-grpcio installs

// OK when `import grpc` works in kPython; otherwise the reason (for GTEST_SKIP).
Status PythonGrpcAvailable(const std::string& scratch_dir);

// Compiles every .proto under `<proto_root>/kinemo` into `out_dir` (created)
// as *_pb2.py and *_pb2_grpc.py modules, for `sys.path.insert(0, out_dir)`.
Status CompileProtosForPython(const std::string& proto_root, const std::string& out_dir);

// Runs `kPython script args...` to its end (at most 300 s); returns its exit
// code, with stdout+stderr in *output.
StatusOr<int> RunPython(const std::string& script, const std::vector<std::string>& args, const std::string& log_path,
                        std::string* output);

// The last line of `output` that starts with '{' (a script's JSON summary),
// or "".
std::string LastJsonLine(const std::string& output);

}  // namespace kinemo::testing

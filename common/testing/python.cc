#include "common/testing/python.h"

#include <chrono>
#include <filesystem>
#include <sstream>

#include "common/testing/process.h"

namespace kinemo::testing {
namespace {

namespace fs = std::filesystem;
constexpr const char* kProtoc = "/usr/bin/protoc";
constexpr const char* kPlugin = "/usr/bin/grpc_python_plugin";  // protobuf-compiler-grpc

}  // namespace

Status PythonGrpcAvailable(const std::string& scratch_dir) {
  std::string output;
  auto code = ChildProcess::Run({kPython, "-c", "import grpc"}, scratch_dir + "/python_probe.log",
                                std::chrono::seconds(60), &output);
  if (!code.ok()) return code.status();
  if (*code != 0) {
    return absl::FailedPreconditionError(
        kinemo::StrCat("python3-grpcio is not installed (deploy/install-deps.sh installs it): ", output));
  }
  return absl::OkStatus();
}

Status CompileProtosForPython(const std::string& proto_root, const std::string& out_dir) {
  if (!fs::exists(kPlugin)) return absl::FailedPreconditionError("grpc_python_plugin (protobuf-compiler-grpc) is missing");
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) return absl::InternalError(kinemo::StrCat(out_dir, ": ", ec.message()));
  std::vector<std::string> argv = {kProtoc, "-I" + proto_root, "--python_out=" + out_dir, "--grpc_python_out=" + out_dir,
                                   std::string("--plugin=protoc-gen-grpc_python=") + kPlugin};
  for (const auto& e : fs::recursive_directory_iterator(proto_root + "/kinemo")) {
    if (e.path().extension() == ".proto") argv.push_back(fs::relative(e.path(), proto_root).string());
  }
  std::string output;
  auto code = ChildProcess::Run(argv, out_dir + "/protoc.log", std::chrono::seconds(120), &output);
  if (!code.ok()) return code.status();
  if (*code != 0) return absl::InternalError(kinemo::StrCat("protoc exited with ", *code, ": ", output));
  return absl::OkStatus();
}

StatusOr<int> RunPython(const std::string& script, const std::vector<std::string>& args, const std::string& log_path,
                        std::string* output) {
  std::vector<std::string> argv = {kPython, script};
  argv.insert(argv.end(), args.begin(), args.end());
  return ChildProcess::Run(argv, log_path, std::chrono::seconds(300), output);
}

std::string LastJsonLine(const std::string& output) {
  std::string last;
  std::istringstream lines(output);
  for (std::string line; std::getline(lines, line);) {
    if (!line.empty() && line[0] == '{') last = line;
  }
  return last;
}

}  // namespace kinemo::testing

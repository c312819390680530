// A client in another language against real processes: proto/ is compiled to
// Python at test time (protoc with Debian's grpc_python_plugin) and Debian's
// python3-grpcio pushes a model through a coordinator in front of an
// inference service, lists it, and has a corrupt model refused
// (push_and_list.py).
#include <gtest/gtest.h>

#include <filesystem>

#include <nlohmann/json.hpp>

#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "tests/integration/stores/stores_fixture.h"

namespace kinemo::stores_test {
namespace {

namespace fs = std::filesystem;
using testing::ChildProcess;
using testing::ServiceProcess;

constexpr const char* kPython = "/usr/bin/python3";  // Debian's, where python3-grpcio installs
constexpr const char* kPlugin = "/usr/bin/grpc_python_plugin";
const std::string kSource = KINEMO_SOURCE_DIR;

// Runs argv to completion; returns the exit code, with the output in *log.
int RunToEnd(const std::vector<std::string>& argv, const std::string& log_path, std::string* log) {
  auto child = ChildProcess::Spawn(argv, log_path);
  if (!child.ok()) return -1;
  auto code = (*child)->WaitExit(std::chrono::seconds(120));
  *log = (*child)->ReadLog();
  return code.ok() ? *code : -1;
}

TEST(PythonClient, PushesAndListsAModelThroughTheCoordinator) {
  testing::TempDir dir;
  std::string log;
  if (RunToEnd({kPython, "-c", "import grpc"}, dir.File("probe.log"), &log) != 0) {
    GTEST_SKIP() << "python3-grpcio is not installed (deploy/install-deps.sh installs it): " << log;
  }
  ASSERT_TRUE(fs::exists(kPlugin)) << "grpc_python_plugin (protobuf-compiler-grpc) is missing";
  std::vector<std::string> protoc = {"/usr/bin/protoc", "-I" + kSource + "/proto", "--python_out=" + dir.File("gen"),
                                     "--grpc_python_out=" + dir.File("gen"),
                                     std::string("--plugin=protoc-gen-grpc_python=") + kPlugin};
  for (const auto& e : fs::recursive_directory_iterator(kSource + "/proto/kinemo")) {
    if (e.path().extension() == ".proto") protoc.push_back(fs::relative(e.path(), kSource + "/proto").string());
  }
  fs::create_directories(dir.File("gen"));
  ASSERT_EQ(RunToEnd(protoc, dir.File("protoc.log"), &log), 0) << log;

  auto corpus = TinyCorpus(dir.File("corpus"));
  ASSERT_TRUE(corpus.ok()) << corpus.status();
  ASSERT_TRUE(WriteTinyModel(*corpus, dir.File("tiny.kmodel"), "tiny").ok());
  std::ofstream(dir.File("inference.textproto")) << "store_dir: \"" << dir.File("store") << "\"\n";
  auto inference = ServiceProcess::Start({.binary = Binary("inference"),
                                          .args = {"--config", dir.File("inference.textproto")},
                                          .health_service = inference::v1::InferenceService::service_full_name()});
  ASSERT_TRUE(inference.ok()) << inference.status();
  std::ofstream(dir.File("coordinator.textproto"))
      << "services { inference { address: \"" << (*inference)->address() << "\" } }\n";
  auto coordinator = ServiceProcess::Start(
      {.binary = Binary("coordinator"), .args = {"--config", dir.File("coordinator.textproto")}});
  ASSERT_TRUE(coordinator.ok()) << coordinator.status();

  const int code = RunToEnd({kPython, kSource + "/tests/integration/stores/push_and_list.py", "--gen", dir.File("gen"),
                        "--server", (*coordinator)->address(), "--model", dir.File("tiny.kmodel"), "--id",
                        "from-python"},
                       dir.File("python.log"), &log);
  EXPECT_EQ(code, 0) << log;
  std::string last;  // the script's JSON line
  std::istringstream lines(log);
  for (std::string line; std::getline(lines, line);) {
    if (!line.empty() && line[0] == '{') last = line;
  }
  const auto result = nlohmann::json::parse(last, nullptr, false);
  ASSERT_FALSE(result.is_discarded()) << log;
  EXPECT_EQ(result["ids"], nlohmann::json::array({"from-python"}));
  // What the Python client saw is what the service holds.
  EXPECT_TRUE(fs::exists(dir.File("store") + "/models/from-python/1/model.kmodel"));
  EXPECT_FALSE(fs::exists(dir.File("store") + "/models/corrupt"));
}

}  // namespace
}  // namespace kinemo::stores_test

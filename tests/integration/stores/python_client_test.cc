// A client in another language against real processes: proto/ is compiled to
// Python at test time (protoc with Debian's grpc_python_plugin) and Debian's
// python3-grpcio pushes a model through a coordinator in front of an
// inference service, lists it, and has a corrupt model refused
// (push_and_list.py).
#include <gtest/gtest.h>

#include <filesystem>

#include <nlohmann/json.hpp>

#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "common/testing/python.h"
#include "tests/integration/stores/stores_fixture.h"

namespace kinemo::stores_test {
namespace {

namespace fs = std::filesystem;
using testing::ServiceProcess;

const std::string kSource = KINEMO_SOURCE_DIR;

TEST(PythonClient, PushesAndListsAModelThroughTheCoordinator) {
  testing::TempDir dir;
  if (Status available = testing::PythonGrpcAvailable(dir.path()); !available.ok()) {
    GTEST_SKIP() << available.message();
  }
  ASSERT_TRUE(testing::CompileProtosForPython(kSource + "/proto", dir.File("gen")).ok());

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

  std::string log;
  auto code = testing::RunPython(kSource + "/tests/integration/stores/push_and_list.py",
                                 {"--gen", dir.File("gen"), "--server", (*coordinator)->address(), "--model",
                                  dir.File("tiny.kmodel"), "--id", "from-python"},
                                 dir.File("python.log"), &log);
  ASSERT_TRUE(code.ok()) << code.status();
  EXPECT_EQ(*code, 0) << log;
  const std::string last = testing::LastJsonLine(log);  // the script's JSON line
  const auto result = nlohmann::json::parse(last, nullptr, false);
  ASSERT_FALSE(result.is_discarded()) << log;
  EXPECT_EQ(result["ids"], nlohmann::json::array({"from-python"}));
  // What the Python client saw is what the service holds.
  EXPECT_TRUE(fs::exists(dir.File("store") + "/models/from-python/1/model.kmodel"));
  EXPECT_FALSE(fs::exists(dir.File("store") + "/models/corrupt"));
}

}  // namespace
}  // namespace kinemo::stores_test

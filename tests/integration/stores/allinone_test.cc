// kinemo_allinone on one address, with the real binary: every service is
// served there (health per service name, no other listening socket), the CLI
// trains a model on it (`crf train --server`) and pushes one (`model push`),
// and after a restart on the same store both are listed and usable.
#include <gtest/gtest.h>

#include <filesystem>
#include <set>

#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "tests/integration/stores/stores_fixture.h"

namespace kinemo::stores_test {
namespace {

namespace fs = std::filesystem;
using testing::ServiceProcess;

std::unique_ptr<grpc::ClientContext> Ctx(int seconds = 60) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  return c;
}

// TCP sockets of process `pid` in the LISTEN state.
int ListeningSockets(pid_t pid) {
  std::set<std::string> inodes;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/proc/" + std::to_string(pid) + "/fd", ec)) {
    const std::string target = fs::read_symlink(e.path(), ec).string();
    if (target.rfind("socket:[", 0) == 0) inodes.insert(target.substr(8, target.size() - 9));
  }
  int listening = 0;
  for (const char* table : {"/proc/net/tcp", "/proc/net/tcp6"}) {
    std::ifstream in(table);
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
      std::istringstream row(line);
      std::string sl, local, remote, state, queues, timer, retransmit, uid, timeout, inode;
      row >> sl >> local >> remote >> state >> queues >> timer >> retransmit >> uid >> timeout >> inode;
      if (state == "0A" && inodes.count(inode) != 0) ++listening;
    }
  }
  return listening;
}

TEST(AllInOne, OneAddressServesEveryServiceAndKeepsItsStore) {
  testing::TempDir dir;
  auto corpus = TinyCorpus(dir.File("corpus"));
  ASSERT_TRUE(corpus.ok()) << corpus.status();
  ASSERT_TRUE(WriteTinyModel(*corpus, dir.File("tiny.kmodel"), "tiny").ok());
  std::ofstream(dir.File("allinone.textproto"))
      << "store_dir: \"" << dir.File("store") << "\"\n"
      << "seed_store_dir: \"" << dir.File("no-seed") << "\"\n";
  const testing::ServiceProcessOptions options{.binary = Binary("kinemo_allinone"),
                                               .args = {"--config", dir.File("allinone.textproto")}};
  std::string out, err;
  {
    auto stack = ServiceProcess::Start(options);
    ASSERT_TRUE(stack.ok()) << stack.status();
    const std::string address = (*stack)->address();
    for (const std::string name :
         {coordinator::v1::CoordinatorService::service_full_name(), prosody::v1::ProsodyService::service_full_name(),
          inference::v1::InferenceService::service_full_name(), planner::v1::PlannerService::service_full_name(),
          cube_tracker::v1::CubeTrackerService::service_full_name()}) {
      const Status serving = testing::WaitForServing((*stack)->Channel(), name, std::chrono::seconds(10));
      EXPECT_TRUE(serving.ok()) << name << ": " << serving;
    }
    // One listening socket: no internal port beside the public one.
    EXPECT_EQ(ListeningSockets((*stack)->process().pid()), 1);
    // No robots configured: the bridge is not there.
    robot_bridge::v1::ListRobotsResponse robots;
    EXPECT_EQ(robot_bridge::v1::RobotBridgeService::NewStub((*stack)->Channel())
                  ->ListRobots(Ctx().get(), robot_bridge::v1::ListRobotsRequest(), &robots)
                  .error_code(),
              grpc::StatusCode::UNIMPLEMENTED);

    // Server-side training from the CLI (the corpus goes inline), and a push.
    ASSERT_EQ((RunKinemo({"crf", "train", "--corpus", dir.File("corpus"), "--states", "3", "--window", "2",
                          "--clusters", "3", "--restarts", "1", "--server", address, "--id", "trained", "--json"},
                         &out, &err)),
              0)
        << err;
    EXPECT_EQ(nlohmann::json::parse(out)["model_id"], "trained");
    EXPECT_NE(err.find("train: crf_optimize"), std::string::npos) << err;
    ASSERT_EQ((RunKinemo({"model", "push", dir.File("tiny.kmodel"), "--id", "pushed", "--server", address}, &out,
                         &err)),
              0)
        << err;
    EXPECT_EQ(*(*stack)->Stop(), 0);
  }
  // The store layout is the documented one.
  EXPECT_TRUE(fs::exists(dir.File("store") + "/models/trained/1/model.kmodel"));
  EXPECT_TRUE(fs::exists(dir.File("store") + "/models/pushed/1/artifact.json"));

  auto stack = ServiceProcess::Start(options);
  ASSERT_TRUE(stack.ok()) << stack.status();
  ASSERT_EQ((RunKinemo({"model", "ls", "--server", (*stack)->address(), "--json"}, &out, &err)), 0) << err;
  const auto listed = nlohmann::json::parse(out);
  ASSERT_EQ(listed.size(), 2u) << out;
  EXPECT_EQ(listed[0]["ref"]["id"], "pushed");
  EXPECT_EQ(listed[1]["ref"]["id"], "trained");
  ASSERT_EQ((RunKinemo({"artifacts", "ls", "--server", (*stack)->address()}, &out, &err)), 0) << err;
  EXPECT_NE(out.find("models/pushed"), std::string::npos) << out;
  EXPECT_NE(out.find("models/trained"), std::string::npos) << out;

  for (const std::string id : {"pushed", "trained"}) {
    inference::v1::InferRequest req;
    req.set_model_id(id);
    *req.mutable_inputs() = inference::ToProto((*corpus)[1]).inputs();
    inference::v1::InferResponse resp;
    const grpc::Status s =
        inference::v1::InferenceService::NewStub((*stack)->Channel())->Infer(Ctx().get(), req, &resp);
    ASSERT_TRUE(s.ok()) << id << ": " << s.error_message();
    EXPECT_EQ(resp.model().model_id(), id);
  }
  // The coordinator answers on the same address.
  coordinator::v1::ListSessionsResponse sessions;
  EXPECT_TRUE(coordinator::v1::CoordinatorService::NewStub((*stack)->Channel())
                  ->ListSessions(Ctx().get(), coordinator::v1::ListSessionsRequest(), &sessions)
                  .ok());
  EXPECT_EQ(*(*stack)->Stop(), 0);
}

}  // namespace
}  // namespace kinemo::stores_test

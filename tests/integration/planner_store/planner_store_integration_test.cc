// The real `planner` binary with a store_dir on an ephemeral loopback port:
// a library (real Bandai clips sent inline), a controller, a gesture graph and
// a locomotion graph built over gRPC come back after a restart under the same
// ids and versions and work. Then the `kinemo` CLI as a user runs it: library
// push, ls, a controller built locally (`crf corpus`, `crf train`,
// `controller build`) and pushed with its library, a refused deletion, and a
// server-side `controller build --server` with the model of a real
// `inference` process.
#include <fstream>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/testing/process.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "tests/service/planner_store/planner_store_util.h"
#include "tests/unit/planner_controller/test_util.h"

namespace kinemo::planner {
namespace {

using namespace store_test;  // NOLINT
using kinemo::testing::ServiceProcess;
using Json = nlohmann::json;

const std::string kKinemo = std::string(KINEMO_BINARY_DIR) + "/services/cli/kinemo";

StatusOr<std::unique_ptr<ServiceProcess>> StartPlanner(const std::string& config) {
  return ServiceProcess::Start({.binary = kinemo::testing::FindBuiltBinary(KINEMO_BINARY_DIR, "planner"),
                                .args = {"--config", config},
                                .health_service = v1::PlannerService::service_full_name()});
}

TEST(PlannerBinary, ArtifactsComeBackAfterARestart) {
  kinemo::testing::TempDir dir;
  const std::string config = dir.File("planner.textproto");
  std::ofstream(config) << "store_dir: \"" << dir.File("store") << "\"\n";
  auto planner = StartPlanner(config);
  ASSERT_TRUE(planner.ok()) << planner.status();
  auto stub = v1::PlannerService::NewStub((*planner)->Channel());

  v1::LoadLibraryRequest gestures;
  gestures.set_library_id("gestures");
  AddControllerClips(&gestures);
  v1::LoadLibraryResponse loaded;
  grpc::Status s = stub->LoadLibrary(Ctx().get(), gestures, &loaded);
  ASSERT_TRUE(s.ok()) << s.error_message();

  const auto model = controller::testing::FitStateModel(*controller::testing::TestLibrary(), 3);
  v1::BuildControllerRequest build;
  build.set_controller_id("ctl");
  build.set_library_id("gestures");
  build.set_inference_model_id("fitted");
  *build.mutable_state_model() = controller::testing::StateModelProto(model);
  {
    auto ctx = Ctx();
    auto reader = stub->BuildController(ctx.get(), build);
    v1::BuildControllerResponse msg;
    while (reader->Read(&msg)) {
    }
    s = reader->Finish();
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  v1::BuildGestureGraphRequest gmg;
  gmg.set_graph_id("gmg");
  gmg.set_library_id("gestures");
  gmg.mutable_params()->set_stroke_phrases(true);
  v1::BuildGestureGraphResponse gmg_built;
  s = stub->BuildGestureGraph(Ctx().get(), gmg, &gmg_built);
  ASSERT_TRUE(s.ok()) << s.error_message();

  v1::LoadLibraryRequest walks;
  walks.set_library_id("walks");
  for (const char* clip : {"dataset-1_walk_normal_001", "dataset-1_run_active_001"}) {
    auto* c = walks.add_clips();
    c->set_name(clip);
    c->set_bvh(ReadFile(kData + "/planner_locomotion/" + clip + ".bvh"));
  }
  s = stub->LoadLibrary(Ctx().get(), walks, &loaded);
  ASSERT_TRUE(s.ok()) << s.error_message();
  v1::BuildLocomotionGraphRequest loco;
  loco.set_graph_id("loco");
  loco.set_library_id("walks");
  loco.mutable_profile()->set_name("SMG");
  loco.mutable_params()->set_threshold(0.8);
  v1::BuildLocomotionGraphResponse loco_built;
  s = stub->BuildLocomotionGraph(Ctx().get(), loco, &loco_built);
  ASSERT_TRUE(s.ok()) << s.error_message();

  // Sorted by kind, id, version.
  const std::vector<std::string> stored = {"controllers/ctl/1", "gesture_graphs/gmg/1", "libraries/gestures/1",
                                           "libraries/walks/1", "locomotion_graphs/loco/1"};
  EXPECT_EQ(Refs(List(stub.get())), stored);
  v1::SynthesizeResponse before;
  ASSERT_TRUE(Synthesize(stub.get(), "ctl", 3, &before).ok());
  v1::PlanTransitionRequest plan;
  plan.set_graph_id("loco");
  plan.set_from_clip("dataset-1_walk_normal_001");
  plan.set_from_frame(10);
  plan.set_to_clip("dataset-1_run_active_001");
  plan.set_metrics_only(true);
  v1::PlanTransitionResponse planned_before;
  s = stub->PlanTransition(Ctx().get(), plan, &planned_before);
  ASSERT_TRUE(s.ok()) << s.error_message();

  stub.reset();  // an open client channel holds the server's shutdown for its grace period
  auto code = (*planner)->Stop();
  ASSERT_TRUE(code.ok()) << code.status();
  EXPECT_EQ(*code, 0);

  auto again = StartPlanner(config);
  ASSERT_TRUE(again.ok()) << again.status();
  stub = v1::PlannerService::NewStub((*again)->Channel());
  const auto list = List(stub.get());
  EXPECT_FALSE(list.in_memory());
  EXPECT_EQ(Refs(list), stored);

  // The controller: the same decisions as before the restart.
  v1::SynthesizeResponse after;
  s = Synthesize(stub.get(), "ctl", 3, &after);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(after.motion().bvh(), before.motion().bvh());
  ASSERT_EQ(after.segments_size(), before.segments_size());
  // The gesture graph, rebuilt from its recipe: the same graph.
  v1::SynthesizeGesturesResponse motion;
  s = SynthesizeGestures(stub.get(), "gmg", &motion);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_GT(motion.report_size(), 0);
  const Json gmg_summary = Json::parse(list.artifacts(1).summary_json());
  EXPECT_EQ(gmg_summary["stats"]["scc_size"].get<uint32_t>(), gmg_built.graph().stats().scc_size());
  // The locomotion graph, rebuilt from its recipe: the same transition.
  v1::PlanTransitionResponse planned;
  s = stub->PlanTransition(Ctx().get(), plan, &planned);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(planned.tbf_frames(), planned_before.tbf_frames());
  EXPECT_DOUBLE_EQ(planned.cost(), planned_before.cost());
  stub.reset();
  EXPECT_EQ(*(*again)->Stop(), 0);
}

// `kinemo` against a planner with a store of its own: run(ARGS, &out) runs
// `kinemo ARGS...` and returns its exit code, its output (stdout and stderr)
// in out.
class KinemoCli : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string config = dir.File("planner.textproto");
    std::ofstream(config) << "store_dir: \"" << dir.File("store") << "\"\n";
    auto started = StartPlanner(config);
    ASSERT_TRUE(started.ok()) << started.status();
    planner = std::move(*started);
    server = planner->address();
  }
  int run(std::vector<std::string> args, std::string* out) {
    args.insert(args.begin(), kKinemo);
    auto rc = kinemo::testing::ChildProcess::Run(args, dir.File("cli" + std::to_string(runs++) + ".log"),
                                                 std::chrono::minutes(5), out);
    EXPECT_TRUE(rc.ok()) << rc.status();
    return rc.ok() ? *rc : -1;
  }
  kinemo::testing::TempDir dir;
  std::unique_ptr<ServiceProcess> planner;
  std::string server;
  int runs = 0;
};

TEST_F(KinemoCli, LibraryPushListAndControllerPushAndServerBuild) {
  std::string out;
  const std::string manifest = kData + "/planner_controller/manifest.json";
  ASSERT_EQ(run({"library", "push", manifest, "--id", "gestures", "--server", server}, &out), 0) << out;
  EXPECT_NE(out.find("stored libraries/gestures/1"), std::string::npos) << out;
  ASSERT_EQ(run({"library", "ls", "--json", "--server", server}, &out), 0) << out;
  Json listed = Json::parse(out);
  ASSERT_EQ(listed.size(), 1u);
  EXPECT_EQ(listed[0]["ref"]["id"], "gestures");
  EXPECT_EQ(listed[0]["ref"]["version"], 1);
  EXPECT_EQ(Json::parse(listed[0]["summary_json"].get<std::string>())["clips"], 7);

  // A controller built locally, as a user does, on the same manifest.
  const std::string speech = kData + "/speech/";
  ASSERT_EQ(run({"crf", "corpus", "--out", dir.File("corpora/tiny"), "--speech",
                 speech + "sense_and_sensibility_01_austen_64kb-0880.wav",
                 speech + "sense_and_sensibility_01_austen_64kb-0930.wav", "--gestures",
                 kData + "/planner_controller/dataset-1_bye_normal_001.bvh",
                 kData + "/planner_controller/dataset-1_bow_normal_001.bvh", "--renditions", "3"},
                &out),
            0)
      << out;
  ASSERT_EQ(run({"crf", "train", "--corpus", dir.File("corpora/tiny"), "--states", "3", "--window", "2", "--clusters",
                 "3", "--restarts", "2", "--out", dir.File("tiny.kmodel")},
                &out),
            0)
      << out;
  ASSERT_EQ(run({"controller", "build", "--library", manifest, "--model", dir.File("tiny.kmodel"), "--out",
                 dir.File("ctl.kctrl")},
                &out),
            0)
      << out;
  ASSERT_EQ(run({"controller", "push", dir.File("ctl.kctrl"), "--id", "ctl", "--library", "gestures", "--server",
                 server},
                &out),
            0)
      << out;
  EXPECT_NE(out.find("stored controllers/ctl/1 (1 files"), std::string::npos) << out;
  EXPECT_NE(out.find("on libraries/gestures/1"), std::string::npos) << out;
  ASSERT_EQ(run({"controller", "ls", "--json", "--server", server}, &out), 0) << out;
  listed = Json::parse(out);
  ASSERT_EQ(listed.size(), 1u);
  EXPECT_EQ(listed[0]["ref"]["id"], "ctl");
  EXPECT_EQ(listed[0]["depends_on"][0]["id"], "gestures");
  // Pushed again without --overwrite: refused, exit 2.
  EXPECT_EQ(run({"controller", "push", dir.File("ctl.kctrl"), "--id", "ctl", "--library", "gestures", "--server",
                 server},
                &out),
            2)
      << out;
  // The library is in use.
  EXPECT_EQ(run({"library", "rm", "gestures", "--server", server}, &out), 2) << out;
  EXPECT_NE(out.find("controllers/ctl/1"), std::string::npos) << out;

  // Server-side build: the model from a real inference process.
  const std::string inference_config = dir.File("inference.textproto");
  std::ofstream(inference_config) << "model_dir: \"" << dir.File("models") << "\"\n"
                                  << "corpus_root: \"" << dir.File("corpora") << "\"\n"
                                  << "defaults { num_states: 3 window: 2 num_clusters: 3 hmm_restarts: 2 }\n";
  auto inference = ServiceProcess::Start({.binary = kinemo::testing::FindBuiltBinary(KINEMO_BINARY_DIR, "inference"),
                                          .args = {"--config", inference_config},
                                          .health_service = inference::v1::InferenceService::service_full_name()});
  ASSERT_TRUE(inference.ok()) << inference.status();
  {
    auto istub = inference::v1::InferenceService::NewStub((*inference)->Channel());
    inference::v1::TrainRequest train;
    train.set_model_id("tiny");
    train.set_corpus_dir("tiny");
    auto ctx = Ctx();
    auto reader = istub->Train(ctx.get(), train);
    inference::v1::TrainResponse msg;
    while (reader->Read(&msg)) {
    }
    const grpc::Status s = reader->Finish();
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  ASSERT_EQ(run({"controller", "build", "--server", server, "--inference-server", (*inference)->address(),
                 "--library-id", "gestures", "--model-id", "tiny", "--id", "built", "--json"},
                &out),
            0)
      << out;
  EXPECT_NE(out.find("kinemo controller build: value_iteration"), std::string::npos) << out;  // progress
  const Json info = Json::parse(out.substr(out.find('{')));
  EXPECT_EQ(info["controller_id"], "built");
  EXPECT_EQ(info["version"], 1);
  EXPECT_EQ(info["library_id"], "gestures");
  EXPECT_EQ(info["num_states"], 3);
  EXPECT_EQ(info["inference_model_id"], "tiny");
  // An unknown model is bad input, named.
  EXPECT_EQ(run({"controller", "build", "--server", server, "--inference-server", (*inference)->address(),
                 "--library-id", "gestures", "--model-id", "nope", "--id", "x"},
                &out),
            2)
      << out;
  EXPECT_NE(out.find("--model-id"), std::string::npos) << out;

  // Clean up through the CLI: controllers first, then the library.
  ASSERT_EQ(run({"controller", "rm", "ctl", "--server", server}, &out), 0) << out;
  ASSERT_EQ(run({"controller", "rm", "built@1", "--server", server}, &out), 0) << out;
  EXPECT_NE(out.find("deleted controllers/built/1"), std::string::npos) << out;
  ASSERT_EQ(run({"library", "rm", "gestures", "--server", server}, &out), 0) << out;
  ASSERT_EQ(run({"library", "ls", "--json", "--server", server}, &out), 0) << out;
  EXPECT_EQ(Json::parse(out).size(), 0u);
  EXPECT_EQ(*(*inference)->Stop(), 0);
  EXPECT_EQ(*planner->Stop(), 0);
}

// kinemo rig push | ls | rm: the user's characters as the planner's "rigs"
// artifacts (what Animate answers on with models.rig_id), through the CLI.
TEST_F(KinemoCli, RigPushListAndRemove) {
  const std::string man = kData + "/characters/quaternius_man_casual.glb";
  const std::string woman = kData + "/characters/quaternius_woman_casual.glb";
  std::string out;
  // The id defaults to the file's stem.
  ASSERT_EQ(run({"rig", "push", man, "--server", server}, &out), 0) << out;
  EXPECT_NE(out.find("stored rigs/quaternius_man_casual version 1"), std::string::npos) << out;
  // --name, --json: the stored version's ArtifactInfo, with the rig's summary.
  ASSERT_EQ(run({"rig", "push", man, "--name", "me", "--json", "--server", server}, &out), 0) << out;
  const Json info = Json::parse(out.substr(out.find('{')));
  EXPECT_EQ(info["ref"]["kind"], "rigs");
  EXPECT_EQ(info["ref"]["id"], "me");
  EXPECT_EQ(info["ref"]["version"], 1);
  const Json summary = Json::parse(info["summary_json"].get<std::string>());
  EXPECT_EQ(summary["family"], "quaternius");
  EXPECT_GT(summary["joints"].get<int>(), 20);
  // The same id again: refused without --overwrite, a new version with it.
  EXPECT_EQ(run({"rig", "push", woman, "--name", "me", "--server", server}, &out), 2) << out;
  EXPECT_NE(out.find("set overwrite for a new version"), std::string::npos) << out;
  ASSERT_EQ(run({"rig", "push", woman, "--name", "me", "--overwrite", "--server", server}, &out), 0) << out;
  EXPECT_NE(out.find("stored rigs/me version 2"), std::string::npos) << out;
  // Not a character file: refused before any call, naming the argument.
  EXPECT_EQ(run({"rig", "push", kData + "/planner_gesture/dataset-1_guide_normal_001.bvh", "--server", server}, &out),
            2)
      << out;
  EXPECT_NE(out.find("must end in .glb or .vrm"), std::string::npos) << out;
  ASSERT_EQ(run({"rig", "ls", "--json", "--server", server}, &out), 0) << out;
  Json listed = Json::parse(out);
  ASSERT_EQ(listed.size(), 2u) << out;
  EXPECT_EQ(listed[0]["ref"]["id"], "me");
  EXPECT_EQ(listed[0]["ref"]["version"], 2);
  EXPECT_EQ(listed[1]["ref"]["id"], "quaternius_man_casual");
  ASSERT_EQ(run({"rig", "ls", "--all", "--json", "--server", server}, &out), 0) << out;
  EXPECT_EQ(Json::parse(out).size(), 3u) << out;
  // One version, then the rest; a third rm finds nothing (exit 2, named).
  ASSERT_EQ(run({"rig", "rm", "me@1", "--server", server}, &out), 0) << out;
  EXPECT_NE(out.find("deleted rigs/me version 1"), std::string::npos) << out;
  ASSERT_EQ(run({"rig", "rm", "me", "--server", server}, &out), 0) << out;
  EXPECT_NE(out.find("deleted rigs/me version 2"), std::string::npos) << out;
  EXPECT_EQ(run({"rig", "rm", "me", "--server", server}, &out), 2) << out;
  EXPECT_NE(out.find("no rigs 'me'"), std::string::npos) << out;
  ASSERT_EQ(run({"rig", "ls", "--json", "--server", server}, &out), 0) << out;
  listed = Json::parse(out);
  ASSERT_EQ(listed.size(), 1u) << out;
  EXPECT_EQ(listed[0]["ref"]["id"], "quaternius_man_casual");
  EXPECT_EQ(*planner->Stop(), 0);
}

}  // namespace
}  // namespace kinemo::planner

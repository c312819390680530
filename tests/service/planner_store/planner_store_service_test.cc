// The planner's artifact store over real gRPC (in-process server, the store
// in a temporary folder, the service re-created on it for "restarts"):
// chunked pushes of real Bandai clips (tests/data), a controller file pushed
// with its library, bad pushes that store nothing, deletions refused while a
// dependent exists, the previous version served after a deletion, seeding,
// preloads that only seed, in-memory listings, corrupt artifacts skipped.
#include <filesystem>
#include <fstream>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/server/service_host.h"
#include "common/testing/process.h"
#include "services/planner/rpc/planner_service.h"
#include "tests/service/planner_store/planner_store_util.h"
#include "tests/unit/planner_controller/test_util.h"

namespace kinemo::planner {
namespace {

namespace fs = std::filesystem;
using namespace store_test;  // NOLINT

class PlannerStoreTest : public ::testing::Test {
 protected:
  // Creates the service on `options` (store_dir = store() unless set) and
  // serves it in process.
  void Start(v1::PlannerOptions options, bool with_store = true) {
    if (with_store && options.store_dir().empty()) options.set_store_dir(store());
    options.set_library_root(kData);
    auto svc = PlannerServiceImpl::Create(options);
    ASSERT_TRUE(svc.ok()) << svc.status();
    common::v1::ServerOptions so;
    so.set_host("127.0.0.1");
    so.set_port(0);
    so.set_shutdown_grace_s(1);
    auto host = server::ServiceHost::Start(so, "planner-store-test", {{*svc, v1::PlannerService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = *std::move(host);
    stub_ = v1::PlannerService::NewStub(host_->InProcessChannel());
  }
  void Start() { Start(v1::PlannerOptions()); }
  // Shuts the server down and destroys the service.
  void Stop() {
    stub_.reset();
    if (host_) host_->Shutdown();
    host_.reset();
  }
  void Restart() {
    Stop();
    Start();
  }
  void TearDown() override { Stop(); }

  std::string store() const { return dir_.File("store"); }

  grpc::Status LoadLibrary(const std::string& id, const std::vector<std::string>& clip_files, bool overwrite,
                           v1::LoadLibraryResponse* resp = nullptr) {
    v1::LoadLibraryRequest req;
    req.set_library_id(id);
    req.set_overwrite(overwrite);
    for (const auto& f : clip_files) {
      auto* c = req.add_clips();
      c->set_name(fs::path(f).stem().string());
      c->set_bvh(ReadFile(kData + "/" + f));
    }
    v1::LoadLibraryResponse ignored;
    auto ctx = Ctx();
    return stub_->LoadLibrary(ctx.get(), req, resp != nullptr ? resp : &ignored);
  }

  grpc::Status BuildGraph(const std::string& id, const std::string& library_id,
                          v1::BuildGestureGraphResponse* resp = nullptr) {
    v1::BuildGestureGraphRequest req;
    req.set_graph_id(id);
    req.set_library_id(library_id);
    v1::BuildGestureGraphResponse ignored;
    auto ctx = Ctx();
    return stub_->BuildGestureGraph(ctx.get(), req, resp != nullptr ? resp : &ignored);
  }

  grpc::Status BuildController(const std::string& id, const std::string& library_id, bool overwrite = false) {
    v1::BuildControllerRequest req;
    req.set_controller_id(id);
    req.set_library_id(library_id);
    req.set_overwrite(overwrite);
    *req.mutable_state_model() = controller::testing::StateModelProto(Model());
    auto ctx = Ctx();
    auto reader = stub_->BuildController(ctx.get(), req);
    v1::BuildControllerResponse msg;
    while (reader->Read(&msg)) {
    }
    return reader->Finish();
  }

  // A 3-state model fitted to the test library's own segments.
  static const controller::StateModel& Model() {
    static const controller::StateModel m =
        controller::testing::FitStateModel(*controller::testing::TestLibrary(), 3);
    return m;
  }

  // The library of an artifact version's depends_on ("libraries/id/v").
  static std::string DependsOn(const cv1::ListArtifactsResponse& list, const std::string& id) {
    for (const auto& a : list.artifacts()) {
      if (a.ref().id() == id && a.depends_on_size() == 1) {
        const auto& d = a.depends_on(0);
        return d.kind() + "/" + d.id() + "/" + std::to_string(d.version());
      }
    }
    return "";
  }

  // Nothing half-written is left in the store.
  void ExpectNoDrafts() {
    std::error_code ec;
    EXPECT_TRUE(fs::is_empty(store() + "/.staging", ec)) << "drafts left in " << store() << "/.staging";
  }

  kinemo::testing::TempDir dir_;
  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::PlannerService::Stub> stub_;
};

TEST_F(PlannerStoreTest, LibraryPushedInChunksIsStoredWithItsManifestAndServedAfterARestart) {
  Start();
  cv1::PushArtifactResponse pushed;
  // 8 KiB chunks: ~120 messages for the 7 clips.
  grpc::Status s = Push(stub_.get(), "libraries", "gestures", ControllerLibraryFiles(), {}, &pushed, 8 << 10);
  ASSERT_TRUE(s.ok()) << s.error_message();
  const cv1::ArtifactInfo& a = pushed.artifact();
  EXPECT_EQ(a.ref().version(), 1u);
  ASSERT_EQ(a.files_size(), 8);  // the stored layout: manifest.json + clips/<name>.bvh
  EXPECT_EQ(a.files(0).name(), "clips/dataset-1_bow_normal_001.bvh");
  EXPECT_EQ(a.files(7).name(), "manifest.json");
  const auto summary = nlohmann::json::parse(a.summary_json());
  EXPECT_EQ(summary["clips"], 7);
  EXPECT_EQ(summary["keywords"], nlohmann::json({"bow", "bye", "this"}));
  EXPECT_EQ(summary["tones"], nlohmann::json({"energetic", "neutral", "subdued"}));

  // The same clips without a manifest: every .bvh, named by its file.
  std::vector<PushFile> bare;
  for (const auto& f : ControllerLibraryFiles()) {
    if (f.name != "manifest.json") bare.push_back({"more/" + f.name, f.bytes});
  }
  ASSERT_TRUE(Push(stub_.get(), "libraries", "bare", bare, {}, &pushed).ok());
  EXPECT_EQ(nlohmann::json::parse(pushed.artifact().summary_json())["keywords"], nlohmann::json::array());

  // Served: a graph builds on it, then everything survives a restart.
  ASSERT_TRUE(BuildGraph("g", "gestures").ok());
  Restart();
  EXPECT_EQ(Refs(List(stub_.get())), (std::vector<std::string>{"gesture_graphs/g/1", "libraries/bare/1",
                                                               "libraries/gestures/1"}));
  v1::SynthesizeGesturesResponse motion;
  s = SynthesizeGestures(stub_.get(), "g", &motion);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_FALSE(motion.motion().bvh().empty());
  ASSERT_TRUE(BuildGraph("g2", "gestures").ok());
  EXPECT_EQ(DependsOn(List(stub_.get(), "gesture_graphs"), "g2"), "libraries/gestures/1");
  ExpectNoDrafts();
}

TEST_F(PlannerStoreTest, ControllerFilePushedWithItsLibraryIsValidatedAgainstIt) {
  // A controller file as `kinemo controller build --out` writes it: built on
  // the manifest's clips, recording the client's paths.
  auto lib = controller::testing::TestLibrary();
  controller::BuildReport report;
  auto built = controller::Controller::Build(lib, Model(), {}, nullptr, &report);
  ASSERT_TRUE(built.ok()) << built.status();
  const std::string file = dir_.File("built.kctrl");
  ASSERT_TRUE((*built)->Save(file, {controller::testing::DataDir() + "/manifest.json"}).ok());
  const std::string bytes = ReadFile(file);

  Start();
  cv1::PushArtifactResponse pushed;
  ASSERT_TRUE(Push(stub_.get(), "libraries", "gestures", ControllerLibraryFiles(), {}, &pushed).ok());
  grpc::Status s = Push(stub_.get(), "controllers", "ctl", {{"built.kctrl", bytes}}, {Ref("libraries", "gestures")},
                        &pushed, 64 << 10);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(pushed.artifact().ref().version(), 1u);
  ASSERT_EQ(pushed.artifact().depends_on_size(), 1);
  EXPECT_EQ(pushed.artifact().depends_on(0).version(), 1u);  // 0 (newest) resolved
  ASSERT_EQ(pushed.artifact().files_size(), 1);
  EXPECT_EQ(pushed.artifact().files(0).name(), "controller.kctrl");
  v1::SynthesizeResponse motion;
  s = Synthesize(stub_.get(), "ctl", 3, &motion);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_GT(motion.segments_size(), 1);

  // Against other clips: refused, naming the dependency; nothing stored.
  std::vector<PushFile> other;
  for (const char* clip : {"dataset-1_bye_angry_001", "dataset-1_guide_happy_001", "dataset-1_respond_normal_001"}) {
    other.push_back({std::string(clip) + ".bvh", ReadFile(kData + "/planner_gesture/" + clip + ".bvh")});
  }
  ASSERT_TRUE(Push(stub_.get(), "libraries", "other", other, {}, &pushed).ok());
  s = Push(stub_.get(), "controllers", "bad", {{"built.kctrl", bytes}}, {Ref("libraries", "other")}, &pushed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(s.error_message().rfind("header.depends_on[0]: ", 0), 0u) << s.error_message();
  EXPECT_EQ(s.error_message().find(".staging"), std::string::npos) << s.error_message();
  // Without its library, or naming one that is not stored.
  s = Push(stub_.get(), "controllers", "bad", {{"built.kctrl", bytes}}, {}, &pushed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message().rfind("header.depends_on: ", 0), 0u) << s.error_message();
  s = Push(stub_.get(), "controllers", "bad", {{"built.kctrl", bytes}}, {Ref("libraries", "nope")}, &pushed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  // A corrupt file.
  s = Push(stub_.get(), "controllers", "bad", {{"built.kctrl", bytes.substr(0, bytes.size() / 2)}},
           {Ref("libraries", "gestures")}, &pushed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message().rfind("header.files[0]: ", 0), 0u) << s.error_message();
  EXPECT_EQ(Refs(List(stub_.get(), "controllers")), std::vector<std::string>{"controllers/ctl/1"});

  // After a restart the controller is loaded on the stored library.
  Restart();
  s = Synthesize(stub_.get(), "ctl", 3, &motion);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ExpectNoDrafts();
}

TEST_F(PlannerStoreTest, BadPushesStoreNothing) {
  Start();
  const std::string bye = ReadFile(kData + "/planner_gesture/dataset-1_bye_angry_001.bvh");
  cv1::PushArtifactResponse r;
  auto expect_invalid = [&](const grpc::Status& s, const std::string& prefix, const std::string& names = "") {
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
    EXPECT_EQ(s.error_message().rfind(prefix, 0), 0u) << s.error_message();
    if (!names.empty()) {
      EXPECT_NE(s.error_message().find(names), std::string::npos) << s.error_message();
    }
    EXPECT_EQ(s.error_message().find(".staging"), std::string::npos) << s.error_message();
  };
  // No manifest and no BVH.
  expect_invalid(Push(stub_.get(), "libraries", "x", {{"notes.txt", "hello"}}, {}, &r), "header.files[0].name: ",
                 "notes.txt");
  expect_invalid(Push(stub_.get(), "libraries", "x", {{"manifest.json", R"({"clips": [{"path": "a.bvh"}]})"}}, {}, &r),
                 "header.files: ", "no .bvh clips");
  // A BVH that does not parse, beside a good one: the message names it.
  expect_invalid(Push(stub_.get(), "libraries", "x", {{"good.bvh", bye}, {"clips/broken.bvh", "HIERARCHY\nROOT Hips\n{\n"}},
                      {}, &r),
                 "header.files: ", "clips/broken.bvh");
  // A manifest naming files outside the push.
  expect_invalid(Push(stub_.get(), "libraries", "x",
                      {{"good.bvh", bye}, {"manifest.json", R"({"clips": [{"path": "../../etc/hostname"}]})"}}, {}, &r),
                 "header.files: manifest.json: clips[0].path: ");
  expect_invalid(Push(stub_.get(), "libraries", "x",
                      {{"good.bvh", bye}, {"manifest.json", R"({"clips": [{"path": "other.bvh"}]})"}}, {}, &r),
                 "header.files: manifest.json: clips[0].path: ", "not one of the pushed files");
  // Fewer bytes than declared.
  {
    auto ctx = Ctx();
    auto writer = stub_->PushArtifact(ctx.get(), &r);
    cv1::PushArtifactRequest h;
    h.mutable_header()->mutable_ref()->set_kind("libraries");
    h.mutable_header()->mutable_ref()->set_id("x");
    auto* f = h.mutable_header()->add_files();
    f->set_name("good.bvh");
    f->set_size_bytes(bye.size());
    ASSERT_TRUE(writer->Write(h));
    cv1::PushArtifactRequest c;
    c.mutable_chunk()->set_data(bye.substr(0, 1000));
    ASSERT_TRUE(writer->Write(c));
    writer->WritesDone();
    expect_invalid(writer->Finish(), "header.files[0]: ");
  }
  // Graph recipes that do not parse, or name no stored library; a kind the
  // planner does not own.
  expect_invalid(Push(stub_.get(), "gesture_graphs", "g", {{"graph.textproto", "library_id: \"x\" params {"}}, {}, &r),
                 "header.files[0]: graph.textproto:");
  grpc::Status s = Push(stub_.get(), "gesture_graphs", "g", {{"graph.textproto", "library_id: \"none\""}}, {}, &r);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
  expect_invalid(Push(stub_.get(), "models", "m", {{"model.kmodel", "x"}}, {}, &r), "header.ref.kind: ");

  EXPECT_EQ(List(stub_.get()).artifacts_size(), 0);
  ExpectNoDrafts();
  std::error_code ec;
  EXPECT_FALSE(fs::exists(store() + "/libraries/x", ec));
}

TEST_F(PlannerStoreTest, DeletionIsRefusedWhileADependentExistsAndServesThePreviousVersion) {
  Start();
  ASSERT_TRUE(LoadLibrary("lib", {"planner_gesture/dataset-1_bye_angry_001.bvh"}, false).ok());
  v1::LoadLibraryResponse loaded;
  grpc::Status s = LoadLibrary("lib", {"planner_gesture/dataset-1_bye_angry_001.bvh"}, false);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ALREADY_EXISTS);
  EXPECT_EQ(s.error_message().rfind("library_id: ", 0), 0u) << s.error_message();
  ASSERT_TRUE(LoadLibrary("lib",
                          {"planner_gesture/dataset-1_bye_angry_001.bvh", "planner_gesture/dataset-1_byebye_normal_001.bvh",
                           "planner_gesture/dataset-1_guide_happy_001.bvh", "planner_gesture/dataset-1_guide_normal_001.bvh",
                           "planner_gesture/dataset-1_respond_normal_001.bvh"},
                          true, &loaded)
                  .ok());
  EXPECT_EQ(loaded.library().version(), 2u);
  v1::BuildGestureGraphResponse g;
  ASSERT_TRUE(BuildGraph("g", "lib", &g).ok());
  EXPECT_EQ(g.graph().version(), 1u);
  EXPECT_EQ(DependsOn(List(stub_.get(), "gesture_graphs"), "g"), "libraries/lib/2");

  // The version the graph was built on cannot go, nor the whole id.
  s = Delete(stub_.get(), "libraries", "lib", 2);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("gesture_graphs/g/1"), std::string::npos) << s.error_message();
  EXPECT_EQ(Delete(stub_.get(), "libraries", "lib", 0).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  // Version 1 can.
  cv1::DeleteArtifactResponse deleted;
  ASSERT_TRUE(Delete(stub_.get(), "libraries", "lib", 1, &deleted).ok());
  ASSERT_EQ(deleted.deleted_size(), 1);
  EXPECT_EQ(deleted.deleted(0).ref().version(), 1u);

  // Deleting the newest version serves the previous one.
  ASSERT_TRUE(LoadLibrary("lib", {"planner_gesture/dataset-1_guide_normal_001.bvh"}, true, &loaded).ok());
  EXPECT_EQ(loaded.library().version(), 3u);
  ASSERT_TRUE(Delete(stub_.get(), "libraries", "lib", 3).ok());
  ASSERT_TRUE(BuildGraph("g2", "lib", &g).ok());
  EXPECT_EQ(DependsOn(List(stub_.get(), "gesture_graphs"), "g2"), "libraries/lib/2");
  EXPECT_EQ(Refs(List(stub_.get(), "libraries", true)), std::vector<std::string>{"libraries/lib/2"});

  // Deleting a graph unloads it.
  ASSERT_TRUE(Delete(stub_.get(), "gesture_graphs", "g", 0).ok());
  v1::SynthesizeGesturesResponse motion;
  EXPECT_EQ(SynthesizeGestures(stub_.get(), "g", &motion).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(SynthesizeGestures(stub_.get(), "g2", &motion).ok());

  // Errors name the request's fields.
  s = Delete(stub_.get(), "libraries", "nope", 0);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(s.error_message().rfind("ref.id: ", 0), 0u) << s.error_message();
  s = Delete(stub_.get(), "libraries", "lib", 7);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(s.error_message().rfind("ref.version: ", 0), 0u) << s.error_message();
  s = Delete(stub_.get(), "cubes", "lib", 0);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message().rfind("ref.kind: ", 0), 0u) << s.error_message();
  s = Delete(stub_.get(), "libraries", "Bad Id", 0);
  EXPECT_EQ(s.error_message().rfind("ref.id: ", 0), 0u) << s.error_message();
  cv1::ListArtifactsRequest bad;
  bad.set_kind("models");
  cv1::ListArtifactsResponse listed;
  auto ctx = Ctx();
  s = stub_->ListArtifacts(ctx.get(), bad, &listed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message().rfind("kind: ", 0), 0u) << s.error_message();
}

TEST_F(PlannerStoreTest, PreloadsSeedAFreshStoreAndSeedStoresAreImported) {
  v1::PlannerOptions o;
  o.set_store_dir(dir_.File("seed"));
  auto* pre = o.add_preload();
  pre->set_library_id("bundled");
  pre->add_paths("planner_gesture");
  auto* graph = o.add_preload_gesture_graphs();
  graph->set_graph_id("bundled");
  graph->set_library_id("bundled");
  graph->mutable_params()->set_stroke_phrases(true);
  Start(o);
  const std::vector<std::string> seeded = {"gesture_graphs/bundled/1", "libraries/bundled/1"};
  EXPECT_EQ(Refs(List(stub_.get(), "", true)), seeded);
  // Started again: the stored versions are served, no new version is added.
  Stop();
  Start(o);
  EXPECT_EQ(Refs(List(stub_.get(), "", true)), seeded);
  Stop();

  // A fresh store seeded from it: the same ids and versions, and they work.
  v1::PlannerOptions fresh;
  fresh.set_seed_store_dir(dir_.File("seed"));
  Start(fresh);
  EXPECT_EQ(Refs(List(stub_.get(), "", true)), seeded);
  v1::SynthesizeGesturesResponse motion;
  grpc::Status s = SynthesizeGestures(stub_.get(), "bundled", &motion);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_GT(motion.report_size(), 0);
  // What the store holds is not replaced by the seed.
  ASSERT_TRUE(LoadLibrary("bundled", {"planner_gesture/dataset-1_guide_normal_001.bvh"}, true).ok());
  Restart();
  EXPECT_EQ(Refs(List(stub_.get(), "libraries", true)),
            (std::vector<std::string>{"libraries/bundled/1", "libraries/bundled/2"}));
  Stop();

  // Without store_dir: in memory only, listed without files.
  v1::PlannerOptions memory = o;
  memory.clear_store_dir();
  Start(memory, /*with_store=*/false);
  const auto list = List(stub_.get());
  EXPECT_TRUE(list.in_memory());
  EXPECT_EQ(Refs(list), seeded);
  for (const auto& a : list.artifacts()) EXPECT_EQ(a.files_size(), 0);
}

TEST_F(PlannerStoreTest, ArtifactsThatFailToLoadAreSkippedAtStart) {
  Start();
  v1::LoadLibraryRequest req;
  req.set_library_id("gestures");
  AddControllerClips(&req);
  v1::LoadLibraryResponse loaded;
  auto ctx = Ctx();
  ASSERT_TRUE(stub_->LoadLibrary(ctx.get(), req, &loaded).ok());
  grpc::Status s = BuildController("ctl", "gestures");
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_TRUE(BuildGraph("g", "gestures").ok());
  ASSERT_TRUE(BuildGraph("h", "gestures").ok());
  Stop();
  // A truncated controller file and a recipe that does not parse.
  fs::resize_file(store() + "/controllers/ctl/1/controller.kctrl", 200);
  std::ofstream(store() + "/gesture_graphs/h/1/graph.textproto") << "params { similarity_threshold: ";
  Start();
  v1::SynthesizeResponse motion;
  EXPECT_EQ(Synthesize(stub_.get(), "ctl", 3, &motion).error_code(), grpc::StatusCode::NOT_FOUND);
  v1::SynthesizeGesturesResponse gestures;
  EXPECT_EQ(SynthesizeGestures(stub_.get(), "h", &gestures).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(SynthesizeGestures(stub_.get(), "g", &gestures).ok());
  // A new version replaces the broken one.
  s = BuildController("ctl", "gestures", /*overwrite=*/true);
  ASSERT_TRUE(s.ok()) << s.error_message();
  s = Synthesize(stub_.get(), "ctl", 3, &motion);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(DependsOn(List(stub_.get(), "controllers"), "ctl"), "libraries/gestures/1");
}

}  // namespace
}  // namespace kinemo::planner

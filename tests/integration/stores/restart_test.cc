// A restart per store, with the real binaries: push with the CLI, stop the
// service, start it again on the same store_dir, list, and use what was
// pushed (Infer with the model on real speech features; TrackSource with the
// cube on a video rendered over a real photograph).
#include <gtest/gtest.h>

#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/render/renderer.h"
#include "tests/integration/stores/cube_video.h"
#include "tests/integration/stores/stores_fixture.h"

namespace kinemo::stores_test {
namespace {

using testing::ServiceProcess;
using testing::ServiceProcessOptions;

std::unique_ptr<grpc::ClientContext> Ctx(int seconds = 60) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  return c;
}

TEST(StoreRestart, InferenceModelPushedWithTheCliSurvivesARestart) {
  testing::TempDir dir;
  auto corpus = TinyCorpus(dir.File("corpus"));
  ASSERT_TRUE(corpus.ok()) << corpus.status();
  ASSERT_TRUE(WriteTinyModel(*corpus, dir.File("tiny.kmodel"), "name-inside-the-file").ok());
  std::ofstream(dir.File("inference.textproto")) << "store_dir: \"" << dir.File("store") << "\"\n";
  const ServiceProcessOptions options{.binary = Binary("inference"),
                                      .args = {"--config", dir.File("inference.textproto")},
                                      .health_service = inference::v1::InferenceService::service_full_name()};
  std::string out, err;
  {
    auto svc = ServiceProcess::Start(options);
    ASSERT_TRUE(svc.ok()) << svc.status();
    ASSERT_EQ((RunKinemo({"model", "push", dir.File("tiny.kmodel"), "--id", "tiny", "--server", (*svc)->address(),
                         "--description", "restart test", "--json"},
                        &out, &err)),
              0)
        << err;
    const auto pushed = nlohmann::json::parse(out);
    EXPECT_EQ(pushed["ref"]["id"], "tiny");
    EXPECT_EQ(pushed["ref"]["version"], 1);
    // The same id again without --overwrite: refused, exit 2, naming the id.
    EXPECT_EQ((RunKinemo({"model", "push", dir.File("tiny.kmodel"), "--id", "tiny", "--server", (*svc)->address()},
                        &out, &err)),
              2);
    EXPECT_NE(err.find("'tiny' exists"), std::string::npos) << err;
    auto code = (*svc)->Stop();
    ASSERT_TRUE(code.ok() && *code == 0);
  }
  auto svc = ServiceProcess::Start(options);
  ASSERT_TRUE(svc.ok()) << svc.status();
  ASSERT_EQ((RunKinemo({"model", "ls", "--server", (*svc)->address(), "--json"}, &out, &err)), 0) << err;
  const auto listed = nlohmann::json::parse(out);
  ASSERT_EQ(listed.size(), 1u) << out;
  EXPECT_EQ(listed[0]["ref"]["id"], "tiny");
  EXPECT_EQ(listed[0]["description"], "restart test");
  EXPECT_EQ(listed[0]["files"][0]["name"], "model.kmodel");

  // Use it: beliefs for real speech features, answered by the id it was pushed with.
  auto stub = inference::v1::InferenceService::NewStub((*svc)->Channel());
  inference::v1::InferRequest req;
  req.set_model_id("tiny");
  *req.mutable_inputs() = inference::ToProto((*corpus)[0]).inputs();
  inference::v1::InferResponse resp;
  const grpc::Status s = stub->Infer(Ctx().get(), req, &resp);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(resp.model().model_id(), "tiny");
  EXPECT_EQ(resp.smoothed_size(), req.inputs_size());
  inference::v1::ListModelsResponse models;
  ASSERT_TRUE(stub->ListModels(Ctx().get(), inference::v1::ListModelsRequest(), &models).ok());
  ASSERT_EQ(models.models_size(), 1);
  EXPECT_EQ(models.models(0).model_id(), "tiny");

  ASSERT_EQ((RunKinemo({"model", "rm", "tiny@1", "--server", (*svc)->address()}, &out, &err)), 0) << err;
  EXPECT_NE(out.find("deleted models/tiny version 1"), std::string::npos) << out;
  EXPECT_EQ((RunKinemo({"model", "rm", "tiny", "--server", (*svc)->address()}, &out, &err)), 2);
  EXPECT_EQ(*(*svc)->Stop(), 0);
}

TEST(StoreRestart, CubePushedWithTheCliSurvivesARestart) {
  testing::TempDir dir;
  auto video = RenderCubeVideo(kData, dir);
  ASSERT_TRUE(video.ok()) << video.status();
  const cube::CubeModel* model = &video->model;
  const cube::RenderScript* script = &video->script;
  // No cubes in the options: only the store knows the cube.
  std::ofstream(dir.File("cube_tracker.textproto"))
      << "store_dir: \"" << dir.File("store") << "\"\n"
      << "default_intrinsics_file: \"" << dir.File("camera.yaml") << "\"\n"
      << "file_root: \"" << dir.path() << "\"\n";
  const ServiceProcessOptions options{.binary = Binary("cube_tracker"),
                                      .args = {"--config", dir.File("cube_tracker.textproto")},
                                      .health_service = cube_tracker::v1::CubeTrackerService::service_full_name()};
  std::string out, err;
  {
    auto svc = ServiceProcess::Start(options);
    ASSERT_TRUE(svc.ok()) << svc.status();
    ASSERT_EQ((RunKinemo({"cube", "push", kData + "/cube/vleo.cube", "--id", "desk", "--server", (*svc)->address()},
                        &out, &err)),
              0)
        << err;
    EXPECT_NE(out.find("stored cubes/desk version 1"), std::string::npos) << out;
    auto code = (*svc)->Stop();
    ASSERT_TRUE(code.ok() && *code == 0);
  }
  auto svc = ServiceProcess::Start(options);
  ASSERT_TRUE(svc.ok()) << svc.status();
  ASSERT_EQ((RunKinemo({"cube", "ls", "--server", (*svc)->address(), "--json"}, &out, &err)), 0) << err;
  const auto listed = nlohmann::json::parse(out);
  ASSERT_EQ(listed.size(), 1u) << out;
  EXPECT_EQ(listed[0]["ref"]["id"], "desk");

  // Track the rendered video with the stored cube, by id (and as the default).
  for (const bool by_id : {true, false}) {
    auto stub = cube_tracker::v1::CubeTrackerService::NewStub((*svc)->Channel());
    cube_tracker::v1::TrackSourceRequest req;
    req.mutable_source()->set_video_file("seq.avi");
    req.mutable_source()->set_max_frames(60);
    if (by_id) req.mutable_config()->set_cube_id("desk");
    auto ctx = Ctx(120);
    auto reader = stub->TrackSource(ctx.get(), req);
    auto renderer = cube::SequenceRenderer::Create(*model, *script);
    ASSERT_TRUE(renderer.ok());
    cube_tracker::v1::TrackResponse r;
    cv::Mat frame;
    int frames = 0, agree = 0, visible = 0;
    while (reader->Read(&r)) {
      cube::TruthFrame t;
      ASSERT_TRUE(renderer->Next(&frame, &t).ok());
      ++frames;
      if (t.visible) {
        ++visible;
        agree += cube::FaceFromProto(r.state().top_face()) == t.top_face ? 1 : 0;
      }
    }
    const grpc::Status s = reader->Finish();
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(frames, 60);
    ASSERT_GT(visible, 30);
    EXPECT_GE(agree, visible - 1) << (by_id ? "by id" : "as the default");
  }
  // kinemo-vision carries the same cube commands: it lists the stored cube
  // and deletes it; then kinemo lists none, and a second rm finds nothing
  // (exit 2, naming the id).
  ASSERT_EQ((RunTool("kinemo-vision", {"cube", "ls", "--server", (*svc)->address()}, &out, &err)), 0) << err;
  EXPECT_NE(out.find("desk"), std::string::npos) << out;
  ASSERT_EQ((RunTool("kinemo-vision", {"cube", "rm", "desk", "--server", (*svc)->address()}, &out, &err)), 0) << err;
  EXPECT_NE(out.find("deleted cubes/desk version 1"), std::string::npos) << out;
  ASSERT_EQ((RunKinemo({"cube", "ls", "--server", (*svc)->address(), "--json"}, &out, &err)), 0) << err;
  EXPECT_EQ(nlohmann::json::parse(out).size(), 0u) << out;
  EXPECT_EQ((RunKinemo({"cube", "rm", "desk", "--server", (*svc)->address()}, &out, &err)), 2) << out;
  EXPECT_NE(err.find("desk"), std::string::npos) << err;
  EXPECT_EQ(*(*svc)->Stop(), 0);
}

}  // namespace
}  // namespace kinemo::stores_test

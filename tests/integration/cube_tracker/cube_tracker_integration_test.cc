// The real `cube_tracker` binary on an ephemeral loopback port: TrackSource
// reads a video rendered over a real photograph (tests/data/images) from under
// its file_root, with the cube and intrinsics from its options file, and the
// states and events it streams back are checked against the renderer's truth.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/testing/process.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/render/evaluation.h"
#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cube_tracker {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

std::string Binary() {
  static const std::string path = testing::FindBuiltBinary(KINEMO_BINARY_DIR, "cube_tracker");
  return path;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

cube::CubeState FromResponse(const v1::TrackResponse& r, int64_t i) {
  cube::CubeState s;
  const v1::CubeState& p = r.state();
  s.visible = p.visible();
  s.top_face = cube::FaceFromProto(p.top_face());
  s.yaw_deg = p.yaw_deg();
  s.intensity = p.intensity();
  s.position_m = cv::Vec2d(p.position_m().x(), p.position_m().y());
  for (const v1::CubeEvent& e : r.events()) {
    cube::CubeEvent c;
    c.frame = i;
    if (e.has_face_changed()) {
      c.type = cube::EventType::kFaceChanged;
      c.top_face = cube::FaceFromProto(e.face_changed().to_face());
    } else if (e.has_action_launched()) {
      c.type = cube::EventType::kActionLaunched;
      c.top_face = cube::FaceFromProto(e.action_launched().face());
    } else if (e.has_lost()) {
      c.type = cube::EventType::kLost;
    } else if (e.has_found()) {
      c.type = cube::EventType::kFound;
      c.top_face = cube::FaceFromProto(e.found().top_face());
    } else {
      c.type = cube::EventType::kIntensityChanged;
    }
    s.events.push_back(c);
  }
  return s;
}

TEST(CubeTrackerBinary, TrackSourceOnARenderedVideo) {
  ASSERT_FALSE(Binary().empty()) << "cube_tracker not built";
  testing::TempDir dir;
  auto model = cube::LoadCubeModel(kData + "/cube/vleo.cube");
  ASSERT_TRUE(model.ok()) << model.status();
  auto script = cube::LoadRenderScript(kData + "/cube/lift_rotate_place.json");
  ASSERT_TRUE(script.ok()) << script.status();
  ASSERT_TRUE(cube::SequenceRenderer::RenderToFiles(*model, *script, dir.File("seq.avi"), dir.File("truth.json"),
                                                    dir.File("camera.yaml"))
                  .ok());
  {
    std::ofstream cfg(dir.File("cube_tracker.textproto"));
    cfg << "server { shutdown_grace_s: 2 }\n"
        << "cubes {\n" << ReadFile(kData + "/cube/vleo.cube") << "}\n"
        << "default_intrinsics_file: \"" << dir.File("camera.yaml") << "\"\n"
        << "file_root: \"" << dir.path() << "\"\n";
  }
  auto svc = testing::ServiceProcess::Start(
      {.binary = Binary(),
       .args = {"--config", dir.File("cube_tracker.textproto")},
       .health_service = v1::CubeTrackerService::service_full_name()});
  ASSERT_TRUE(svc.ok()) << svc.status();
  auto stub = v1::CubeTrackerService::NewStub((*svc)->Channel());

  // The whole file.
  v1::TrackSourceRequest req;
  req.mutable_source()->set_video_file("seq.avi");
  std::vector<v1::TrackResponse> responses;
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(300));
    auto reader = stub->TrackSource(&ctx, req);
    v1::TrackResponse r;
    while (reader->Read(&r)) responses.push_back(r);
    grpc::Status st = reader->Finish();
    ASSERT_TRUE(st.ok()) << st.error_message();
  }
  auto renderer = cube::SequenceRenderer::Create(*model, *script);
  ASSERT_TRUE(renderer.ok());
  ASSERT_EQ(static_cast<int64_t>(responses.size()), renderer->frame_count());
  std::vector<cube::TruthFrame> truth;
  std::vector<cube::CubeState> states;
  cv::Mat frame;
  for (size_t i = 0; i < responses.size(); ++i) {
    cube::TruthFrame t;
    ASSERT_TRUE(renderer->Next(&frame, &t).ok());
    ASSERT_FALSE(responses[i].has_frame_error()) << responses[i].frame_error().message();
    EXPECT_EQ(responses[i].state().frame(), i);
    EXPECT_NEAR(responses[i].state().time_s(), t.time_s, 1e-6);
    truth.push_back(t);
    states.push_back(FromResponse(responses[i], static_cast<int64_t>(i)));
  }
  const cube::TrackingReport r = cube::EvaluateTracking(truth, states);
  std::printf("[cube_tracker TrackSource lift_rotate_place.avi] %s\n", r.Summary().c_str());
  EXPECT_GE(r.top_face_accuracy, 0.995);
  EXPECT_LE(r.yaw_err_median_deg, 2.0);
  EXPECT_LE(r.pos_err_median_m, 0.005);
  EXPECT_LE(r.intensity_err_max, 0.02);
  EXPECT_GE(r.truth_events, 5);
  EXPECT_EQ(r.missed_events, 0);
  EXPECT_EQ(r.spurious_events, 0);

  // A window of the file: start_frame and max_frames.
  req.mutable_source()->set_start_frame(100);
  req.mutable_source()->set_max_frames(10);
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    auto reader = stub->TrackSource(&ctx, req);
    v1::TrackResponse resp;
    std::vector<uint64_t> frames;
    while (reader->Read(&resp)) frames.push_back(resp.state().frame());
    ASSERT_TRUE(reader->Finish().ok());
    ASSERT_EQ(frames.size(), 10u);
    EXPECT_EQ(frames.front(), 100u);
    EXPECT_EQ(frames.back(), 109u);
  }
  // Outside the root: refused, naming the field.
  req.mutable_source()->set_video_file("../../etc/hostname");
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    auto reader = stub->TrackSource(&ctx, req);
    v1::TrackResponse resp;
    EXPECT_FALSE(reader->Read(&resp));
    grpc::Status st = reader->Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_EQ(st.error_message().rfind("source.video_file:", 0), 0u) << st.error_message();
  }
  auto code = (*svc)->Stop();
  ASSERT_TRUE(code.ok()) << code.status();
  EXPECT_EQ(*code, 0);
}

// A bad options file stops the binary at start-up with the field named.
TEST(CubeTrackerBinary, BadOptionsFailAtStartUp) {
  testing::TempDir dir;
  std::ofstream(dir.File("bad.textproto")) << "cubes { cube_id: \"x\" dictionary: \"DICT_4X4_50\" }\n";
  auto svc = testing::ServiceProcess::Start({.binary = Binary(), .args = {"--config", dir.File("bad.textproto")}});
  ASSERT_FALSE(svc.ok());
  EXPECT_NE(svc.status().message().find("cubes[0]"), std::string::npos) << svc.status();
}

}  // namespace
}  // namespace kinemo::cube_tracker

// The real `cube_tracker` binary on an ephemeral loopback port: TrackSource
// reads a video rendered over a real photograph (tests/data/images) from under
// its file_root, with the cube and intrinsics from its options file, and the
// states and events it streams back are checked against the renderer's truth.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/testing/process.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include <opencv2/imgcodecs.hpp>

#include "services/cube_tracker/core/calibration.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/render/board_view.h"
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
  std::vector<cube::TruthFrame> truth;
  ASSERT_TRUE(cube::SequenceRenderer::RenderToFiles(*model, *script, dir.File("seq.avi"), dir.File("truth.json"),
                                                    dir.File("camera.yaml"), &truth)
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
  ASSERT_EQ(static_cast<int64_t>(truth.size()), script->frame_count());
  ASSERT_EQ(responses.size(), truth.size());
  std::vector<cube::CubeState> states;
  for (size_t i = 0; i < responses.size(); ++i) {
    ASSERT_FALSE(responses[i].has_frame_error()) << responses[i].frame_error().message();
    EXPECT_EQ(responses[i].state().frame(), i);
    EXPECT_NEAR(responses[i].state().time_s(), truth[i].time_s, 1e-6);
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

// A script past the bounds writes nothing: exit 2 naming the key's field
// (a key at t_s 100000 used to write video without limit).
TEST(KinemoCli, CubeRenderRefusesScriptsPastItsBounds) {
  const std::string kinemo = testing::FindBuiltBinary(KINEMO_BINARY_DIR, "kinemo");
  ASSERT_FALSE(kinemo.empty()) << "kinemo not built";
  testing::TempDir dir;
  const std::string head = R"({"background": ")" + kData + R"(/images/home.jpg", )";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {head + R"("keys": [{"t_s": 0}, {"t_s": 1}, {"t_s": 2}, {"t_s": 3}, {"t_s": 100000}]})",
       "keys[4].t_s: 100000 is not in [0, 600] s"},
      {head + R"("fps": 240, "keys": [{"t_s": 0}, {"t_s": 300}]})",
       "keys[1].t_s: 300 s at 240 fps makes 72001 frames (at most 36000)"},
      {head + R"("width": 100000, "keys": [{"t_s": 0}, {"t_s": 1}]})", "width: must be an integer in 64..4096, got 100000"},
      {head + R"("keys": [{"t_s": 0}, {"t_s": 1, "x_m": 1e300}]})", "keys[1].x_m: "},
  };
  for (size_t i = 0; i < cases.size(); ++i) {
    std::ofstream(dir.File("script.json")) << cases[i].first;
    std::string output;
    auto rc = testing::ChildProcess::Run({kinemo, "cube", "render", "--model", kData + "/cube/vleo.cube", "--script",
                                          dir.File("script.json"), "--out", dir.File("out.avi")},
                                         dir.File("render.log"), std::chrono::seconds(120), &output);
    ASSERT_TRUE(rc.ok()) << rc.status();
    EXPECT_EQ(*rc, 2) << output;
    EXPECT_NE(output.find(cases[i].second), std::string::npos) << output;
    EXPECT_FALSE(std::filesystem::exists(dir.File("out.avi")));
  }
}

// The verification interface: `kinemo cube render` then `kinemo cube track
// VIDEO --model CUBE --intrinsics CAM --json`, one JSON object per frame.
TEST(KinemoCli, CubeRenderThenTrackJson) {
  const std::string kinemo = testing::FindBuiltBinary(KINEMO_BINARY_DIR, "kinemo");
  ASSERT_FALSE(kinemo.empty()) << "kinemo not built";
  testing::TempDir dir;
  const std::string model = kData + "/cube/vleo.cube";
  auto render = testing::ChildProcess::Spawn(
      {kinemo, "cube", "render", "--model", model, "--script", kData + "/cube/rotate_two_turns.json", "--out",
       dir.File("seq.avi"), "--truth", dir.File("truth.json"), "--camera", dir.File("cam.yaml")},
      dir.File("render.log"));
  ASSERT_TRUE(render.ok()) << render.status();
  auto rc = (*render)->WaitExit(std::chrono::milliseconds(300000));
  ASSERT_TRUE(rc.ok()) << rc.status();
  ASSERT_EQ(*rc, 0) << (*render)->ReadLog();
  auto truth = nlohmann::json::parse(ReadFile(dir.File("truth.json")), nullptr, false);
  ASSERT_FALSE(truth.is_discarded());
  ASSERT_TRUE(truth.contains("frames"));

  auto track = testing::ChildProcess::Spawn({kinemo, "cube", "track", dir.File("seq.avi"), "--model", model,
                                             "--intrinsics", dir.File("cam.yaml"), "--json"},
                                            dir.File("track.log"));
  ASSERT_TRUE(track.ok()) << track.status();
  rc = (*track)->WaitExit(std::chrono::milliseconds(300000));
  ASSERT_TRUE(rc.ok()) << rc.status();
  ASSERT_EQ(*rc, 0) << (*track)->ReadLog();
  std::istringstream lines((*track)->ReadLog());
  std::string line;
  std::vector<nlohmann::json> frames;
  while (std::getline(lines, line)) {
    auto j = nlohmann::json::parse(line, nullptr, false);
    if (!j.is_discarded() && j.is_object() && j.contains("frame")) frames.push_back(j);
  }
  ASSERT_EQ(frames.size(), truth["frames"].size());
  for (size_t i = 0; i < frames.size(); ++i) {
    const auto& j = frames[i];
    for (const char* key : {"frame", "time_s", "visible", "top_face", "action", "yaw_deg", "intensity",
                            "position_m", "events"}) {
      ASSERT_TRUE(j.contains(key)) << key << " missing in " << j.dump();
    }
    EXPECT_EQ(j["frame"].get<int64_t>(), static_cast<int64_t>(i));
    EXPECT_EQ(j["position_m"].size(), 2u);
    EXPECT_TRUE(j["events"].is_array());
  }
  // Two turns one way after one the other: the intensity ends at the top.
  EXPECT_NEAR(frames.back()["intensity"].get<double>(), 1.0, 0.02);
  EXPECT_EQ(frames.front()["events"][0]["type"], "found");
  EXPECT_EQ(frames.front()["events"][0]["top_face"], 0);

  // A missing model is bad input: exit code 2.
  auto bad = testing::ChildProcess::Spawn({kinemo, "cube", "track", dir.File("seq.avi"), "--model",
                                           dir.File("none.cube"), "--intrinsics", dir.File("cam.yaml"), "--json"},
                                          dir.File("bad.log"));
  ASSERT_TRUE(bad.ok());
  rc = (*bad)->WaitExit(std::chrono::milliseconds(60000));
  ASSERT_TRUE(rc.ok());
  EXPECT_EQ(*rc, 2) << (*bad)->ReadLog();
}

// `kinemo cube board` prints the board; views of it rendered over a real photo
// go through `kinemo cube calibrate` (intrinsics, then the table).
TEST(KinemoCli, CubeBoardThenCalibrate) {
  const std::string kinemo = testing::FindBuiltBinary(KINEMO_BINARY_DIR, "kinemo");
  ASSERT_FALSE(kinemo.empty()) << "kinemo not built";
  testing::TempDir dir;
  auto run = [&](std::vector<std::string> args, const std::string& log) {
    args.insert(args.begin(), kinemo);
    auto p = testing::ChildProcess::Spawn(args, dir.File(log));
    EXPECT_TRUE(p.ok()) << p.status();
    if (!p.ok()) return -1;
    auto rc = (*p)->WaitExit(std::chrono::milliseconds(120000));
    EXPECT_TRUE(rc.ok()) << rc.status();
    if (*rc != 0) std::printf("%s\n", (*p)->ReadLog().c_str());
    return rc.ok() ? *rc : -1;
  };
  ASSERT_EQ(run({"cube", "board", "--out", dir.File("board.png"), "--pixels-per-square", "120"}, "board.log"), 0);
  const cv::Mat board = cv::imread(dir.File("board.png"), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(board.empty());
  const cube::CharucoBoardSpec spec;  // the command's defaults
  const cv::Mat background = cv::imread(kData + "/images/home.jpg");
  ASSERT_FALSE(background.empty());
  const cube::CameraModel truth = cube::PinholeCamera(640, 480, 58);
  cv::RNG rng(3);
  const double poses[][6] = {{0.45, 0, 0, 0, 0, 0},          {0.5, 30, 0, 5, 0.02, 0.01},
                             {0.5, -30, 0, -5, -0.02, 0},    {0.48, 0, 32, 10, 0, -0.02},
                             {0.48, 0, -32, -10, 0.03, 0.02}, {0.55, 25, 25, 20, -0.03, 0.03},
                             {0.42, -20, 20, -15, 0.02, -0.03}, {0.6, 15, -25, 30, -0.05, 0.04},
                             {0.5, 45, 0, 0, 0, 0.03},        {0.5, 0, -45, 0, -0.04, 0}};
  std::vector<std::string> args = {"cube", "calibrate"};
  for (size_t i = 0; i < std::size(poses); ++i) {
    const auto& p = poses[i];
    const cv::Mat view = cube::RenderBoardView(board, spec, 120, truth,
                                               cube::BoardPose(p[0], p[1], p[2], p[3], p[4], p[5]), background, rng);
    const std::string path = dir.File("view" + std::to_string(i) + ".png");
    ASSERT_TRUE(cv::imwrite(path, view));
    args.push_back(path);
  }
  args.push_back("--out");
  args.push_back(dir.File("cam.yaml"));
  ASSERT_EQ(run(args, "calibrate.log"), 0);
  const cv::Mat table = cube::RenderBoardView(board, spec, 120, truth, cube::BoardPose(0.45, 40, 0, 0, 0, 0.02),
                                              background, rng);
  ASSERT_TRUE(cv::imwrite(dir.File("table.png"), table));
  ASSERT_EQ(run({"cube", "calibrate", "--intrinsics", dir.File("cam.yaml"), "--surface", dir.File("table.png"),
                 "--out", dir.File("cam_table.yaml")},
                "surface.log"),
            0);
  auto cam = cube::LoadCameraModel(dir.File("cam_table.yaml"));
  ASSERT_TRUE(cam.ok()) << cam.status();
  std::printf("kinemo cube calibrate: fx %.2f fy %.2f cx %.2f cy %.2f (truth %.2f, %.2f, %.2f)\n", cam->K(0, 0),
              cam->K(1, 1), cam->K(0, 2), cam->K(1, 2), truth.K(0, 0), truth.K(0, 2), truth.K(1, 2));
  EXPECT_NEAR(cam->K(0, 0) / truth.K(0, 0), 1.0, 0.015);
  EXPECT_NEAR(cam->K(1, 1) / truth.K(1, 1), 1.0, 0.015);
  EXPECT_NEAR(cam->K(0, 2), truth.K(0, 2), 6.0);
  EXPECT_NEAR(cam->K(1, 2), truth.K(1, 2), 6.0);
  ASSERT_TRUE(cam->surface.has_value());
  // Unreadable images are bad input.
  EXPECT_EQ(run({"cube", "calibrate", dir.File("missing.png"), "--out", dir.File("x.yaml")}, "bad.log"), 2);
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

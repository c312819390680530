// The cube tracker service in process (ServiceHost + InProcessChannel): a
// sequence rendered over a real photograph (tests/data/images) streamed through
// Track as JPEG, PNG and raw frames, checked against the renderer's truth;
// garbage frames; request validation; ConfigureCube; TrackSource refusals.
#include "services/cube_tracker/cube_tracker_service.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/config/options.h"
#include "common/server/service_host.h"
#include "common/testing/process.h"
#include "services/cube_tracker/core/track_messages.h"
#include "services/cube_tracker/render/evaluation.h"
#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cube_tracker {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

v1::CubeModel VleoProto() {
  v1::CubeModel m;
  Status s = config::LoadTextProtoFile(kData + "/cube/vleo.cube", &m);
  EXPECT_TRUE(s.ok()) << s;
  return m;
}

cube::CubeModel Vleo() {
  auto m = cube::CubeModelFromProto(VleoProto());
  EXPECT_TRUE(m.ok()) << m.status();
  return *m;
}

std::chrono::system_clock::time_point Deadline(int seconds = 120) {
  return std::chrono::system_clock::now() + std::chrono::seconds(seconds);
}

v1::CameraIntrinsics Intrinsics(const cube::CameraModel& c) {
  v1::CameraIntrinsics p;
  p.set_width_px(c.width);
  p.set_height_px(c.height);
  p.set_fx_px(c.K(0, 0));
  p.set_fy_px(c.K(1, 1));
  p.set_cx_px(c.K(0, 2));
  p.set_cy_px(c.K(1, 2));
  for (int i = 0; i < static_cast<int>(c.dist.total()); ++i) p.add_distortion(c.dist.at<double>(i));
  return p;
}

// The camera_from_surface pose as the API carries it (through a quaternion).
common::v1::Pose SurfacePose(const cube::Pose& pose) {
  cube::CubeState s;
  s.visible = true;
  s.camera_from_cube = pose;
  v1::CubeState out;
  StateToProto(s, Vleo(), std::nullopt, true, 0, &out);
  return out.camera_from_cube();
}

// A response back in the core's terms, for EvaluateTracking.
cube::CubeState FromResponse(const v1::TrackResponse& r) {
  cube::CubeState s;
  const v1::CubeState& p = r.state();
  s.frame = static_cast<int64_t>(p.frame());
  s.time_s = p.time_s();
  s.visible = p.visible();
  s.top_face = cube::FaceFromProto(p.top_face());
  s.action = cube::ActionFromProto(p.action());
  s.yaw_deg = p.yaw_deg();
  s.intensity = p.intensity();
  s.position_m = cv::Vec2d(p.position_m().x(), p.position_m().y());
  for (const v1::CubeEvent& e : r.events()) {
    cube::CubeEvent c;
    c.frame = static_cast<int64_t>(e.frame());
    c.time_s = e.time_s();
    switch (e.event_case()) {
      case v1::CubeEvent::kFaceChanged:
        c.type = cube::EventType::kFaceChanged;
        c.top_face = cube::FaceFromProto(e.face_changed().to_face());
        c.previous_face = cube::FaceFromProto(e.face_changed().from_face());
        break;
      case v1::CubeEvent::kActionLaunched:
        c.type = cube::EventType::kActionLaunched;
        c.top_face = cube::FaceFromProto(e.action_launched().face());
        c.intensity = e.action_launched().intensity();
        break;
      case v1::CubeEvent::kIntensityChanged:
        c.type = cube::EventType::kIntensityChanged;
        c.intensity = e.intensity_changed().to_intensity();
        break;
      case v1::CubeEvent::kLost:
        c.type = cube::EventType::kLost;
        break;
      case v1::CubeEvent::kFound:
        c.type = cube::EventType::kFound;
        c.top_face = cube::FaceFromProto(e.found().top_face());
        break;
      default:
        ADD_FAILURE() << "event without a type";
    }
    s.events.push_back(c);
  }
  return s;
}

class CubeTrackerServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = scratch_.File("root");  // unique per process
    std::filesystem::create_directories(root_);
    v1::CubeTrackerOptions options;
    *options.add_cubes() = VleoProto();
    options.set_file_root(root_);
    options.add_allowed_devices("/dev/video_kinemo_test");
    auto service = CubeTrackerService::Create(options);
    ASSERT_TRUE(service.ok()) << service.status();
    common::v1::ServerOptions server;
    server.set_host("127.0.0.1");
    server.set_port(0);
    server.set_shutdown_grace_s(1);
    auto host = server::ServiceHost::Start(server, "cube_tracker_test",
                                           {{*service, v1::CubeTrackerService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = std::move(*host);
    stub_ = v1::CubeTrackerService::NewStub(host_->InProcessChannel());
  }
  void TearDown() override {
    if (host_) host_->Shutdown();
  }

  // Opens Track, sends `config`, returns the stream.
  std::unique_ptr<grpc::ClientReaderWriter<v1::TrackRequest, v1::TrackResponse>> OpenTrack(
      grpc::ClientContext* ctx, const v1::TrackConfig& config) {
    ctx->set_deadline(Deadline());
    auto stream = stub_->Track(ctx);
    v1::TrackRequest req;
    *req.mutable_config() = config;
    EXPECT_TRUE(stream->Write(req));
    return stream;
  }

  kinemo::testing::TempDir scratch_;
  std::string root_;
  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::CubeTrackerService::Stub> stub_;
};

// Four encodings in turn; a garbage frame after every 50th frame.
TEST_F(CubeTrackerServiceTest, TrackStreamsARenderedSequenceAgainstTruth) {
  auto script = cube::LoadRenderScript(kData + "/cube/lift_rotate_place.json");
  ASSERT_TRUE(script.ok()) << script.status();
  auto renderer = cube::SequenceRenderer::Create(Vleo(), *script);
  ASSERT_TRUE(renderer.ok()) << renderer.status();

  v1::TrackConfig config;
  config.set_cube_id("vleo");
  *config.mutable_camera() = Intrinsics(renderer->camera());
  *config.mutable_surface()->mutable_camera_from_surface() = SurfacePose(*renderer->camera().surface);
  config.set_include_details(true);
  config.set_request_id("service-test");
  grpc::ClientContext ctx;
  auto stream = OpenTrack(&ctx, config);

  std::vector<cube::TruthFrame> truth;
  std::vector<cube::CubeState> states;
  int garbage_sent = 0, garbage_errors = 0;
  cv::Mat bgr, gray, rgb;
  uint64_t index = 0;
  for (int64_t i = 0; i < renderer->frame_count(); ++i) {
    cube::TruthFrame t;
    ASSERT_TRUE(renderer->Next(&bgr, &t).ok());
    v1::TrackRequest req;
    v1::TrackFrame* f = req.mutable_frame();
    f->set_frame(index++);
    f->set_time_s(t.time_s);
    v1::Image* img = f->mutable_image();
    std::vector<uint8_t> bytes;
    switch (i % 4) {
      case 0:
        ASSERT_TRUE(cv::imencode(".jpg", bgr, bytes, {cv::IMWRITE_JPEG_QUALITY, 92}));
        img->set_encoding(v1::IMAGE_ENCODING_JPEG);
        img->set_data(bytes.data(), bytes.size());
        break;
      case 1:
        ASSERT_TRUE(cv::imencode(".png", bgr, bytes));
        img->set_encoding(v1::IMAGE_ENCODING_PNG);
        img->set_data(bytes.data(), bytes.size());
        img->set_width_px(bgr.cols);
        img->set_height_px(bgr.rows);
        break;
      case 2: {
        cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
        // Rows padded to 648 bytes: the stride is honoured.
        cv::Mat padded(gray.rows, 648, CV_8UC1, cv::Scalar(0));
        gray.copyTo(padded(cv::Rect(0, 0, gray.cols, gray.rows)));
        img->set_encoding(v1::IMAGE_ENCODING_GRAY8);
        img->set_data(padded.data, padded.total());
        img->set_width_px(gray.cols);
        img->set_height_px(gray.rows);
        img->set_stride_bytes(648);
        break;
      }
      default:
        cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
        img->set_encoding(v1::IMAGE_ENCODING_RGB8);
        img->set_data(rgb.data, rgb.total() * 3);
        img->set_width_px(rgb.cols);
        img->set_height_px(rgb.rows);
    }
    ASSERT_TRUE(stream->Write(req));
    v1::TrackResponse resp;
    ASSERT_TRUE(stream->Read(&resp));
    ASSERT_FALSE(resp.has_frame_error()) << "frame " << i << ": " << resp.frame_error().message();
    EXPECT_EQ(resp.state().frame(), f->frame());
    if (resp.state().visible()) {
      EXPECT_TRUE(resp.state().has_camera_from_cube());
      EXPECT_GT(resp.state().markers_seen_size(), 0);
    }
    truth.push_back(t);
    cube::CubeState s = FromResponse(resp);
    for (auto& e : s.events) e.frame = i;
    states.push_back(std::move(s));

    if (i % 50 == 25) {
      // A JPEG cut in half, then bytes that are no image at all.
      ++garbage_sent;
      v1::TrackRequest bad;
      bad.mutable_frame()->set_frame(index++);
      bad.mutable_frame()->set_time_s(t.time_s);
      std::vector<uint8_t> jpeg;
      ASSERT_TRUE(cv::imencode(".jpg", bgr, jpeg));
      bad.mutable_frame()->mutable_image()->set_encoding(i % 100 == 25 ? v1::IMAGE_ENCODING_JPEG
                                                                        : v1::IMAGE_ENCODING_PNG);
      bad.mutable_frame()->mutable_image()->set_data(jpeg.data(), i % 100 == 25 ? jpeg.size() / 2 : 3000);
      ASSERT_TRUE(stream->Write(bad));
      v1::TrackResponse bad_resp;
      ASSERT_TRUE(stream->Read(&bad_resp));
      if (bad_resp.has_frame_error()) {
        ++garbage_errors;
        EXPECT_EQ(bad_resp.frame_error().frame(), bad.frame().frame());
        EXPECT_FALSE(bad_resp.has_state());
      }
    }
  }
  ASSERT_TRUE(stream->WritesDone());
  v1::TrackResponse extra;
  EXPECT_FALSE(stream->Read(&extra));
  grpc::Status st = stream->Finish();
  EXPECT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(garbage_errors, garbage_sent);
  EXPECT_GT(garbage_sent, 5);

  const cube::TrackingReport r = cube::EvaluateTracking(truth, states);
  std::printf("[service lift_rotate_place] %s\n", r.Summary().c_str());
  EXPECT_GE(r.top_face_accuracy, 0.995);
  EXPECT_LE(r.yaw_err_median_deg, 2.0);
  EXPECT_LE(r.pos_err_median_m, 0.005);
  EXPECT_LE(r.intensity_err_max, 0.02);
  EXPECT_GE(r.truth_events, 5);
  EXPECT_EQ(r.missed_events, 0);
  EXPECT_EQ(r.spurious_events, 0);
  EXPECT_LE(r.max_event_offset_frames, 3);
}

TEST_F(CubeTrackerServiceTest, BadFramesAreErrorsForThatFrameOnly) {
  grpc::ClientContext ctx;
  v1::TrackConfig config;
  *config.mutable_camera() = Intrinsics(cube::PinholeCamera(640, 480, 60));
  auto stream = OpenTrack(&ctx, config);
  struct Case {
    v1::TrackFrame frame;
    std::string expect;
  };
  std::vector<Case> cases;
  auto add = [&](uint64_t n, v1::ImageEncoding enc, std::string data, uint32_t w, uint32_t h,
                 const std::string& expect) {
    Case c;
    c.frame.set_frame(n);
    c.frame.set_time_s(0.1 * n);
    c.frame.mutable_image()->set_encoding(enc);
    c.frame.mutable_image()->set_data(data);
    c.frame.mutable_image()->set_width_px(w);
    c.frame.mutable_image()->set_height_px(h);
    c.expect = expect;
    cases.push_back(c);
  };
  add(1, v1::IMAGE_ENCODING_JPEG, "", 0, 0, "frame.image.data: empty");
  add(2, v1::IMAGE_ENCODING_UNSPECIFIED, "xyz", 0, 0, "frame.image.encoding");
  add(3, v1::IMAGE_ENCODING_GRAY8, std::string(100, '\x10'), 640, 480, "frame.image.data: 100 bytes");
  add(4, v1::IMAGE_ENCODING_GRAY8, std::string(320 * 240, '\x10'), 320, 240, "frame.image.width_px: 320x240");
  add(5, v1::IMAGE_ENCODING_BGR8, std::string(640 * 480, '\x10'), 640, 480, "frame.image.data");
  add(6, v1::IMAGE_ENCODING_GRAY8, std::string(640 * 480, '\x10'), 0, 0, "frame.image.width_px: required");
  add(7, v1::IMAGE_ENCODING_JPEG, "\xFF\xD8garbage", 0, 0, "frame");
  for (const Case& c : cases) {
    v1::TrackRequest req;
    *req.mutable_frame() = c.frame;
    ASSERT_TRUE(stream->Write(req));
    v1::TrackResponse resp;
    ASSERT_TRUE(stream->Read(&resp));
    ASSERT_TRUE(resp.has_frame_error()) << c.expect;
    EXPECT_EQ(resp.frame_error().frame(), c.frame.frame());
    EXPECT_EQ(resp.frame_error().message().rfind(c.expect, 0), 0u) << resp.frame_error().message();
  }
  // A good (empty table) frame is still answered; then a frame index going back.
  cv::Mat table(480, 640, CV_8UC1, cv::Scalar(120));
  v1::TrackRequest ok;
  ok.mutable_frame()->set_frame(10);
  ok.mutable_frame()->set_time_s(1.0);
  ok.mutable_frame()->mutable_image()->set_encoding(v1::IMAGE_ENCODING_GRAY8);
  ok.mutable_frame()->mutable_image()->set_data(table.data, table.total());
  ok.mutable_frame()->mutable_image()->set_width_px(640);
  ok.mutable_frame()->mutable_image()->set_height_px(480);
  ASSERT_TRUE(stream->Write(ok));
  v1::TrackResponse resp;
  ASSERT_TRUE(stream->Read(&resp));
  EXPECT_FALSE(resp.has_frame_error()) << resp.frame_error().message();
  EXPECT_FALSE(resp.state().visible());
  ok.mutable_frame()->set_frame(9);
  ASSERT_TRUE(stream->Write(ok));
  ASSERT_TRUE(stream->Read(&resp));
  ASSERT_TRUE(resp.has_frame_error());
  EXPECT_EQ(resp.frame_error().message().rfind("frame.frame: 9", 0), 0u) << resp.frame_error().message();
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
}

// Each bad config ends the call with INVALID_ARGUMENT (or NOT_FOUND) naming the field.
TEST_F(CubeTrackerServiceTest, BadConfigsNameTheField) {
  const v1::CameraIntrinsics good_camera = Intrinsics(cube::PinholeCamera(640, 480, 60));
  struct Case {
    std::function<void(v1::TrackConfig&)> mutate;
    grpc::StatusCode code;
    std::string expect;
  };
  const std::vector<Case> cases = {
      {[](v1::TrackConfig& c) { c.clear_camera(); }, grpc::StatusCode::INVALID_ARGUMENT, "config.intrinsics:"},
      {[](v1::TrackConfig& c) { c.mutable_camera()->set_fx_px(0); }, grpc::StatusCode::INVALID_ARGUMENT,
       "config.camera.fx_px:"},
      {[](v1::TrackConfig& c) { c.mutable_camera()->set_fx_px(1e308); }, grpc::StatusCode::INVALID_ARGUMENT,
       "config.camera.fx_px:"},
      {[](v1::TrackConfig& c) { c.mutable_camera()->set_fy_px(std::nan("")); }, grpc::StatusCode::INVALID_ARGUMENT,
       "config.camera.fy_px:"},
      {[](v1::TrackConfig& c) { c.mutable_camera()->add_distortion(0.1); }, grpc::StatusCode::INVALID_ARGUMENT,
       "config.camera.distortion:"},
      {[](v1::TrackConfig& c) { c.set_cube_id("nope"); }, grpc::StatusCode::NOT_FOUND, "config.cube_id:"},
      {[](v1::TrackConfig& c) {
         *c.mutable_cube_model() = VleoProto();
         c.mutable_cube_model()->mutable_faces(1)->set_marker_id(0);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "config.cube_model.faces[1].marker_id:"},
      {[](v1::TrackConfig& c) { c.mutable_params()->set_turns_full_range(-1); }, grpc::StatusCode::INVALID_ARGUMENT,
       "config.params.turns_full_range:"},
      {[](v1::TrackConfig& c) { c.mutable_params()->set_lift_height_m(0.001); }, grpc::StatusCode::INVALID_ARGUMENT,
       "config.params.lift_height_m:"},
      {[](v1::TrackConfig& c) { c.mutable_surface()->mutable_camera_from_surface(); },
       grpc::StatusCode::INVALID_ARGUMENT, "config.surface.camera_from_surface.orientation:"},
      {[](v1::TrackConfig& c) { c.set_intrinsics_file("../../etc/passwd"); }, grpc::StatusCode::INVALID_ARGUMENT,
       "config.intrinsics_file:"},
      // A stream's config passes no request guard: the handler checks it.
      {[](v1::TrackConfig& c) { c.mutable_params()->set_lift_height_m(std::nan("")); },
       grpc::StatusCode::INVALID_ARGUMENT, "config.params.lift_height_m: not a finite number"},
  };
  for (const Case& c : cases) {
    v1::TrackConfig config;
    *config.mutable_camera() = good_camera;
    c.mutate(config);
    grpc::ClientContext ctx;
    auto stream = OpenTrack(&ctx, config);
    stream->WritesDone();
    v1::TrackResponse resp;
    EXPECT_FALSE(stream->Read(&resp));
    grpc::Status st = stream->Finish();
    EXPECT_EQ(st.error_code(), c.code) << c.expect << ": " << st.error_message();
    EXPECT_EQ(st.error_message().rfind(c.expect, 0), 0u) << st.error_message();
  }
  // A frame before the config.
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline());
  auto stream = stub_->Track(&ctx);
  v1::TrackRequest req;
  req.mutable_frame()->set_frame(0);
  ASSERT_TRUE(stream->Write(req));
  stream->WritesDone();
  grpc::Status st = stream->Finish();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message().rfind("config:", 0), 0u) << st.error_message();
}

TEST_F(CubeTrackerServiceTest, ConfigureCubeStoresValidatedModels) {
  v1::ConfigureCubeRequest req;
  *req.mutable_model() = VleoProto();
  req.mutable_model()->set_cube_id("big");
  req.mutable_model()->set_cube_size_m(0.1);
  req.mutable_model()->set_marker_size_m(0.08);
  req.set_make_default(true);
  v1::ConfigureCubeResponse resp;
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    grpc::Status st = stub_->ConfigureCube(&ctx, req, &resp);
    ASSERT_TRUE(st.ok()) << st.error_message();
    EXPECT_TRUE(resp.is_default());
    EXPECT_EQ(resp.model().faces_size(), 6);
  }
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    grpc::Status st = stub_->ConfigureCube(&ctx, req, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::ALREADY_EXISTS) << st.error_message();
    req.set_overwrite(true);
    grpc::ClientContext ctx2;
    ctx2.set_deadline(Deadline(10));
    EXPECT_TRUE(stub_->ConfigureCube(&ctx2, req, &resp).ok());
  }
  {
    req.mutable_model()->set_marker_size_m(0.2);
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    grpc::Status st = stub_->ConfigureCube(&ctx, req, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_EQ(st.error_message().rfind("model.marker_size_m:", 0), 0u) << st.error_message();
  }
  // The stored cube is usable by id.
  v1::TrackConfig config;
  config.set_cube_id("big");
  *config.mutable_camera() = Intrinsics(cube::PinholeCamera(640, 480, 60));
  grpc::ClientContext ctx;
  auto stream = OpenTrack(&ctx, config);
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
}

// Without a store_dir the artifacts are answered as in memory; pushes are
// validated like ConfigureCube and take the pushed id; deletion unloads.
TEST_F(CubeTrackerServiceTest, CubeArtifactsInMemory) {
  const std::string text = "# a pushed cube\n" + VleoProto().DebugString();
  auto push = [&](const std::string& id, const std::string& name, const std::string& data,
                  common::v1::PushArtifactResponse* response) {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    auto writer = stub_->PushArtifact(&ctx, response);
    common::v1::PushArtifactRequest req;
    req.mutable_header()->mutable_ref()->set_kind("cubes");
    req.mutable_header()->mutable_ref()->set_id(id);
    auto* f = req.mutable_header()->add_files();
    f->set_name(name);
    f->set_size_bytes(data.size());
    writer->Write(req);
    req.Clear();
    req.mutable_chunk()->set_data(data);
    writer->Write(req);
    writer->WritesDone();
    return writer->Finish();
  };
  common::v1::PushArtifactResponse pushed;
  grpc::Status st = push("desk", "cube.textproto", text, &pushed);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(pushed.artifact().ref().id(), "desk");
  st = push("bad", "cube.textproto", "faces { face: CUBE_FACE_POS_Z marker_id: 0 }", &pushed);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message().rfind("header.files[0]: ", 0), 0u) << st.error_message();
  st = push("bad", "cube.json", text, &pushed);
  EXPECT_EQ(st.error_message().rfind("header.files: ", 0), 0u) << st.error_message();

  common::v1::ListArtifactsResponse listed;
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    ASSERT_TRUE(stub_->ListArtifacts(&ctx, common::v1::ListArtifactsRequest(), &listed).ok());
  }
  EXPECT_TRUE(listed.in_memory());
  ASSERT_EQ(listed.artifacts_size(), 1);
  EXPECT_EQ(listed.artifacts(0).ref().id(), "desk");
  EXPECT_EQ(listed.artifacts(0).files_size(), 0);

  v1::TrackConfig config;
  config.set_cube_id("desk");
  *config.mutable_camera() = Intrinsics(cube::PinholeCamera(640, 480, 60));
  {
    grpc::ClientContext ctx;
    auto stream = OpenTrack(&ctx, config);
    stream->WritesDone();
    EXPECT_TRUE(stream->Finish().ok());
  }
  common::v1::DeleteArtifactRequest del;
  del.mutable_ref()->set_kind("cubes");
  del.mutable_ref()->set_id("desk");
  common::v1::DeleteArtifactResponse deleted;
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    ASSERT_TRUE(stub_->DeleteArtifact(&ctx, del, &deleted).ok());
  }
  grpc::ClientContext ctx;
  auto stream = OpenTrack(&ctx, config);
  stream->WritesDone();
  EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(CubeTrackerServiceTest, TrackSourceRefusesPathsOutsideTheRootAndUnlistedDevices) {
  std::ofstream(std::filesystem::path(root_).parent_path() / "outside.avi") << "x";
  struct Case {
    std::function<void(v1::TrackSourceRequest&)> mutate;
    grpc::StatusCode code;
    std::string expect;
  };
  const std::vector<Case> cases = {
      {[](v1::TrackSourceRequest& r) { r.mutable_source()->set_video_file("../outside.avi"); },
       grpc::StatusCode::INVALID_ARGUMENT, "source.video_file:"},
      {[](v1::TrackSourceRequest& r) { r.mutable_source()->set_video_file("/etc/hostname"); },
       grpc::StatusCode::INVALID_ARGUMENT, "source.video_file:"},
      {[](v1::TrackSourceRequest& r) { r.mutable_source()->set_video_file("missing.avi"); },
       grpc::StatusCode::NOT_FOUND, "source.video_file:"},
      {[](v1::TrackSourceRequest& r) { r.mutable_source()->set_device("/dev/video0"); },
       grpc::StatusCode::INVALID_ARGUMENT, "source.device:"},
      {[](v1::TrackSourceRequest& r) { r.mutable_source()->set_device("/dev/video_kinemo_test"); },
       grpc::StatusCode::UNAVAILABLE, "source.device:"},
      {[](v1::TrackSourceRequest& r) { r.mutable_source()->Clear(); }, grpc::StatusCode::INVALID_ARGUMENT,
       "source:"},
  };
  for (const Case& c : cases) {
    v1::TrackSourceRequest req;
    *req.mutable_config()->mutable_camera() = Intrinsics(cube::PinholeCamera(640, 480, 60));
    c.mutate(req);
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(30));
    auto reader = stub_->TrackSource(&ctx, req);
    v1::TrackResponse resp;
    EXPECT_FALSE(reader->Read(&resp));
    grpc::Status st = reader->Finish();
    EXPECT_EQ(st.error_code(), c.code) << c.expect << ": " << st.error_message();
    EXPECT_EQ(st.error_message().rfind(c.expect, 0), 0u) << st.error_message();
  }
}

}  // namespace
}  // namespace kinemo::cube_tracker

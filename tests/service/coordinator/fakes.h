// Mock services for the coordinator's tests: real gRPC servers (sync API) that
// record what the coordinator sends and answer with well-formed data.
#pragma once

#include <atomic>
#include <condition_variable>
#include <deque>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"

namespace kinemo::coordinator::testing {

inline std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Inference: a two-state belief per step (voiced steps lean to state 0).
class FakeInference final : public inference::v1::InferenceService::Service {
 public:
  grpc::Status Infer(grpc::ServerContext*, const inference::v1::InferRequest* request,
                     inference::v1::InferResponse* response) override {
    {
      std::lock_guard<std::mutex> l(mu);
      last = *request;
      ++calls;
    }
    response->mutable_model()->set_model_id(request->model_id());
    std::uint64_t i = 0;
    for (const auto& x : request->inputs()) {
      auto* b = response->add_smoothed();
      b->set_step(i++);
      b->set_start_s(x.start_s());
      b->set_end_s(x.end_s());
      b->add_probabilities(x.voiced() ? 0.8 : 0.1);
      b->add_probabilities(x.voiced() ? 0.2 : 0.9);
    }
    response->set_request_id(request->request_id());
    return grpc::Status::OK;
  }
  // Live: one filtered belief per features message, as it arrives.
  grpc::Status StreamInfer(grpc::ServerContext*,
                           grpc::ServerReaderWriter<inference::v1::StreamInferResponse,
                                                    inference::v1::StreamInferRequest>* stream)
      override {
    inference::v1::StreamInferRequest q;
    std::uint64_t step = 0;
    while (stream->Read(&q)) {
      if (q.has_config()) {
        std::lock_guard<std::mutex> l(mu);
        stream_model = q.config().model_id();
        continue;
      }
      const auto& x = q.features();
      {
        std::lock_guard<std::mutex> l(mu);
        streamed.push_back(x);
      }
      inference::v1::StreamInferResponse r;
      auto* b = r.mutable_filtered();
      b->set_step(step++);
      b->set_start_s(x.start_s());
      b->set_end_s(x.end_s());
      b->add_probabilities(x.voiced() ? 0.8 : 0.1);
      b->add_probabilities(x.voiced() ? 0.2 : 0.9);
      if (!stream->Write(r)) break;
    }
    return grpc::Status::OK;
  }
  std::mutex mu;
  inference::v1::InferRequest last;
  int calls = 0;
  std::string stream_model;
  std::vector<inference::v1::ProsodyFeatures> streamed;
};

// Planner: returns a real BVH (read from `bvh_path`) for Synthesize and
// SynthesizeGestures, one placement per accent, visemes one frame per phone.
class FakePlanner final : public planner::v1::PlannerService::Service {
 public:
  explicit FakePlanner(std::string bvh) : bvh_(std::move(bvh)) {}
  grpc::Status Synthesize(grpc::ServerContext*, const planner::v1::SynthesizeRequest* request,
                          planner::v1::SynthesizeResponse* response) override {
    {
      std::lock_guard<std::mutex> l(mu);
      last_synthesize = *request;
    }
    if (request->beliefs().empty()) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "beliefs: empty");
    }
    response->mutable_motion()->set_bvh(bvh_);
    auto* seg = response->add_segments();
    seg->set_clip("fake");
    seg->set_end_s(request->duration_s());
    return grpc::Status::OK;
  }
  grpc::Status SynthesizeGestures(grpc::ServerContext*,
                                  const planner::v1::SynthesizeGesturesRequest* request,
                                  planner::v1::SynthesizeGesturesResponse* response) override {
    {
      std::lock_guard<std::mutex> l(mu);
      last_gestures = *request;
    }
    response->mutable_motion()->set_bvh(bvh_);
    for (int i = 0; i < request->accents_size(); ++i) {
      auto* r = response->add_report();
      r->set_accent_index(i);
      r->set_papt_s(request->accents(i).time_s());
      r->set_apex_s(request->accents(i).time_s() + 0.05);
      r->set_placed(true);
    }
    if (request->include_visemes()) FillVisemes(request->phones(), response->mutable_visemes());
    return grpc::Status::OK;
  }
  grpc::Status Visemes(grpc::ServerContext*, const planner::v1::VisemesRequest* request,
                       planner::v1::VisemesResponse* response) override {
    {
      std::lock_guard<std::mutex> l(mu);
      last_visemes = *request;
    }
    FillVisemes(request->phones(), response->mutable_track());
    return grpc::Status::OK;
  }
  static void FillVisemes(const google::protobuf::RepeatedPtrField<common::v1::Phone>& phones,
                          planner::v1::VisemeTrack* track) {
    track->set_frame_time_s(1.0 / 30);
    track->add_categories(planner::v1::VISEME_CATEGORY_PAU);
    for (const auto& p : phones) {
      auto* f = track->add_frames();
      f->set_time_s(p.start_s());
      f->add_weights(1.0);
    }
  }
  // Live: a header, then for every belief the frames (30 fps) up to its end.
  grpc::Status Control(grpc::ServerContext*,
                       grpc::ServerReaderWriter<planner::v1::ControlResponse,
                                                planner::v1::ControlRequest>* stream) override {
    planner::v1::ControlRequest q;
    double next_frame_s = 0.0;
    const double frame_s = 1.0 / 30;
    while (stream->Read(&q)) {
      if (q.has_config()) {
        planner::v1::ControlResponse h;
        h.mutable_header()->set_frame_time_s(frame_s);
        h.mutable_header()->mutable_skeleton()->set_name(q.config().controller_id());
        if (!stream->Write(h)) break;
        continue;
      }
      if (!q.has_belief()) continue;
      {
        std::lock_guard<std::mutex> l(mu);
        beliefs.push_back(q.belief());
      }
      planner::v1::ControlResponse r;
      while (next_frame_s < q.belief().end_s()) {
        auto* f = r.mutable_frames()->add_frames();
        f->set_time_s(next_frame_s);
        f->add_values(q.belief().probabilities(0));
        next_frame_s += frame_s;
      }
      if (r.has_frames() && !stream->Write(r)) break;
    }
    return grpc::Status::OK;
  }
  std::vector<planner::v1::BeliefStep> beliefs;
  std::mutex mu;
  planner::v1::SynthesizeRequest last_synthesize;
  planner::v1::SynthesizeGesturesRequest last_gestures;
  planner::v1::VisemesRequest last_visemes;

 private:
  std::string bvh_;
};

// Robot bridge: records SetEmotion, streams a status that follows the last
// command (commanded and shown).
class FakeBridge final : public robot_bridge::v1::RobotBridgeService::Service {
 public:
  grpc::Status SetEmotion(grpc::ServerContext*, const robot_bridge::v1::SetEmotionRequest* request,
                          robot_bridge::v1::SetEmotionResponse* response) override {
    if (request->robot_id() != "pleo") {
      return grpc::Status(grpc::StatusCode::NOT_FOUND, "robot_id: unknown");
    }
    std::lock_guard<std::mutex> l(mu);
    commands.push_back(request->emotion());
    response->set_sequence_number(static_cast<std::uint32_t>(commands.size()));
    response->set_applied(true);
    cv.notify_all();
    return grpc::Status::OK;
  }
  grpc::Status WatchStatus(grpc::ServerContext* context,
                           const robot_bridge::v1::WatchStatusRequest* request,
                           grpc::ServerWriter<robot_bridge::v1::RobotStatus>* writer) override {
    std::size_t sent = static_cast<std::size_t>(-1);
    std::unique_lock<std::mutex> l(mu);
    while (!context->IsCancelled() && !stopping) {
      if (sent != commands.size()) {
        sent = commands.size();
        robot_bridge::v1::RobotStatus st;
        st.set_robot_id(request->robot_id());
        st.set_connected(true);
        if (!commands.empty()) {
          st.set_commanded_emotion(commands.back());
          st.set_shown_emotion(commands.back());
        }
        st.set_state(robot_bridge::v1::ROBOT_STATE_FOLLOWING);
        st.set_battery_percent(90);
        l.unlock();
        if (!writer->Write(st)) return grpc::Status::OK;
        l.lock();
      }
      cv.wait_for(l, std::chrono::milliseconds(20));
    }
    return grpc::Status::OK;
  }
  // Waits until `emotion` was commanded at least `count` times in total.
  bool WaitFor(common::v1::Emotion emotion, int count, std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> l(mu);
    return cv.wait_for(l, timeout, [&] {
      return std::count(commands.begin(), commands.end(), emotion) >= count;
    });
  }
  void Stop() {
    std::lock_guard<std::mutex> l(mu);
    stopping = true;
    cv.notify_all();
  }
  std::mutex mu;
  std::condition_variable cv;
  std::vector<common::v1::Emotion> commands;
  bool stopping = false;
};

// Cube tracker: TrackSource plays a list of per-frame events; the first call
// fails with UNAVAILABLE after `fail_after_frames` frames (0 = never), so the
// coordinator has to reconnect and resume.
class FakeCubeTracker final : public cube_tracker::v1::CubeTrackerService::Service {
 public:
  struct Frame {
    std::vector<cube_tracker::v1::CubeEvent> events;
  };
  std::vector<Frame> frames;
  std::uint64_t fail_after_frames = 0;
  // Not OK: every TrackSource is refused with it, before any frame.
  grpc::Status refuse = grpc::Status::OK;
  std::mutex mu;
  std::vector<std::uint64_t> start_frames;

  grpc::Status TrackSource(grpc::ServerContext*, const cube_tracker::v1::TrackSourceRequest* request,
                           grpc::ServerWriter<cube_tracker::v1::TrackResponse>* writer) override {
    bool first;
    {
      std::lock_guard<std::mutex> l(mu);
      first = start_frames.empty();
      start_frames.push_back(request->source().start_frame());
    }
    if (!refuse.ok()) return refuse;
    for (std::uint64_t f = request->source().start_frame(); f < frames.size(); ++f) {
      if (first && fail_after_frames > 0 && f == fail_after_frames) {
        return grpc::Status(grpc::StatusCode::UNAVAILABLE, "camera hiccup");
      }
      cube_tracker::v1::TrackResponse r;
      r.mutable_state()->set_frame(f);
      r.mutable_state()->set_visible(true);
      for (const auto& e : frames[f].events) *r.add_events() = e;
      if (!writer->Write(r)) return grpc::Status::OK;
    }
    return grpc::Status::OK;
  }
};

}  // namespace kinemo::coordinator::testing

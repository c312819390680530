// CoordinatorService.AnimateChunked: Animate for a recording of any length.
// The recording arrives in chunks and goes on to the prosody service as it
// comes (AnalyzeChunked, with the speech face); the motion comes back from
// the planner in pieces (SynthesizeChunked / SynthesizeGesturesChunked,
// VisemesChunked) and goes on to the client as it comes, its SMPL-X jaw
// driven by the face and each piece followed by its frames' faces
// (core/face_animate.h, ChunkedMotionFace). The coordinator holds the
// prosody track (syllables, accents, phones: a few MB an hour) and the
// speech face (88 bytes per 10 ms: 32 MB an hour), never the audio or the
// motion. The requests of the stages are built in core/animate_requests.h.
#include <algorithm>
#include <chrono>
#include <vector>

#include "common/face/face_proto.h"
#include "common/grpc/call_slot.h"
#include "common/grpc/request_check.h"
#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
#include "services/coordinator/coordinator_service.h"
#include "services/coordinator/core/animate_plan.h"
#include "services/coordinator/core/animate_requests.h"
#include "services/coordinator/core/face_animate.h"
#include "services/coordinator/downstream.h"

namespace kinemo::coordinator {

namespace inf = ::kinemo::inference::v1;
namespace pl = ::kinemo::planner::v1;
namespace pr = ::kinemo::prosody::v1;

namespace {
namespace animate_chunked {  // this file's own helpers (the unity build puts files together)

double ElapsedSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

grpc::Status InvalidStatus(const Status& s) { return ToGrpcStatus(s); }

// Face frames per `face` piece: 2048 are about 0.35 MB.
constexpr std::size_t kFaceFramesPerPiece = 2048;
// A clip piece with its faces added is split above this (the planner's
// pieces are at most 960 KiB without them).
constexpr std::size_t kMaxClipPieceBytes = 960 << 10;

}  // namespace animate_chunked
}  // namespace

grpc::Status WithChunkedRemedy(const grpc::Status& s) {
  const std::string& m = s.error_message();
  if (s.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED && m.find("larger than max") != std::string::npos) {
    return grpc::Status(s.error_code(),
                        absl::StrCat(m, ": the recording or its motion does not fit in one message "
                                        "(server.max_message_bytes); animate long recordings with "
                                        "CoordinatorService.AnimateChunked (kinemo animate does)"));
  }
  if (const auto at = m.find("AnalyzeChunked"); at != std::string::npos) {
    return grpc::Status(s.error_code(), absl::StrCat(m.substr(0, at),
                                                     "CoordinatorService.AnimateChunked (kinemo animate does)",
                                                     m.substr(at + std::string_view("AnalyzeChunked").size())));
  }
  return s;
}

grpc::Status CoordinatorServiceImpl::AnimateChunked(
    grpc::ServerContext* context, grpc::ServerReaderWriter<v1::AnimateChunkedResponse, v1::AnimateChunkedRequest>* stream) {
  using namespace animate_chunked;
  const auto t0 = std::chrono::steady_clock::now();
  // Admission: each call holds a recording and a motion downstream.
  const int limit = options_.animate().max_concurrent_chunked() > 0
                        ? static_cast<int>(options_.animate().max_concurrent_chunked())
                        : 2;
  CallSlot slot;  // free before the client hears the status (the handler returns first)
  if (!slot.Take(&chunked_, limit)) {
    return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                        absl::StrCat("animate.max_concurrent_chunked: ", limit,
                                     " long recordings are being animated; retry when one is done"));
  }
  v1::AnimateChunkedRequest msg;
  if (!stream->Read(&msg)) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "config: the call ended before its config message");
  }
  if (!msg.has_config()) return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "config: must be the first message");
  if (Status s = CheckRequestValues(msg.config(), "config"); !s.ok()) return InvalidStatus(s);
  const v1::AnimateChunkedConfig config = msg.config();
  const v1::AnimateRequest& req = config.request();
  if (!req.audio().data().empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "config.request.audio.data: not used here; send the recording as chunks after the config");
  }
  if (!(config.expected_duration_s() >= 0)) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "config.expected_duration_s: must be >= 0 (0 = unknown)");
  }
  const double max_audio_s =
      options_.animate().max_chunked_audio_s() > 0 ? options_.animate().max_chunked_audio_s() : 7200;
  auto clock = AudioClock::Create(req.audio().format(), max_audio_s, "config.request.audio.format",
                                  "animate.max_chunked_audio_s");
  if (!clock.ok()) return InvalidStatus(clock.status());
  auto method = ResolveMethod(req.method(), options_.animate().default_method(), "config.request.method");
  if (!method.ok()) return InvalidStatus(method.status());
  if (!prosody_) return Unavailable("prosody");
  if (!planner_) return Unavailable("planner");
  const bool gc = *method == v1::METHOD_GESTURE_CONTROLLER;
  if (gc && !inference_) return Unavailable("inference");
  auto models = ResolveAnimateModels(req, options_.animate(), *method, "config.request.models");
  if (!models.ok()) return InvalidStatus(models.status());
  const std::string request_id =
      req.request_id().empty() ? absl::StrCat("animate-", clock_->WallUnixNs()) : req.request_id();
  // Each stage's call carries the caller's cancellation and deadline, and
  // its own (deadlines.analysis_*, from the recording's duration once known).
  auto stage_context = [&](double audio_s) {
    std::unique_ptr<grpc::ClientContext> ctx = grpc::ClientContext::FromServerContext(*context);
    ctx->set_deadline(std::min(DeadlineAfter(deadlines_.Analysis(audio_s)), context->deadline()));
    return ctx;
  };
  auto progress = [&](v1::AnimateStage stage, double audio_s, std::chrono::steady_clock::time_point since) {
    v1::AnimateChunkedResponse r;
    r.mutable_progress()->set_stage(stage);
    r.mutable_progress()->set_audio_s(audio_s);
    r.mutable_progress()->set_elapsed_s(ElapsedSince(since));
    return stream->Write(r);
  };
  const grpc::Status gone(grpc::StatusCode::CANCELLED, "the client went away");

  // 1. Prosody: the chunks go on as they come.
  v1::AnimateResponse result;
  std::unique_ptr<grpc::ClientContext> pctx = stage_context(max_audio_s);
  auto prosody = prosody_->AnalyzeChunked(pctx.get());
  {
    pr::AnalyzeChunkedRequest first;
    *first.mutable_config() = ProsodyConfigFor(req, *method, request_id);
    first.mutable_config()->set_expected_duration_s(std::min(config.expected_duration_s(), max_audio_s));
    bool open = prosody->Write(first);
    while (open && stream->Read(&msg)) {
      Status bad;
      if (!msg.has_chunk()) {
        bad = InvalidField(msg.has_config() ? "config" : "message",
                           msg.has_config() ? "sent twice" : "neither config nor chunk");
      } else if (bad = CheckRequestValues(msg.chunk(), "chunk"); bad.ok()) {
        bad = clock->Add(msg.chunk());
      }
      if (!bad.ok()) {
        pctx->TryCancel();
        (void)prosody->Finish();
        return InvalidStatus(bad);
      }
      pr::AnalyzeChunkedRequest next;
      *next.mutable_chunk() = std::move(*msg.mutable_chunk());
      open = prosody->Write(next);
    }
    if (context->IsCancelled()) {
      pctx->TryCancel();
      (void)prosody->Finish();
      return gone;
    }
    if (open) prosody->WritesDone();
  }
  const auto uploaded = std::chrono::steady_clock::now();
  if (!progress(v1::ANIMATE_STAGE_PROSODY, clock->audio_s(), uploaded)) {
    pctx->TryCancel();
    (void)prosody->Finish();
    return gone;
  }
  pr::ProsodyTrack track;
  FrameTally tally;
  // The face (docs/face.md): composed onto the motion as it goes through.
  const auto [expression, expression_weight] =
      gc ? ExpressionOfStyle(req.style()) : std::pair<face::Expression, float>{face::Expression::kNeutral, 0.0f};
  ChunkedMotionFace face(expression, expression_weight, req.gesture_style().face_emphasis());
  {
    pr::AnalyzeChunkedResponse r;
    while (prosody->Read(&r)) {
      if (r.has_result()) {
        track = std::move(*r.mutable_result()->mutable_track());
      } else if (r.has_frames()) {
        tally.Add(r.frames().frames());
      } else if (r.has_face()) {
        face.AddSpeech(r.face());
      }
    }
    const grpc::Status s = prosody->Finish();
    if (!s.ok()) {
      return WithChunkedRemedy(
          Downstream("prosody", RenameField(s, "config.face.model_id", "config.request.face_model_id")));
    }
  }
  face.AddAccents(track);
  result.mutable_times()->set_prosody_s(ElapsedSince(uploaded));
  const double audio_s = track.duration_s();

  // 2. The motion, in pieces, straight on to the client, each followed by
  // the face of its frames.
  std::vector<face::FaceFrame> faces;
  std::int64_t face_frames = 0;
  auto forward_faces = [&]() {
    for (std::size_t at = 0; at < faces.size(); at += kFaceFramesPerPiece) {
      v1::AnimateChunkedResponse r;
      auto* piece = r.mutable_face();
      piece->set_frame_time_s(face.frame_time_s());
      const std::size_t end = std::min(faces.size(), at + kFaceFramesPerPiece);
      piece->mutable_frames()->Reserve(static_cast<int>(end - at));
      for (std::size_t i = at; i < end; ++i) face::ToProto(faces[i], piece->add_frames());
      if (!stream->Write(r)) return false;
    }
    face_frames += static_cast<std::int64_t>(faces.size());
    faces.clear();
    return true;
  };
  Status face_error;
  auto write_motion = [&](common::v1::MotionChunk* piece) {
    v1::AnimateChunkedResponse r;
    *r.mutable_motion() = std::move(*piece);
    return stream->Write(r);
  };
  auto forward_motion = [&](common::v1::MotionChunk* piece) {
    if (Status s = face.Add(piece, &faces); !s.ok()) {
      face_error = s;
      return false;
    }
    if (piece->has_frames() && piece->ByteSizeLong() > kMaxClipPieceBytes) {
      // The faces made the clip piece larger than a piece may be: in parts.
      auto* all = piece->mutable_frames()->mutable_frames();
      const int parts = static_cast<int>(piece->ByteSizeLong() / kMaxClipPieceBytes) + 1;
      const int per_part = (all->size() + parts - 1) / parts;
      for (int at = 0; at < all->size(); at += per_part) {
        common::v1::MotionChunk part;
        auto* frames = part.mutable_frames()->mutable_frames();
        for (int i = at; i < std::min(all->size(), at + per_part); ++i) *frames->Add() = std::move(*all->Mutable(i));
        if (!write_motion(&part)) return false;
      }
    } else if (!(piece->has_bvh() && piece->bvh().empty()) && !write_motion(piece)) {
      return false;
    }
    return forward_faces();
  };
  // After the planner's last piece: a BVH line it left without a newline.
  auto finish_motion = [&]() {
    common::v1::MotionChunk rest;
    if (Status s = face.Finish(rest.mutable_bvh(), &faces); !s.ok()) {
      face_error = s;
      return false;
    }
    if (!rest.bvh().empty() && !write_motion(&rest)) return false;
    return forward_faces();
  };
  auto forward_visemes = [&](pl::VisemeTrack* piece) {
    v1::AnimateChunkedResponse r;
    *r.mutable_visemes() = std::move(*piece);
    return stream->Write(r);
  };
  if (gc) {
    auto ireq = InferRequestFor(track, models->inference_model_id, request_id);
    if (!ireq.ok()) return InvalidStatus(ireq.status());
    if (!progress(v1::ANIMATE_STAGE_INFERENCE, audio_s, uploaded)) return gone;
    inf::InferResponse ires;
    const auto t1 = std::chrono::steady_clock::now();
    {
      auto ctx = stage_context(audio_s);
      const grpc::Status s = inference_->Infer(ctx.get(), *ireq, &ires);
      if (!s.ok()) return Downstream("inference", s);
    }
    result.mutable_times()->set_inference_s(ElapsedSince(t1));
    auto sreq = SynthesizeRequestFor(req, track, *ireq, ires, models->controller_id, request_id);
    if (!sreq.ok()) return ToGrpcStatus(sreq.status());
    ires.Clear();
    if (!progress(v1::ANIMATE_STAGE_PLANNER, audio_s, uploaded)) return gone;
    const auto t2 = std::chrono::steady_clock::now();
    {
      auto ctx = stage_context(audio_s);
      auto planner = planner_->SynthesizeChunked(ctx.get(), *sreq);
      pl::SynthesizeChunkedResponse r;
      while (planner->Read(&r)) {
        if (r.has_motion() && !forward_motion(r.mutable_motion())) {
          ctx->TryCancel();
          (void)planner->Finish();
          return face_error.ok() ? gone : ToGrpcStatus(face_error);
        }
        if (r.has_result()) {
          *result.mutable_segments() = std::move(*r.mutable_result()->mutable_segments());
        }
      }
      const grpc::Status s = planner->Finish();
      if (!s.ok()) return Downstream("planner", RenameField(s, "rig_id", "config.request.models.rig_id"));
      if (!finish_motion()) return face_error.ok() ? gone : ToGrpcStatus(face_error);
    }
    result.mutable_times()->set_planner_s(ElapsedSince(t2));
    if (req.visemes()) {
      if (!progress(v1::ANIMATE_STAGE_VISEMES, audio_s, uploaded)) return gone;
      const auto t3 = std::chrono::steady_clock::now();
      auto ctx = stage_context(audio_s);
      auto visemes = planner_->VisemesChunked(ctx.get(), VisemesRequestFor(req, track));
      pl::VisemesResponse r;
      while (visemes->Read(&r)) {
        if (!forward_visemes(r.mutable_track())) {
          ctx->TryCancel();
          (void)visemes->Finish();
          return gone;
        }
      }
      const grpc::Status s = visemes->Finish();
      if (!s.ok()) return Downstream("planner", s);
      result.mutable_times()->set_visemes_s(ElapsedSince(t3));
    }
  } else {
    if (!progress(v1::ANIMATE_STAGE_PLANNER, audio_s, uploaded)) return gone;
    const auto t2 = std::chrono::steady_clock::now();
    auto ctx = stage_context(audio_s);
    auto planner =
        planner_->SynthesizeGesturesChunked(ctx.get(), GesturesRequestFor(req, track, *method,
                                                                          models->gesture_graph_id, request_id));
    pl::SynthesizeGesturesChunkedResponse r;
    while (planner->Read(&r)) {
      bool ok = true;
      if (r.has_motion()) ok = forward_motion(r.mutable_motion());
      if (r.has_visemes()) ok = forward_visemes(r.mutable_visemes());
      if (r.has_result()) *result.mutable_accent_report() = std::move(*r.mutable_result()->mutable_report());
      if (!ok) {
        ctx->TryCancel();
        (void)planner->Finish();
        return face_error.ok() ? gone : ToGrpcStatus(face_error);
      }
    }
    const grpc::Status s = planner->Finish();
    if (!s.ok()) return Downstream("planner", RenameField(s, "rig_id", "config.request.models.rig_id"));
    if (!finish_motion()) return face_error.ok() ? gone : ToGrpcStatus(face_error);
    result.mutable_times()->set_planner_s(ElapsedSince(t2));
  }
  *result.mutable_prosody() = SummarizeProsody(track, tally);
  result.set_method(*method);
  result.set_request_id(request_id);
  result.mutable_times()->set_total_s(ElapsedSince(t0));
  log::Info("animated_chunked", {{"request_id", request_id},
                                 {"method", v1::Method_Name(*method)},
                                 {"duration_s", audio_s},
                                 {"chunks", clock->chunks()},
                                 {"face_frames", face_frames},
                                 {"total_s", result.times().total_s()}});
  v1::AnimateChunkedResponse last;
  *last.mutable_result() = std::move(result);
  if (!stream->Write(last)) return gone;
  return grpc::Status::OK;
}

}  // namespace kinemo::coordinator

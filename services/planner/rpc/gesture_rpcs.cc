// gRPC adapter of the GMG/BodySpeech area: BuildGestureGraph,
// SynthesizeGestures, Visemes, and the "gesture_graphs" artifacts (the
// build request as a recipe, graph.textproto, rebuilt at start on the library
// version it depends on). Core errors become grpc::Status only through
// FinishUnary (ToGrpcStatus).
#include <algorithm>
#include <chrono>
#include <cmath>

#include "common/grpc/cancel_token.h"
#include "common/grpc/worker_write_reactor.h"
#include "common/motion/bvh.h"
#include "services/planner/gesture/graph.h"
#include "services/planner/gesture/phrases.h"
#include "services/planner/gesture/synthesis.h"
#include "services/planner/gesture/visemes.h"
#include "services/planner/rpc/planner_service.h"

namespace kinemo::planner {
namespace {

namespace gs = gesture;

v1::GesturePhase PhaseToProto(gs::Phase p) {
  switch (p) {
    case gs::Phase::kPreparation: return v1::GESTURE_PHASE_PREPARATION;
    case gs::Phase::kStroke: return v1::GESTURE_PHASE_STROKE;
    case gs::Phase::kHold: return v1::GESTURE_PHASE_HOLD;
    case gs::Phase::kRetraction: return v1::GESTURE_PHASE_RETRACTION;
  }
  return v1::GESTURE_PHASE_UNSPECIFIED;
}

v1::GestureEdgeKind EdgeKindToProto(gs::EdgeKind k) {
  switch (k) {
    case gs::EdgeKind::kConsecutive: return v1::GESTURE_EDGE_KIND_CONSECUTIVE;
    case gs::EdgeKind::kSimilarity: return v1::GESTURE_EDGE_KIND_SIMILARITY;
    case gs::EdgeKind::kRest: return v1::GESTURE_EDGE_KIND_REST;
  }
  return v1::GESTURE_EDGE_KIND_UNSPECIFIED;
}

void StatsToProto(const gs::GraphStats& s, v1::GestureGraphStats* out) {
  out->set_similarity_threshold(s.similarity_threshold);
  out->set_size(static_cast<uint32_t>(s.size));
  out->set_branching_factor(s.branching_factor);
  out->set_scc_size(static_cast<uint32_t>(s.scc_size));
  out->set_scc_branching_factor(s.scc_branching_factor);
}

void GraphToProto(const gs::GestureGraph& g, const std::string& library_id, v1::GestureGraphInfo* out) {
  out->set_graph_id(g.id);
  out->set_version(static_cast<uint32_t>(g.version));
  out->set_library_id(library_id);
  StatsToProto(g.stats(), out->mutable_stats());
  out->set_consecutive_edges(static_cast<uint32_t>(g.consecutive_edges()));
  out->set_similarity_edges(static_cast<uint32_t>(g.similarity_edges()));
  const Library& lib = g.library();
  for (int i = 0; i < g.num_phrases(); ++i) {
    const gs::Phrase& p = g.phrases()[static_cast<size_t>(i)];
    const double dt = lib.clips[static_cast<size_t>(p.clip)].clip.frame_time_s;
    auto* o = out->add_phrases();
    o->set_phrase_index(static_cast<uint32_t>(i));
    o->set_clip(lib.clips[static_cast<size_t>(p.clip)].name);
    o->set_start_s(p.first_frame * dt);
    o->set_end_s(p.end_frame * dt);
    for (const auto& s : p.phases) {
      auto* ps = o->add_phases();
      ps->set_phase(PhaseToProto(s.phase));
      ps->set_start_s(s.first_frame * dt);
      ps->set_end_s(s.end_frame * dt);
    }
    o->set_apex_s(p.apex_frame * dt);
    o->set_gsi(p.gsi);
    o->set_gsi_raw(p.gsi_raw);
  }
  if (g.rest_node() >= 0) {
    auto* o = out->add_phrases();
    o->set_phrase_index(static_cast<uint32_t>(g.rest_node()));
    o->set_clip(lib.clips[static_cast<size_t>(g.rest_clip())].name);
    o->set_rest_pose(true);
  }
  out->set_build_s(g.build_s());
  auto* p = out->mutable_params();
  p->set_similarity_threshold(g.params().similarity_threshold);
  p->set_keep_all_components(g.params().keep_all_components);
  p->set_no_rest_pose(g.params().no_rest_pose);
  p->set_stroke_phrases(g.params().stroke_phrases);
  p->set_rest_pose_clip(g.rest_clip() >= 0 ? lib.clips[static_cast<size_t>(g.rest_clip())].name
                                           : g.params().rest_pose_clip);
}

// Request params over server defaults over built-in defaults (zeros = unset).
gs::SynthesisParams MergeSynthesisParams(const v1::GestureSynthesisParams& req, const v1::GestureSynthesisParams& def,
                                         double max_output_s) {
  gs::SynthesisParams p;
  auto pick = [](double r, double d, double builtin) { return r != 0 ? r : (d != 0 ? d : builtin); };
  p.synchrony_min_s = pick(req.synchrony_min_s(), def.synchrony_min_s(), p.synchrony_min_s);
  p.synchrony_max_s = pick(req.synchrony_max_s(), def.synchrony_max_s(), p.synchrony_max_s);
  p.max_warp = pick(req.max_warp(), def.max_warp(), p.max_warp);
  p.penalty = pick(req.penalty(), def.penalty(), p.penalty);
  p.blend_s = pick(req.blend_s(), def.blend_s(), p.blend_s);
  p.seed = req.seed() != 0 ? req.seed() : def.seed();
  p.max_output_s = max_output_s > 0 ? max_output_s : 600;
  return p;
}

Status ToVisemeInputs(const google::protobuf::RepeatedPtrField<kinemo::common::v1::Phone>& phones,
                      const google::protobuf::RepeatedPtrField<kinemo::common::v1::PitchAccent>& accents,
                      std::vector<gs::TimedPhone>* tp, std::vector<gs::VisemeAccent>* va) {
  for (const auto& p : phones) tp->push_back({p.phone(), p.start_s(), p.end_s()});
  for (const auto& a : accents) va->push_back({a.time_s(), a.strength(), a.syllable_start_s(), a.syllable_end_s()});
  return absl::OkStatus();
}

void TrackToProto(const gs::VisemeTrack& t, v1::VisemeTrack* out) {
  out->set_frame_time_s(t.frame_time_s);
  for (int c = 0; c < gs::kNumVisemes; ++c) out->add_categories(static_cast<v1::VisemeCategory>(c + 1));
  for (const auto& f : t.frames) {
    auto* o = out->add_frames();
    o->set_time_s(f.time_s);
    for (double w : f.weights) o->add_weights(w);
    o->set_emphasis(f.emphasis);
  }
}

// The next piece of a viseme track, from frame *next on (at most about
// 1 MiB): the first (*next == 0) also carries frame_time_s and categories.
void TrackPieceToProto(const gs::VisemeTrack& t, std::size_t* next, v1::VisemeTrack* out) {
  // A frame is about 150 bytes (15 weights, time, emphasis).
  constexpr std::size_t kFramesPerPiece = 6000;
  if (*next == 0) {
    out->set_frame_time_s(t.frame_time_s);
    for (int c = 0; c < gs::kNumVisemes; ++c) out->add_categories(static_cast<v1::VisemeCategory>(c + 1));
  }
  const std::size_t end = std::min(t.frames.size(), *next + kFramesPerPiece);
  for (; *next < end; ++*next) {
    const auto& f = t.frames[*next];
    auto* o = out->add_frames();
    o->set_time_s(f.time_s);
    for (double w : f.weights) o->add_weights(w);
    o->set_emphasis(f.emphasis);
  }
}

gs::VisemeParams MergeVisemeParams(const v1::VisemeParams& req, const v1::VisemeParams& def) {
  gs::VisemeParams p;
  auto pick = [](double r, double d, double builtin) { return r != 0 ? r : (d != 0 ? d : builtin); };
  p.frame_time_s = pick(req.frame_time_s(), def.frame_time_s(), p.frame_time_s);
  p.coarticulation_s = pick(req.coarticulation_s(), def.coarticulation_s(), p.coarticulation_s);
  p.face_emphasis = req.face_emphasis() != 0 ? req.face_emphasis() : def.face_emphasis();
  return p;
}

}  // namespace

namespace {

// Builds the graph `request` describes on `lib` (params over `defaults`).
// `recipe` receives the request with its parameters resolved (no sweep, no
// overwrite): building it again with empty defaults gives the same graph.
// Sweep rows go to `sweep` when it is not null.
StatusOr<std::shared_ptr<gs::GestureGraph>> BuildGraph(const v1::BuildGestureGraphRequest& request,
                                                       const v1::GestureGraphParams& def,
                                                       std::shared_ptr<const Library> lib,
                                                       v1::BuildGestureGraphRequest* recipe,
                                                       v1::BuildGestureGraphResponse* sweep) {
  const auto& rp = request.params();
  gs::GraphParams p;
  p.similarity_threshold = rp.similarity_threshold() != 0
                               ? rp.similarity_threshold()
                               : (def.similarity_threshold() != 0 ? def.similarity_threshold() : 1.0);
  p.keep_all_components = rp.keep_all_components() || def.keep_all_components();
  p.no_rest_pose = rp.no_rest_pose() || def.no_rest_pose();
  p.rest_pose_clip = !rp.rest_pose_clip().empty() ? rp.rest_pose_clip() : def.rest_pose_clip();
  p.stroke_phrases = rp.stroke_phrases() || def.stroke_phrases();
  if (p.similarity_threshold < 0 || !std::isfinite(p.similarity_threshold)) {
    return InvalidField("params.similarity_threshold", "must be > 0");
  }
  if (request.sweep_thresholds_size() > 1000) {
    return InvalidField("sweep_thresholds", "at most 1000 thresholds");
  }
  KINEMO_ASSIGN_OR_RETURN(gs::PhraseSet set, gs::ExtractPhrases(*lib));
  if (sweep != nullptr && request.sweep_thresholds_size() > 0) {
    std::vector<double> thresholds(request.sweep_thresholds().begin(), request.sweep_thresholds().end());
    KINEMO_ASSIGN_OR_RETURN(auto rows, gs::GestureGraph::Sweep(*lib, set, thresholds, p));
    for (const auto& r : rows) StatsToProto(r, sweep->add_sweep());
  }
  KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<gs::GestureGraph> graph, gs::GestureGraph::Build(lib, std::move(set), p));
  recipe->Clear();
  recipe->set_graph_id(request.graph_id());
  recipe->set_library_id(lib->id);
  auto* rparams = recipe->mutable_params();
  rparams->set_similarity_threshold(p.similarity_threshold);
  rparams->set_keep_all_components(p.keep_all_components);
  rparams->set_no_rest_pose(p.no_rest_pose);
  rparams->set_rest_pose_clip(p.rest_pose_clip);
  rparams->set_stroke_phrases(p.stroke_phrases);
  return graph;
}

// Commits a built graph (its recipe) as the next version of `id` and serves it.
StatusOr<store::ArtifactMeta> CommitGraph(PlannerServiceImpl* svc, const std::string& id,
                                          std::shared_ptr<gs::GestureGraph> graph,
                                          const v1::BuildGestureGraphRequest& recipe, std::string description,
                                          bool overwrite, std::string_view field) {
  const Library& lib = graph->library();
  v1::GestureGraphInfo summary;
  GraphToProto(*graph, lib.id, &summary);
  summary.clear_phrases();
  summary.clear_version();
  summary.set_graph_id(id);
  store::ArtifactMeta meta;
  KINEMO_ASSIGN_OR_RETURN(store::Draft draft, svc->WriteRecipe(store::kGestureGraphs, id, recipe, lib,
                                                               std::move(description), SummaryJson(summary), &meta));
  return svc->CommitArtifact(std::move(draft), std::move(meta), overwrite, field, [&](int version) {
    graph->id = id;
    svc->gesture_graphs().Set(id, graph, version);
  });
}

}  // namespace

Status PlannerServiceImpl::BuildAndStoreGestureGraph(const v1::BuildGestureGraphRequest* request,
                                                     v1::BuildGestureGraphResponse* response) {
  if (!IsValidId(request->graph_id())) {
    return InvalidField("graph_id", "must match [a-z0-9_-]{1,64}");
  }
  KINEMO_RETURN_IF_ERROR(CheckNewVersion(store::kGestureGraphs, request->graph_id(), request->overwrite(), "graph_id"));
  KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const Library> lib, libraries_.Get(request->library_id(), "library_id"));
  v1::BuildGestureGraphRequest recipe;
  KINEMO_ASSIGN_OR_RETURN(auto graph, BuildGraph(*request, options_.gesture_graph_defaults(), lib, &recipe, response));
  KINEMO_RETURN_IF_ERROR(CommitGraph(this, request->graph_id(), graph, recipe, "BuildGestureGraph",
                                     request->overwrite(), "graph_id")
                             .status());
  GraphToProto(*graph, request->library_id(), response->mutable_graph());
  response->set_request_id(request->request_id());
  return absl::OkStatus();
}

PlannerServiceImpl::ArtifactKind PlannerServiceImpl::GestureGraphKind() {
  ArtifactKind k;
  k.kind = std::string(store::kGestureGraphs);
  k.served_version = [this](const std::string& id) { return gesture_graphs_.Version(id); };
  k.unserve = [this](const std::string& id) { gesture_graphs_.Remove(id); };
  k.serve = [this](const store::ArtifactMeta& meta) -> Status {
    v1::BuildGestureGraphRequest request, recipe;
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const Library> lib, ReadStoredRecipe(meta, &request));
    KINEMO_ASSIGN_OR_RETURN(auto graph, BuildGraph(request, v1::GestureGraphParams(), lib, &recipe, nullptr));
    graph->id = meta.id;
    gesture_graphs_.Set(meta.id, std::move(graph), static_cast<int>(meta.version));
    return absl::OkStatus();
  };
  // A recipe pushed as graph.textproto: built here on the library it names.
  k.push = [this](store::Draft draft,
                  const common::v1::PushArtifactHeader& header) -> StatusOr<common::v1::PushArtifactResponse> {
    v1::BuildGestureGraphRequest request, recipe;
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const Library> lib, ReadPushedRecipe(draft, header, &request));
    const std::string& id = header.ref().id();
    request.set_graph_id(id);
    auto graph = BuildGraph(request, options_.gesture_graph_defaults(), lib, &recipe, nullptr);
    if (!graph.ok()) return Annotate(graph.status(), "header.files[0]: graph.textproto");
    KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta meta, CommitGraph(this, id, *graph, recipe, header.description(),
                                                                  header.overwrite(), "header.ref.id"));
    common::v1::PushArtifactResponse response;
    *response.mutable_artifact() = kinemo::ToProto(meta);
    return response;
  };
  return k;
}

grpc::ServerUnaryReactor* PlannerServiceImpl::BuildGestureGraph(grpc::CallbackServerContext* ctx,
                                                                const v1::BuildGestureGraphRequest* request,
                                                                v1::BuildGestureGraphResponse* response) {
  return FinishUnary(ctx, BuildAndStoreGestureGraph(request, response));
}

StatusOr<PlannerServiceImpl::GestureSynthesis> PlannerServiceImpl::RunSynthesizeGestures(
    const v1::SynthesizeGesturesRequest& request, double max_output_s, const CancelToken* cancel) {
  KINEMO_ASSIGN_OR_RETURN(auto graph, gesture_graphs_.Get(request.graph_id(), "graph_id"));
  const gs::GestureGraph& g = *graph;
  // (The clip's own frame time is used when it is retargeted.)
  KINEMO_ASSIGN_OR_RETURN(std::unique_ptr<rig::RigMotion> on_rig,
                          MotionOnRig(request.rig_id(), g.library(), 1.0 / 30.0, "rig_id"));
  gs::SynthesisParams p = MergeSynthesisParams(request.params(), options_.gesture_synthesis_defaults(), max_output_s);
  p.gesture_emphasis = request.style().gesture_emphasis();
  p.duration_s = request.duration_s();
  if (!(request.style().face_emphasis() >= -1 && request.style().face_emphasis() <= 1)) {
    return InvalidField("style.face_emphasis", "must be in [-1, 1]");
  }
  if (request.include_visemes() && request.phones_size() == 0) {
    return InvalidField("phones", "needed with include_visemes");
  }
  const gs::Algorithm alg =
      request.algorithm() == v1::GESTURE_ALGORITHM_GMG ? gs::Algorithm::kGmg : gs::Algorithm::kBodySpeech;
  std::vector<gs::AccentInput> accents;
  accents.reserve(static_cast<size_t>(request.accents_size()));
  for (const auto& a : request.accents()) accents.push_back({a.time_s(), a.strength(), a.psi()});
  GestureSynthesis out;
  // Visemes first: their validation must not leave half a response.
  if (request.include_visemes()) {
    std::vector<gs::TimedPhone> tp;
    std::vector<gs::VisemeAccent> va;
    (void)ToVisemeInputs(request.phones(), request.accents(), &tp, &va);
    gs::VisemeParams vp = MergeVisemeParams(request.viseme_params(), options_.viseme_defaults());
    if (vp.face_emphasis == 0) vp.face_emphasis = request.style().face_emphasis();
    vp.duration_s = request.duration_s();
    vp.max_duration_s = std::max(vp.max_duration_s, max_output_s);
    KINEMO_ASSIGN_OR_RETURN(out.visemes, gs::ComputeVisemes(tp, va, vp));
  }
  // The caller's deadline and cancellation stop the synthesis.
  p.cancel = cancel;
  KINEMO_ASSIGN_OR_RETURN(out.result, gs::Synthesize(g, accents, alg, p));
  const Library& lib = g.library();
  if (on_rig) {
    KINEMO_ASSIGN_OR_RETURN(out.motion.clip, on_rig->Clip(out.result.clip));
    out.motion.meters_per_unit = on_rig->meters_per_unit();
    out.motion.regions = on_rig->regions();
    out.motion.skeleton_name = on_rig->name();
  } else {
    out.motion.clip = std::move(out.result.clip);
    out.motion.meters_per_unit = lib.meters_per_unit;
    out.motion.regions = lib.regions;
    out.motion.skeleton_name = std::string(motion::SkeletonFamilyName(lib.regions.family));
  }
  out.result.clip = motion::Clip();
  out.motion.bvh = {9, "\t"};
  return out;
}

namespace {

// Everything of SynthesizeGestures' response but the motion and the visemes.
void FillGesturesResponse(const PlannerServiceImpl::GestureSynthesis& out, const v1::SynthesizeGesturesRequest& request,
                          v1::SynthesizeGesturesResponse* response) {
  for (const auto& pl : out.result.report) {
    auto* o = response->add_report();
    o->set_accent_index(static_cast<uint32_t>(pl.accent_index));
    o->set_papt_s(pl.papt_s);
    o->set_psi(pl.psi);
    o->set_placed(pl.placed);
    o->set_anticipation_s(pl.anticipation_s);
    if (!pl.placed) {
      o->set_skipped_reason(pl.skipped_reason);
      continue;
    }
    o->set_apex_s(pl.apex_s);
    o->set_gsi(pl.gsi);
    o->set_warp(pl.warp);
    auto* e = o->mutable_edge();
    e->set_kind(EdgeKindToProto(pl.edge_kind));
    e->set_from_phrase(static_cast<uint32_t>(pl.from_node));
    e->set_to_phrase(static_cast<uint32_t>(pl.to_node));
    e->set_weight(pl.edge_weight);
    e->set_blend_s(pl.edge_blend_s);
    o->set_phrase_index(static_cast<uint32_t>(pl.phrase));
    o->set_smooth_cost(pl.smooth_cost);
    o->set_intensity_cost(pl.intensity_cost);
    o->set_time_cost(pl.time_cost);
  }
  response->set_synchrony_rate(out.result.synchrony_rate);
  response->set_intensity_rule_rate(out.result.intensity_rule_rate);
  response->set_compute_s(out.result.compute_s);
  response->set_request_id(request.request_id());
}

}  // namespace

grpc::ServerUnaryReactor* PlannerServiceImpl::SynthesizeGestures(grpc::CallbackServerContext* ctx,
                                                                 const v1::SynthesizeGesturesRequest* request,
                                                                 v1::SynthesizeGesturesResponse* response) {
  const std::unique_ptr<CancelToken> cancel = CallCancelToken(*ctx);
  auto out = RunSynthesizeGestures(*request, options_.max_output_s(), cancel.get());
  if (!out.ok()) return FinishUnary(ctx, out.status());
  const MotionOut& m = out->motion;
  const Status written = MotionToProto(m.clip, m.meters_per_unit, m.regions, m.skeleton_name, "", request->format(),
                                       m.bvh, response->mutable_motion());
  if (!written.ok()) return FinishUnary(ctx, written);
  FillGesturesResponse(*out, *request, response);
  if (request->include_visemes()) TrackToProto(out->visemes, response->mutable_visemes());
  return FinishUnary(ctx, absl::OkStatus());
}

// The synthesis on a worker thread, then the motion and the visemes in
// pieces as the client reads them, then the rest of the response.
grpc::ServerWriteReactor<v1::SynthesizeGesturesChunkedResponse>* PlannerServiceImpl::SynthesizeGesturesChunked(
    grpc::CallbackServerContext* ctx, const v1::SynthesizeGesturesRequest* request) {
  using Response = v1::SynthesizeGesturesChunkedResponse;
  return NewChunkedCall<Response>(this, [this, ctx, request = *request](const auto& send) -> Status {
    const std::unique_ptr<CancelToken> cancel = CallCancelToken(*ctx);
    KINEMO_ASSIGN_OR_RETURN(GestureSynthesis out,
                            RunSynthesizeGestures(request, MaxChunkedOutputS(options()), cancel.get()));
    Response last;
    FillGesturesResponse(out, request, last.mutable_result());
    KINEMO_RETURN_IF_ERROR(SendMotionPieces<Response>(std::move(out.motion), request.format(), send));
    if (request.include_visemes()) {
      std::size_t next = 0;
      do {
        Response piece;
        TrackPieceToProto(out.visemes, &next, piece.mutable_visemes());
        if (!send(std::move(piece))) return absl::CancelledError("the client went away");
      } while (next < out.visemes.frames.size());
    }
    send(std::move(last));
    return absl::OkStatus();
  });
}

// The track in pieces.
grpc::ServerWriteReactor<v1::VisemesResponse>* PlannerServiceImpl::VisemesChunked(
    grpc::CallbackServerContext* /*ctx*/, const v1::VisemesRequest* request) {
  return NewChunkedCall<v1::VisemesResponse>(this, [this, request = *request](const auto& send) -> Status {
    std::vector<gs::TimedPhone> tp;
    std::vector<gs::VisemeAccent> va;
    (void)ToVisemeInputs(request.phones(), request.accents(), &tp, &va);
    gs::VisemeParams vp = MergeVisemeParams(request.params(), options().viseme_defaults());
    vp.duration_s = request.duration_s();
    vp.max_duration_s = std::max(vp.max_duration_s, MaxChunkedOutputS(options()));
    KINEMO_ASSIGN_OR_RETURN(gs::VisemeTrack track, gs::ComputeVisemes(tp, va, vp));
    std::size_t next = 0;
    bool first = true;
    do {
      v1::VisemesResponse piece;
      TrackPieceToProto(track, &next, piece.mutable_track());
      if (first) {
        for (const auto& u : track.unknown_phones) piece.add_unknown_phones(u);
        first = false;
      }
      if (!send(std::move(piece))) return absl::CancelledError("the client went away");
    } while (next < track.frames.size());
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* PlannerServiceImpl::Visemes(grpc::CallbackServerContext* ctx,
                                                      const v1::VisemesRequest* request,
                                                      v1::VisemesResponse* response) {
  std::vector<gs::TimedPhone> tp;
  std::vector<gs::VisemeAccent> va;
  (void)ToVisemeInputs(request->phones(), request->accents(), &tp, &va);
  gs::VisemeParams vp = MergeVisemeParams(request->params(), options_.viseme_defaults());
  vp.duration_s = request->duration_s();
  auto t = gs::ComputeVisemes(tp, va, vp);
  if (!t.ok()) return FinishUnary(ctx, t.status());
  TrackToProto(*t, response->mutable_track());
  for (const auto& u : t->unknown_phones) response->add_unknown_phones(u);
  return FinishUnary(ctx, absl::OkStatus());
}

}  // namespace kinemo::planner

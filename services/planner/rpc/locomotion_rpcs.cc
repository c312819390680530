// Planner RPCs of the locomotion area: BuildLocomotionGraph, PlanTransition,
// EvaluateLocomotion (long work on its own thread) and Drive (bidi stream,
// frames paced in real time by a worker thread per stream); and the
// "locomotion_graphs" artifacts (the build request as a recipe,
// graph.textproto, rebuilt at start on the library version it depends on).
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <mutex>
#include <numbers>
#include <thread>

#include "common/grpc/cancel_token.h"
#include "common/grpc/request_check.h"
#include "common/grpc/status_mapping.h"
#include "common/motion/bvh.h"
#include "services/planner/locomotion/locomotion.h"
#include "services/planner/rpc/planner_service.h"

namespace kinemo::planner {

namespace loco = locomotion;

struct StoredGraph {
  int version = 0;
  std::string library_id;
  int library_version = 0;
  std::shared_ptr<const loco::LocomotionGraph> graph;
  v1::LocomotionGraphInfo info;
};

struct PlannerServiceImpl::LocomotionState {
  VersionedStore<StoredGraph> graphs;
  std::mutex mu;
  // Features per (library id, library version), shared by graphs.
  std::map<std::pair<std::string, int>, std::shared_ptr<const loco::LocomotionData>> data;
  std::atomic<int> builds{0};
  std::atomic<int> streams{0};
};

std::shared_ptr<PlannerServiceImpl::LocomotionState> PlannerServiceImpl::MakeLocomotionState() {
  return std::make_shared<LocomotionState>();
}

namespace {

using LocoState = PlannerServiceImpl::LocomotionState;

// ---- conversions

StatusOr<loco::Chain> FromProto(v1::KinematicChain c) {
  switch (c) {
    case v1::KINEMATIC_CHAIN_HEAD:
      return loco::Chain::kHead;
    case v1::KINEMATIC_CHAIN_TRUNK:
      return loco::Chain::kTrunk;
    case v1::KINEMATIC_CHAIN_UPPER_RIGHT:
      return loco::Chain::kUpperRight;
    case v1::KINEMATIC_CHAIN_UPPER_LEFT:
      return loco::Chain::kUpperLeft;
    case v1::KINEMATIC_CHAIN_LOWER:
      return loco::Chain::kLower;
    default:
      return InvalidField("profile.parts.chains", "unspecified chain");
  }
}

v1::KinematicChain ToProto(loco::Chain c) {
  switch (c) {
    case loco::Chain::kHead:
      return v1::KINEMATIC_CHAIN_HEAD;
    case loco::Chain::kTrunk:
      return v1::KINEMATIC_CHAIN_TRUNK;
    case loco::Chain::kUpperRight:
      return v1::KINEMATIC_CHAIN_UPPER_RIGHT;
    case loco::Chain::kUpperLeft:
      return v1::KINEMATIC_CHAIN_UPPER_LEFT;
    case loco::Chain::kLower:
      return v1::KINEMATIC_CHAIN_LOWER;
  }
  return v1::KINEMATIC_CHAIN_UNSPECIFIED;
}

StatusOr<loco::SplitProfile> FromProto(const v1::SplitProfile& p) {
  if (p.parts_size() == 0) return loco::BuiltinProfile(p.name().empty() ? "SP5" : p.name());
  loco::SplitProfile out;
  out.name = p.name().empty() ? "custom" : p.name();
  for (const auto& part : p.parts()) {
    std::vector<loco::Chain> chains;
    for (int c : part.chains()) {
      KINEMO_ASSIGN_OR_RETURN(loco::Chain chain, FromProto(static_cast<v1::KinematicChain>(c)));
      chains.push_back(chain);
    }
    out.parts.push_back(std::move(chains));
  }
  KINEMO_RETURN_IF_ERROR(loco::ValidateProfile(out));
  return out;
}

void ToProto(const std::vector<loco::Chain>& chains, v1::BodyPart* out) {
  for (auto c : chains) out->add_chains(ToProto(c));
}

// Request params over the server's defaults over the thesis' values.
loco::GraphParams FromProto(const v1::LocomotionGraphParams& req, const v1::LocomotionGraphParams& defaults) {
  auto pick = [](double a, double b) { return a != 0 ? a : b; };
  loco::GraphParams p;
  p.threshold = pick(req.threshold(), defaults.threshold());
  for (const auto& [k, v] : defaults.joint_weights()) p.joint_weights[k] = v;
  for (const auto& [k, v] : req.joint_weights()) p.joint_weights[k] = v;
  p.progressive_window_frames = static_cast<int>(req.progressive_window_frames() != 0 ? req.progressive_window_frames()
                                                                                      : defaults.progressive_window_frames());
  p.max_path_length_ratio = pick(req.max_path_length_ratio(), defaults.max_path_length_ratio());
  p.contact_height_m = pick(req.contact_height_m(), defaults.contact_height_m());
  p.contact_speed_mps = pick(req.contact_speed_mps(), defaults.contact_speed_mps());
  p.filter_cutoff_hz = pick(req.filter_cutoff_hz(), defaults.filter_cutoff_hz());
  return p;
}

void ToProto(const loco::GraphParams& p, v1::LocomotionGraphParams* out) {
  out->set_threshold(p.threshold);
  for (const auto& [k, v] : p.joint_weights) (*out->mutable_joint_weights())[k] = v;
  out->set_progressive_window_frames(static_cast<uint32_t>(p.progressive_window_frames));
  out->set_max_path_length_ratio(p.max_path_length_ratio);
  out->set_contact_height_m(p.contact_height_m);
  out->set_contact_speed_mps(p.contact_speed_mps);
  out->set_filter_cutoff_hz(p.filter_cutoff_hz);
}

common::v1::Channel ToProto(motion::ChannelType t) {
  switch (t) {
    case motion::ChannelType::kXPosition:
      return common::v1::CHANNEL_X_POSITION;
    case motion::ChannelType::kYPosition:
      return common::v1::CHANNEL_Y_POSITION;
    case motion::ChannelType::kZPosition:
      return common::v1::CHANNEL_Z_POSITION;
    case motion::ChannelType::kXRotation:
      return common::v1::CHANNEL_X_ROTATION;
    case motion::ChannelType::kYRotation:
      return common::v1::CHANNEL_Y_ROTATION;
    case motion::ChannelType::kZRotation:
      return common::v1::CHANNEL_Z_ROTATION;
  }
  return common::v1::CHANNEL_UNSPECIFIED;
}

common::v1::BodyRegion ToProto(motion::BodyRegion r) {
  return static_cast<common::v1::BodyRegion>(static_cast<int>(r) + 1);
}

void ToProto(const Library& lib, common::v1::Skeleton* out) {
  for (int j = 0; j < lib.skeleton.num_joints(); ++j) {
    const auto& joint = lib.skeleton.joint(j);
    auto* pj = out->add_joints();
    pj->set_name(joint.name);
    pj->set_parent_index(joint.parent);
    pj->mutable_offset()->set_x(joint.offset.x());
    pj->mutable_offset()->set_y(joint.offset.y());
    pj->mutable_offset()->set_z(joint.offset.z());
    for (auto c : joint.channels) pj->add_channels(ToProto(c));
    if (joint.end_site) {
      pj->set_has_end_site(true);
      pj->mutable_end_site_offset()->set_x(joint.end_site->x());
      pj->mutable_end_site_offset()->set_y(joint.end_site->y());
      pj->mutable_end_site_offset()->set_z(joint.end_site->z());
    }
    if (static_cast<size_t>(j) < lib.regions.region.size()) pj->set_region(ToProto(lib.regions.region[static_cast<size_t>(j)]));
  }
  out->set_meters_per_unit(lib.meters_per_unit);
  out->set_name(std::string(motion::SkeletonFamilyName(lib.regions.family)));
}

Status ToProto(const Library& lib, const motion::Clip& clip, const std::string& name, common::v1::MotionFormat format,
               common::v1::Motion* out) {
  if (format == common::v1::MOTION_FORMAT_CLIP) {
    auto* c = out->mutable_clip();
    ToProto(lib, c->mutable_skeleton());
    c->set_frame_time_s(clip.frame_time_s);
    c->set_name(name);
    for (int f = 0; f < clip.num_frames(); ++f) {
      auto* fr = c->add_frames();
      fr->set_time_s(f * clip.frame_time_s);
      const auto row = clip.frame(f);
      fr->mutable_values()->Add(row.begin(), row.end());
    }
    return absl::OkStatus();
  }
  KINEMO_ASSIGN_OR_RETURN(std::string bvh, motion::WriteBvh(clip, {.significant_digits = 9}));
  out->set_bvh(std::move(bvh));
  return absl::OkStatus();
}

StatusOr<std::shared_ptr<const loco::LocomotionData>> DataFor(LocoState& state, std::shared_ptr<const Library> lib,
                                                              const loco::GraphParams& params) {
  // Features depend on the contact thresholds and joint weights too; cache
  // only the default-weight case keyed by library and contact thresholds.
  const bool cacheable = params.joint_weights.empty();
  const auto key = std::make_pair(kinemo::StrCat(lib->id, "|", params.contact_height_m, "|", params.contact_speed_mps),
                                  lib->version);
  if (cacheable) {
    std::lock_guard lock(state.mu);
    auto it = state.data.find(key);
    // The same library object (an id's version number is reused after every
    // version was deleted).
    if (it != state.data.end() && it->second->library == lib) return it->second;
  }
  KINEMO_ASSIGN_OR_RETURN(auto data, loco::BuildLocomotionData(lib, params));
  if (cacheable) {
    std::lock_guard lock(state.mu);
    if (state.data.size() > 16) state.data.clear();
    state.data[key] = data;
  }
  return data;
}

class BuildSlot {
 public:
  BuildSlot(std::atomic<int>& counter, int limit) : counter_(counter) { ok_ = ++counter_ <= limit; }
  ~BuildSlot() { --counter_; }
  bool ok() const { return ok_; }

 private:
  std::atomic<int>& counter_;
  bool ok_;
};

}  // namespace

namespace {

// Builds the graph `request` describes on `lib` (params over `defaults`).
// `recipe` receives the request with its profile and parameters resolved:
// building it again with empty defaults gives the same graph.
StatusOr<std::shared_ptr<StoredGraph>> BuildGraph(LocoState& state, const v1::BuildLocomotionGraphRequest& request,
                                                  const v1::LocomotionGraphParams& defaults, int limit,
                                                  std::shared_ptr<const Library> lib,
                                                  v1::BuildLocomotionGraphRequest* recipe) {
  KINEMO_ASSIGN_OR_RETURN(loco::SplitProfile profile, FromProto(request.profile()));
  KINEMO_RETURN_IF_ERROR(CheckFitsInt(request.params(), "params"));
  KINEMO_ASSIGN_OR_RETURN(loco::GraphParams params, loco::ResolveParams(FromProto(request.params(), defaults)));
  BuildSlot slot(state.builds, limit);
  if (!slot.ok()) return absl::ResourceExhaustedError("max_concurrent_builds: too many builds running");
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_ASSIGN_OR_RETURN(auto data, DataFor(state, lib, params));
  KINEMO_ASSIGN_OR_RETURN(auto graph, loco::LocomotionGraph::Build(data, profile, params));
  const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  auto stored = std::make_shared<StoredGraph>();
  stored->library_id = lib->id;
  stored->library_version = lib->version;
  stored->graph = graph;
  v1::LocomotionGraphInfo& info = stored->info;
  info.set_graph_id(request.graph_id());
  info.set_library_id(lib->id);
  info.mutable_profile()->set_name(profile.name);
  for (const auto& part : profile.parts) ToProto(part, info.mutable_profile()->add_parts());
  ToProto(graph->params(), info.mutable_params());
  info.mutable_params()->set_progressive_window_frames(static_cast<uint32_t>(graph->window_frames()));
  for (const auto& pg : graph->parts()) {
    auto* ps = info.add_parts();
    ToProto(pg.chains, ps->mutable_part());
    ps->set_threshold(pg.threshold);
    ps->set_scc_nodes(static_cast<uint32_t>(pg.scc_nodes));
    ps->set_scc_edges(static_cast<uint64_t>(pg.scc_edges));
  }
  info.set_connected_clips(static_cast<uint32_t>(graph->connected_clips()));
  info.set_connectivity(graph->connectivity());
  info.set_build_s(build_s);
  const double minutes = lib->duration_s() / 60;
  info.set_build_s_per_clip_minute(minutes > 0 ? build_s / minutes : 0);
  recipe->Clear();
  recipe->set_graph_id(request.graph_id());
  recipe->set_library_id(lib->id);
  *recipe->mutable_profile() = info.profile();
  ToProto(params, recipe->mutable_params());
  return stored;
}

// Commits a built graph (its recipe) as the next version of `id` and serves it.
StatusOr<store::ArtifactMeta> CommitGraph(PlannerServiceImpl* svc, LocoState& state, const std::string& id,
                                          std::shared_ptr<StoredGraph> stored, const Library& lib,
                                          const v1::BuildLocomotionGraphRequest& recipe, std::string description,
                                          bool overwrite, std::string_view field) {
  v1::LocomotionGraphInfo summary = stored->info;
  summary.clear_version();
  summary.set_graph_id(id);
  store::ArtifactMeta meta;
  KINEMO_ASSIGN_OR_RETURN(store::Draft draft, svc->WriteRecipe(store::kLocomotionGraphs, id, recipe, lib,
                                                               std::move(description), SummaryJson(summary), &meta));
  return svc->CommitArtifact(std::move(draft), std::move(meta), overwrite, field, [&](int version) {
    stored->info.set_graph_id(id);
    stored->info.set_version(static_cast<uint32_t>(version));
    state.graphs.Set(id, stored, version);
  });
}

int BuildLimit(const v1::PlannerOptions& options) {
  return options.max_concurrent_builds() > 0 ? static_cast<int>(options.max_concurrent_builds()) : 1;
}

}  // namespace

grpc::ServerUnaryReactor* PlannerServiceImpl::BuildLocomotionGraph(grpc::CallbackServerContext* ctx,
                                                                   const v1::BuildLocomotionGraphRequest* request,
                                                                   v1::BuildLocomotionGraphResponse* response) {
  auto* reactor = ctx->DefaultReactor();
  auto state = locomotion_;
  std::thread([this, reactor, request, response, state]() {
    auto run = [&]() -> Status {
      if (!IsValidId(request->graph_id())) return InvalidField("graph_id", "must match [a-z0-9_-]{1,64}");
      KINEMO_RETURN_IF_ERROR(
          CheckNewVersion(store::kLocomotionGraphs, request->graph_id(), request->overwrite(), "graph_id"));
      KINEMO_ASSIGN_OR_RETURN(auto lib, libraries().Get(request->library_id(), "library_id"));
      v1::BuildLocomotionGraphRequest recipe;
      KINEMO_ASSIGN_OR_RETURN(auto stored, BuildGraph(*state, *request, options_.locomotion_defaults(),
                                                      BuildLimit(options_), lib, &recipe));
      KINEMO_RETURN_IF_ERROR(CommitGraph(this, *state, request->graph_id(), stored, *lib, recipe,
                                         "BuildLocomotionGraph", request->overwrite(), "graph_id")
                                 .status());
      *response->mutable_graph() = stored->info;
      response->set_request_id(request->request_id());
      return absl::OkStatus();
    };
    reactor->Finish(ToGrpcStatus(run()));
  }).detach();
  return reactor;
}

PlannerServiceImpl::ArtifactKind PlannerServiceImpl::LocomotionGraphKind() {
  ArtifactKind k;
  k.kind = std::string(store::kLocomotionGraphs);
  k.served_version = [this](const std::string& id) { return locomotion_->graphs.Version(id); };
  k.unserve = [this](const std::string& id) { locomotion_->graphs.Remove(id); };
  k.serve = [this](const store::ArtifactMeta& meta) -> Status {
    v1::BuildLocomotionGraphRequest request, recipe;
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const Library> lib, ReadStoredRecipe(meta, &request));
    request.set_graph_id(meta.id);
    // Start-up and deletes run one at a time: no build limit.
    KINEMO_ASSIGN_OR_RETURN(auto stored, BuildGraph(*locomotion_, request, v1::LocomotionGraphParams(),
                                                    std::numeric_limits<int>::max(), lib, &recipe));
    stored->info.set_version(meta.version);
    locomotion_->graphs.Set(meta.id, std::move(stored), static_cast<int>(meta.version));
    return absl::OkStatus();
  };
  // A recipe pushed as graph.textproto: built here on the library it names.
  k.push = [this](store::Draft draft,
                  const common::v1::PushArtifactHeader& header) -> StatusOr<common::v1::PushArtifactResponse> {
    v1::BuildLocomotionGraphRequest request, recipe;
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const Library> lib, ReadPushedRecipe(draft, header, &request));
    const std::string& id = header.ref().id();
    request.set_graph_id(id);
    auto stored = BuildGraph(*locomotion_, request, options_.locomotion_defaults(), BuildLimit(options_), lib, &recipe);
    if (!stored.ok()) return Annotate(stored.status(), "header.files[0]: graph.textproto");
    KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta meta, CommitGraph(this, *locomotion_, id, *stored, *lib, recipe,
                                                                  header.description(), header.overwrite(),
                                                                  "header.ref.id"));
    common::v1::PushArtifactResponse response;
    *response.mutable_artifact() = kinemo::ToProto(meta);
    return response;
  };
  return k;
}

grpc::ServerUnaryReactor* PlannerServiceImpl::PlanTransition(grpc::CallbackServerContext* ctx,
                                                             const v1::PlanTransitionRequest* request,
                                                             v1::PlanTransitionResponse* response) {
  auto run = [&]() -> Status {
    KINEMO_ASSIGN_OR_RETURN(auto stored, locomotion_->graphs.Get(request->graph_id(), "graph_id"));
    const loco::LocomotionGraph& graph = *stored->graph;
    const loco::LocomotionData& d = graph.data();
    const int from = d.ClipIndex(request->from_clip());
    if (from < 0) return InvalidField("from_clip", kinemo::StrCat("no clip '", request->from_clip(), "'"));
    const int to = d.ClipIndex(request->to_clip());
    if (to < 0) return InvalidField("to_clip", kinemo::StrCat("no clip '", request->to_clip(), "'"));
    const int n = d.clip_begin[static_cast<size_t>(from) + 1] - d.clip_begin[static_cast<size_t>(from)];
    if (request->from_frame() >= static_cast<uint32_t>(n)) {
      return InvalidField("from_frame", kinemo::StrCat(request->from_frame(), " is beyond the clip's ", n, " frames"));
    }
    thread_local loco::SearchWorkspace ws;
    loco::Transition tr;
    const auto t0 = std::chrono::steady_clock::now();
    KINEMO_RETURN_IF_ERROR(loco::PlanTransition(graph, d.clip_begin[static_cast<size_t>(from)] +
                                                           static_cast<int>(request->from_frame()),
                                                to, &ws, &tr));
    response->set_search_us(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    response->set_tbf_frames(tr.total_frames);
    response->set_response_frames(tr.response_frames);
    response->set_cost(loco::TransitionCost(graph, tr));
    for (size_t p = 0; p < tr.parts.size(); ++p) {
      const auto& pp = tr.parts[p];
      auto* out = response->add_paths();
      ToProto(graph.parts()[p].chains, out->mutable_part());
      out->set_origin_frame(static_cast<uint32_t>(d.FrameInClip(pp.origin)));
      out->set_target_frame(static_cast<uint32_t>(d.FrameInClip(pp.target)));
      out->set_start_offset_frames(static_cast<uint32_t>(pp.start));
      out->set_length_frames(static_cast<uint32_t>(pp.length));
      out->set_cost(pp.cost);
    }
    if (!request->metrics_only()) {
      KINEMO_ASSIGN_OR_RETURN(motion::Clip clip, loco::TransitionMotion(graph, tr));
      KINEMO_RETURN_IF_ERROR(ToProto(*d.library, clip,
                                     kinemo::StrCat(request->from_clip(), "_to_", request->to_clip()),
                                     request->format(), response->mutable_motion()));
    }
    return absl::OkStatus();
  };
  return FinishUnary(ctx, run());
}

grpc::ServerUnaryReactor* PlannerServiceImpl::EvaluateLocomotion(grpc::CallbackServerContext* ctx,
                                                                 const v1::EvaluateLocomotionRequest* request,
                                                                 v1::EvaluateLocomotionResponse* response) {
  auto* reactor = ctx->DefaultReactor();
  auto state = locomotion_;
  const int limit = options_.max_concurrent_builds() > 0 ? static_cast<int>(options_.max_concurrent_builds()) : 1;
  const v1::LocomotionGraphParams defaults = options_.locomotion_defaults();
  std::thread([this, ctx, reactor, request, response, state, limit, defaults]() {
    // The caller's deadline and cancellation stop the evaluation.
    const std::unique_ptr<CancelToken> cancel = CallCancelToken(*ctx);
    auto run = [&]() -> Status {
      KINEMO_ASSIGN_OR_RETURN(auto lib, libraries().Get(request->library_id(), "library_id"));
      loco::EvaluationOptions options;
      for (int i = 0; i < request->profiles_size(); ++i) {
        auto p = FromProto(request->profiles(i));
        if (!p.ok()) return Annotate(p.status(), kinemo::StrCat("profiles[", i, "]"));
        options.profiles.push_back(*std::move(p));
      }
      options.thresholds.assign(request->thresholds().begin(), request->thresholds().end());
      KINEMO_RETURN_IF_ERROR(CheckFitsInt(request->params(), "params"));
      KINEMO_ASSIGN_OR_RETURN(options.params, loco::ResolveParams(FromProto(request->params(), defaults)));
      options.maneuverability = request->include_maneuverability();
      options.threads = 1;
      options.cancel = cancel.get();
      BuildSlot slot(state->builds, limit);
      if (!slot.ok()) return absl::ResourceExhaustedError("max_concurrent_builds: too many builds running");
      KINEMO_ASSIGN_OR_RETURN(auto data, DataFor(*state, lib, options.params));
      KINEMO_ASSIGN_OR_RETURN(auto rows, loco::Evaluate(data, options));
      for (const auto& c : lib->clips) response->add_clips(c.name);
      response->set_frame_rate_hz(data->fps);
      for (const auto& r : rows) {
        auto* row = response->add_rows();
        row->set_method(r.method);
        row->set_threshold(r.threshold);
        row->set_connected_clips(static_cast<uint32_t>(r.connected_clips));
        row->set_tbf_frames(r.tbf_frames);
        row->set_response_frames(r.response_frames);
        row->set_connectivity(r.connectivity);
        row->set_cost(r.cost);
        for (double v : r.maneuverability) row->add_maneuverability(v);
      }
      response->set_request_id(request->request_id());
      return absl::OkStatus();
    };
    reactor->Finish(ToGrpcStatus(run()));
  }).detach();
  return reactor;
}

// ---- Drive

namespace {

class DriveReactor : public grpc::ServerBidiReactor<v1::DriveRequest, v1::DriveResponse> {
 public:
  DriveReactor(PlannerServiceImpl* service, std::shared_ptr<LocoState> state) : service_(service), state_(state) {
    const uint32_t limit = service->options().max_concurrent_streams() > 0 ? service->options().max_concurrent_streams() : 1024;
    if (!slot_.Take(&state_->streams, static_cast<int>(limit))) {
      Finish(ToGrpcStatus(absl::ResourceExhaustedError("max_concurrent_streams: too many streams")));
      return;
    }
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    const Status st = ok ? Handle(request_) : absl::OkStatus();
    if (ok && st.ok()) {
      StartRead(&request_);
      return;
    }
    // Half-close, cancel or a bad message: the worker (if any) finishes.
    bool finish_here = false;
    {
      std::lock_guard lock(mu_);
      if (!st.ok()) error_ = st;
      closed_ = true;
      cv_.notify_all();
      if (!started_ && !finished_) finish_here = finished_ = true;
    }
    if (finish_here) {
      slot_.Release();  // before the client hears the end
      Finish(ToGrpcStatus(st));
    }
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard lock(mu_);
    writing_ = false;
    if (!ok) closed_ = true;
    cv_.notify_all();
  }

  void OnCancel() override {
    std::lock_guard lock(mu_);
    cancelled_ = true;
    closed_ = true;
    cv_.notify_all();
  }

  void OnDone() override {
    if (worker_.joinable()) {
      // Finish may run OnDone on the worker itself, as its last action.
      if (worker_.get_id() == std::this_thread::get_id()) {
        worker_.detach();
      } else {
        worker_.join();
      }
    }
    delete this;
  }

 private:
  Status Handle(const v1::DriveRequest& req) {
    if (!driver_) {
      if (!req.has_config()) return InvalidField("config", "must be the first message");
      const auto& c = req.config();
      KINEMO_ASSIGN_OR_RETURN(auto stored, state_->graphs.Get(c.graph_id(), "config.graph_id"));
      loco::DriveParams p;
      p.idle_clip = c.idle_clip();
      p.walk_clip = c.walk_clip();
      p.run_clip = c.run_clip();
      p.start.position_m = Eigen::Vector2d(c.start_position_m().x(), c.start_position_m().y());
      p.start.heading_rad = c.start_heading_deg() * std::numbers::pi / 180;
      const auto& o = service_->options();
      p.walk_min_speed = o.walk_min_speed();
      p.run_min_speed = o.run_min_speed();
      p.arrival_radius_m = o.arrival_radius_m();
      KINEMO_ASSIGN_OR_RETURN(auto drv, loco::AvatarDriver::Create(stored->graph, p));
      graph_ = stored;
      driver_ = std::move(drv);
      const double fps = stored->graph->data().fps;
      const double tick = o.drive_tick_s() > 0 ? o.drive_tick_s() : 1.0 / fps;
      frames_per_tick_ = std::max(1, static_cast<int>(std::lround(tick * fps)));
      {
        std::lock_guard lock(mu_);
        started_ = true;
      }
      worker_ = std::thread([this]() { Run(); });
      return absl::OkStatus();
    }
    std::lock_guard lock(mu_);
    switch (req.message_case()) {
      case v1::DriveRequest::kConfig:
        return InvalidField("config", "sent twice");
      case v1::DriveRequest::kSpeed:
        if (!std::isfinite(req.speed()) || req.speed() < 0 || req.speed() > 5.55 + 1e-9) {
          return InvalidField("speed", "must be in [0, 5.55]");
        }
        break;
      case v1::DriveRequest::kCubeAngleDeg:
        if (!std::isfinite(req.cube_angle_deg())) return InvalidField("cube_angle_deg", "must be finite");
        break;
      case v1::DriveRequest::kTargetM:
        if (!std::isfinite(req.target_m().x()) || !std::isfinite(req.target_m().y())) {
          return InvalidField("target_m", "must be finite");
        }
        break;
      case v1::DriveRequest::kPath:
        if (req.path().points_m_size() == 0 || req.path().points_m_size() > 1000) {
          return InvalidField("path.points_m", "needs 1 to 1000 points");
        }
        break;
      default:
        break;
    }
    pending_.push_back(req);
    return absl::OkStatus();
  }

  void Apply(const v1::DriveRequest& req) {
    switch (req.message_case()) {
      case v1::DriveRequest::kSpeed:
        (void)driver_->SetSpeed(req.speed());
        break;
      case v1::DriveRequest::kCubeAngleDeg:
        (void)driver_->SetSpeed(loco::CubeAngleToSpeed(req.cube_angle_deg()));
        break;
      case v1::DriveRequest::kTargetM:
        driver_->SetTarget(Eigen::Vector2d(req.target_m().x(), req.target_m().y()));
        break;
      case v1::DriveRequest::kPath: {
        std::vector<Eigen::Vector2d> pts;
        for (const auto& p : req.path().points_m()) pts.emplace_back(p.x(), p.y());
        (void)driver_->SetPath(std::move(pts), req.path().loop());
        break;
      }
      case v1::DriveRequest::kStop:
        driver_->Stop();
        break;
      default:
        break;
    }
  }

  // Waits for the write in flight; false when the stream is over.
  bool Write(const v1::DriveResponse& r) {
    std::unique_lock lock(mu_);
    if (cancelled_) return false;
    writing_ = true;
    lock.unlock();
    StartWrite(&r);
    lock.lock();
    cv_.wait(lock, [&] { return !writing_; });
    return !cancelled_;
  }

  void Run() {
    const loco::LocomotionData& d = graph_->graph->data();
    {
      v1::DriveResponse header;
      ToProto(*d.library, header.mutable_header()->mutable_skeleton());
      header.mutable_header()->set_frame_time_s(1.0 / d.fps);
      if (!Write(header)) return FinishOnce(grpc::Status::CANCELLED);
    }
    const auto start = std::chrono::steady_clock::now();
    int64_t frames = 0;
    std::vector<double> row(static_cast<size_t>(d.library->skeleton.num_channels()));
    v1::DriveResponse out;
    while (true) {
      std::deque<v1::DriveRequest> commands;
      bool end = false;
      grpc::Status end_status;
      {
        std::unique_lock lock(mu_);
        const auto due = start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                     std::chrono::duration<double>(static_cast<double>(frames) / d.fps));
        cv_.wait_until(lock, due, [&] { return cancelled_ || (closed_ && pending_.empty()); });
        if (cancelled_) {
          end = true;
          end_status = grpc::Status::CANCELLED;
        } else if (closed_ && pending_.empty()) {
          end = true;
          end_status = error_.ok() ? grpc::Status::OK : ToGrpcStatus(error_);
        }
        commands.swap(pending_);
      }
      if (end) return FinishOnce(end_status);
      for (const auto& c : commands) Apply(c);
      out.Clear();
      bool reached = false;
      for (int k = 0; k < frames_per_tick_; ++k) {
        driver_->Step(row);
        auto* f = out.mutable_frames()->add_frames();
        f->set_time_s(static_cast<double>(frames) / d.fps);
        f->mutable_values()->Add(row.begin(), row.end());
        ++frames;
        reached = reached || driver_->status().target_reached;
      }
      const auto& st = driver_->status();
      auto* s = out.mutable_status();
      s->set_time_s(static_cast<double>(frames - 1) / d.fps);
      s->mutable_position_m()->set_x(st.root.position_m.x());
      s->mutable_position_m()->set_y(st.root.position_m.y());
      s->set_heading_deg(st.root.heading_rad * 180 / std::numbers::pi);
      s->set_speed_mps(st.speed_mps);
      static const v1::LocomotionState kStates[] = {v1::LOCOMOTION_STATE_IDLE, v1::LOCOMOTION_STATE_WALK,
                                                    v1::LOCOMOTION_STATE_RUN, v1::LOCOMOTION_STATE_TRANSITION};
      s->set_state(kStates[static_cast<int>(st.state)]);
      s->set_distance_to_target_m(st.distance_to_target_m);
      s->set_target_reached(reached);
      if (!Write(out)) return FinishOnce(grpc::Status::CANCELLED);
    }
  }

  // The worker's last action: nothing of `this` is touched after Finish.
  void FinishOnce(const grpc::Status& status) {
    {
      std::lock_guard lock(mu_);
      if (finished_) return;
      finished_ = true;
    }
    slot_.Release();  // before the client hears the end
    Finish(status);
  }

  PlannerServiceImpl* service_;
  std::shared_ptr<LocoState> state_;
  CallSlot slot_;  // max_concurrent_streams
  v1::DriveRequest request_;
  std::shared_ptr<const StoredGraph> graph_;
  std::unique_ptr<loco::AvatarDriver> driver_;
  int frames_per_tick_ = 1;
  std::thread worker_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<v1::DriveRequest> pending_;
  bool closed_ = false, cancelled_ = false, writing_ = false, finished_ = false, started_ = false;
  Status error_;
};

}  // namespace

grpc::ServerBidiReactor<v1::DriveRequest, v1::DriveResponse>* PlannerServiceImpl::Drive(
    grpc::CallbackServerContext* /*ctx*/) {
  return new DriveReactor(this, locomotion_);
}

}  // namespace kinemo::planner

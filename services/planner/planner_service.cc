#include "services/planner/planner_service.h"

#include <filesystem>

#include "common/grpc/status_mapping.h"
#include "services/planner/gesture/phrases.h"

namespace kinemo::planner {
namespace fs = std::filesystem;

grpc::ServerUnaryReactor* FinishUnary(grpc::CallbackServerContext* ctx, const Status& status) {
  auto* r = ctx->DefaultReactor();
  r->Finish(ToGrpcStatus(status));
  return r;
}

StatusOr<std::shared_ptr<PlannerServiceImpl>> PlannerServiceImpl::Create(const v1::PlannerOptions& options) {
  auto svc = std::shared_ptr<PlannerServiceImpl>(new PlannerServiceImpl(options));
  for (int i = 0; i < options.preload_size(); ++i) {
    std::vector<std::string> warnings;
    auto lib = svc->LoadAndStore(options.preload(i), &warnings);
    if (!lib.ok()) return Annotate(lib.status(), kinemo::StrCat("preload[", i, "]"));
  }
  for (int i = 0; i < options.preload_gesture_graphs_size(); ++i) {
    v1::BuildGestureGraphResponse built;
    const Status s = svc->BuildAndStoreGestureGraph(&options.preload_gesture_graphs(i), &built);
    if (!s.ok()) return Annotate(s, kinemo::StrCat("preload_gesture_graphs[", i, "]"));
  }
  return svc;
}

StatusOr<std::string> PlannerServiceImpl::ResolvePath(const std::string& relative, std::string_view field) const {
  if (options_.library_root().empty()) {
    return absl::FailedPreconditionError(
        kinemo::StrCat(field, ": server-side paths are disabled (no library_root)"));
  }
  std::error_code ec;
  const fs::path root = fs::weakly_canonical(options_.library_root(), ec);
  const fs::path p = fs::weakly_canonical(fs::path(options_.library_root()) / relative, ec);
  const std::string rs = root.string(), ps = p.string();
  if (fs::path(relative).is_absolute() || ps.compare(0, rs.size(), rs) != 0 ||
      (ps.size() > rs.size() && ps[rs.size()] != '/')) {
    return absl::FailedPreconditionError(kinemo::StrCat(field, ": '", relative, "' is outside library_root"));
  }
  return ps;
}

StatusOr<std::shared_ptr<const Library>> PlannerServiceImpl::LoadAndStore(const v1::LoadLibraryRequest& request,
                                                                          std::vector<std::string>* warnings) {
  if (!IsValidId(request.library_id())) return InvalidField("library_id", "must match [a-z0-9_-]{1,64}");
  if (request.meters_per_unit() < 0) return InvalidField("meters_per_unit", "must be >= 0");
  if (!request.overwrite() && libraries_.Version(request.library_id()) > 0) {
    return absl::AlreadyExistsError(
        kinemo::StrCat("library_id: '", request.library_id(), "' exists (set overwrite)"));
  }
  LibrarySources sources;
  for (int i = 0; i < request.paths_size(); ++i) {
    KINEMO_ASSIGN_OR_RETURN(std::string p, ResolvePath(request.paths(i), kinemo::StrCat("paths[", i, "]")));
    sources.paths.push_back(std::move(p));
  }
  for (const auto& c : request.clips()) {
    sources.inline_clips.push_back({c.name(), c.bvh(), c.tone(), {c.keywords().begin(), c.keywords().end()}});
  }
  sources.meters_per_unit = request.meters_per_unit() > 0 ? request.meters_per_unit()
                                                          : options_.default_meters_per_unit();
  if (options_.max_library_clips() > 0) sources.max_clips = options_.max_library_clips();
  KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<Library> lib, planner::LoadLibrary(request.library_id(), sources));
  // gesture: a malformed gesture-phrase annotation in a manifest is bad input.
  for (const auto& c : lib->clips) {
    if (c.annotation_json.empty()) continue;
    if (auto st = gesture::ExtractPhrases(*lib).status(); absl::IsInvalidArgument(st)) return st;
    break;
  }
  *warnings = lib->warnings;
  KINEMO_RETURN_IF_ERROR(libraries_.Put(request.library_id(), lib, request.overwrite()).status());
  return std::shared_ptr<const Library>(std::move(lib));
}

void ToProto(const Library& library, v1::LibraryInfo* out) {
  out->set_library_id(library.id);
  out->set_version(static_cast<uint32_t>(library.version));
  out->set_duration_s(library.duration_s());
  out->set_frame_rate_hz(library.frame_rate_hz);
  for (const auto& c : library.clips) {
    auto* ci = out->add_clips();
    ci->set_name(c.name);
    ci->set_frames(static_cast<uint32_t>(c.clip.num_frames()));
    ci->set_frame_time_s(c.clip.frame_time_s);
    ci->set_duration_s(c.clip.duration_s());
    ci->set_tone(c.tone);
    for (const auto& k : c.keywords) ci->add_keywords(k);
    // Gesture segments (Gesture Controller segmentation, default options).
    auto segments = controller::CountSegments(c.clip, {});
    ci->set_segments(segments.ok() ? static_cast<uint32_t>(*segments) : 0);
    out->set_segments(out->segments() + ci->segments());
  }
  // gesture: phrases per clip (annotation where given, else automatic).
  if (auto phrases = gesture::ExtractPhrases(library); phrases.ok()) {
    for (size_t i = 0; i < phrases->clip_counts.size(); ++i) {
      out->mutable_clips(static_cast<int>(i))->set_phrases(static_cast<uint32_t>(phrases->clip_counts[i]));
    }
    out->set_phrases(static_cast<uint32_t>(phrases->phrases.size()));
  }
  for (const auto& t : library.tones()) out->add_tones(t);
  for (const auto& k : library.keywords()) out->add_keywords(k);
}

grpc::ServerUnaryReactor* PlannerServiceImpl::LoadLibrary(grpc::CallbackServerContext* ctx,
                                                          const v1::LoadLibraryRequest* request,
                                                          v1::LoadLibraryResponse* response) {
  std::vector<std::string> warnings;
  auto lib = LoadAndStore(*request, &warnings);
  if (!lib.ok()) return FinishUnary(ctx, lib.status());
  ToProto(**lib, response->mutable_library());
  for (auto& w : warnings) response->add_warnings(w);
  response->set_request_id(request->request_id());
  return FinishUnary(ctx, absl::OkStatus());
}

}  // namespace kinemo::planner

#include "services/planner/rpc/planner_service.h"

#include <filesystem>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
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
  KINEMO_RETURN_IF_ERROR(svc->OpenStore());
  // Preloads seed a fresh store: an id the store holds is served from it.
  for (int i = 0; i < options.preload_size(); ++i) {
    if (svc->store_->Get(store::kLibraries, options.preload(i).library_id()).ok()) {
      log::Info("preload_skipped", {{"library_id", options.preload(i).library_id()}, {"reason", "in the store"}});
      continue;
    }
    std::vector<std::string> warnings;
    auto lib = svc->LoadAndStore(options.preload(i), &warnings);
    if (!lib.ok()) return Annotate(lib.status(), kinemo::StrCat("preload[", i, "]"));
  }
  for (int i = 0; i < options.preload_gesture_graphs_size(); ++i) {
    if (svc->store_->Get(store::kGestureGraphs, options.preload_gesture_graphs(i).graph_id()).ok()) {
      log::Info("preload_skipped",
                {{"graph_id", options.preload_gesture_graphs(i).graph_id()}, {"reason", "in the store"}});
      continue;
    }
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

namespace {

// Kind-specific summary of a stored library.
std::string LibrarySummary(const Library& lib) {
  return nlohmann::json{{"clips", lib.clips.size()},
                        {"duration_s", lib.duration_s()},
                        {"frame_rate_hz", lib.frame_rate_hz},
                        {"meters_per_unit", lib.meters_per_unit},
                        {"joints", lib.skeleton.num_joints()},
                        {"tones", lib.tones()},
                        {"keywords", lib.keywords()}}
      .dump();
}

bool EndsWithIgnoreCase(std::string_view s, std::string_view suffix) {
  if (s.size() < suffix.size()) return false;
  for (size_t i = 0; i < suffix.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(s[s.size() - suffix.size() + i])) !=
        std::tolower(static_cast<unsigned char>(suffix[i]))) {
      return false;
    }
  }
  return true;
}

// A malformed gesture-phrase annotation in a manifest is bad input.
Status CheckAnnotations(const Library& lib) {
  for (const auto& c : lib.clips) {
    if (c.annotation_json.empty()) continue;
    if (auto st = gesture::ExtractPhrases(lib).status(); absl::IsInvalidArgument(st)) return st;
    break;
  }
  return absl::OkStatus();
}

// LoadLibraryRequest.segmentation: bounded like the controller's own
// parameters (segments.cc), though loading a library does not segment.
Status CheckSegmentation(const v1::SegmentationParams& s) {
  if (!(s.hand_speed_threshold_mps() >= 0 && s.hand_speed_threshold_mps() <= 10)) {
    return InvalidField("segmentation.hand_speed_threshold_mps", s.hand_speed_threshold_mps(), " is outside [0, 10]");
  }
  if (!(s.min_segment_s() >= 0 && s.min_segment_s() <= 60)) {
    return InvalidField("segmentation.min_segment_s", s.min_segment_s(), " is outside [0, 60]");
  }
  if (s.interruption_frames() > 16) {
    return InvalidField("segmentation.interruption_frames", s.interruption_frames(), " is outside [0, 16]");
  }
  return absl::OkStatus();
}

}  // namespace

StatusOr<std::shared_ptr<const Library>> PlannerServiceImpl::LoadAndStore(const v1::LoadLibraryRequest& request,
                                                                          std::vector<std::string>* warnings) {
  if (!IsValidId(request.library_id())) return InvalidField("library_id", "must match [a-z0-9_-]{1,64}");
  // 0 = the default; else a scale of BVH units (0.001 mm ... 1 m and some room).
  if (!(request.meters_per_unit() == 0 ||
        (request.meters_per_unit() >= kMinMetersPerUnit && request.meters_per_unit() <= kMaxMetersPerUnit))) {
    return InvalidField("meters_per_unit", request.meters_per_unit(), " is not 0 (the default) or in [",
                        kMinMetersPerUnit, ", ", kMaxMetersPerUnit, "]");
  }
  KINEMO_RETURN_IF_ERROR(CheckSegmentation(request.segmentation()));
  std::map<std::string, int> inline_names;
  for (int i = 0; i < request.clips_size(); ++i) {
    const auto [it, added] = inline_names.emplace(request.clips(i).name(), i);
    if (!added) {
      return InvalidField(kinemo::StrCat("clips[", i, "].name"), "\"", request.clips(i).name(),
                          "\" is also the name of clips[", it->second, "] (inline clip names must be unique)");
    }
  }
  KINEMO_RETURN_IF_ERROR(CheckNewVersion(store::kLibraries, request.library_id(), request.overwrite(), "library_id"));
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
  KINEMO_RETURN_IF_ERROR(CheckAnnotations(*lib));
  *warnings = lib->warnings;
  std::string description = "LoadLibrary";
  for (int i = 0; i < request.paths_size(); ++i) description += kinemo::StrCat(i == 0 ? " " : ", ", request.paths(i));
  if (request.clips_size() > 0) {
    description += kinemo::StrCat(request.paths_size() > 0 ? " + " : " ", request.clips_size(), " inline clips");
  }
  KINEMO_RETURN_IF_ERROR(StoreLibrary(lib, sources, description, request.overwrite(), "library_id").status());
  return std::shared_ptr<const Library>(std::move(lib));
}

StatusOr<store::ArtifactMeta> PlannerServiceImpl::StoreLibrary(std::shared_ptr<Library> library,
                                                               const LibrarySources& sources, std::string description,
                                                               bool overwrite, std::string_view field) {
  KINEMO_ASSIGN_OR_RETURN(store::Draft draft, store_->Begin(store::kLibraries, library->id));
  KINEMO_RETURN_IF_ERROR(WriteLibraryFiles(*library, sources, draft.dir()));
  store::ArtifactMeta meta;
  meta.description = std::move(description);
  meta.summary_json = LibrarySummary(*library);
  return CommitArtifact(std::move(draft), std::move(meta), overwrite, field,
                        [&](int version) { libraries_.Set(library->id, library, version); });
}

StatusOr<std::shared_ptr<Library>> PlannerServiceImpl::ReadStoredLibrary(const store::ArtifactMeta& meta) const {
  LibrarySources sources;
  sources.paths.push_back(store_->FilePath(meta.ref(), "manifest.json"));
  if (options_.max_library_clips() > 0) sources.max_clips = options_.max_library_clips();
  KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<Library> lib, planner::LoadLibrary(meta.id, sources));
  lib->version = static_cast<int>(meta.version);
  return lib;
}

StatusOr<std::shared_ptr<const Library>> PlannerServiceImpl::StoredLibrary(const std::string& id,
                                                                           std::uint32_t version,
                                                                           std::string_view field) {
  auto meta = store_->Get(store::kLibraries, id, version);
  if (!meta.ok()) {
    return Status(meta.status().code(),
                  kinemo::StrCat(field, ": no library '", id, "'", version > 0 ? kinemo::StrCat(" version ", version) : ""));
  }
  auto served = libraries_.Get(id, field);
  if (served.ok() && (*served)->version == static_cast<int>(meta->version)) return *served;
  KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<Library> lib, ReadStoredLibrary(*meta));
  return std::shared_ptr<const Library>(std::move(lib));
}

StatusOr<std::shared_ptr<const Library>> PlannerServiceImpl::DependencyLibrary(const store::ArtifactMeta& meta) {
  for (const auto& d : meta.depends_on) {
    if (d.kind == store::kLibraries) return StoredLibrary(d.id, d.version, "depends_on");
  }
  return absl::FailedPreconditionError(
      kinemo::StrCat(store::RefString(meta.ref()), ": depends on no library (artifact.json depends_on)"));
}

StatusOr<common::v1::PushArtifactResponse> PlannerServiceImpl::PushLibrary(
    store::Draft draft, const common::v1::PushArtifactHeader& header) {
  // BVH clips in any folder, and an optional manifest.json at the top.
  std::set<std::string> names;
  bool has_manifest = false;
  int clips = 0;
  for (int i = 0; i < header.files_size(); ++i) {
    const std::string& name = header.files(i).name();
    names.insert(name);
    if (name == "manifest.json") {
      has_manifest = true;
    } else if (EndsWithIgnoreCase(name, ".bvh")) {
      ++clips;
    } else {
      return InvalidField(kinemo::StrCat("header.files[", i, "].name"), "'", name,
                          "' is neither a .bvh clip nor manifest.json");
    }
  }
  if (clips == 0) {
    return InvalidField("header.files", "no .bvh clips (a library is BVH files and an optional manifest.json)");
  }
  const std::string& id = header.ref().id();
  KINEMO_RETURN_IF_ERROR(CheckNewVersion(store::kLibraries, id, header.overwrite(), "header.ref.id"));
  LibrarySources sources;
  if (options_.max_library_clips() > 0) sources.max_clips = options_.max_library_clips();
  sources.meters_per_unit = options_.default_meters_per_unit();
  if (has_manifest) {
    // Its clips must be files of this push (no paths outside it).
    const std::string path = draft.dir() + "/manifest.json";
    KINEMO_ASSIGN_OR_RETURN(std::string text, ReadArtifactFile(path, "header.files: manifest.json"));
    const nlohmann::json manifest = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (manifest.is_discarded() || !manifest.is_object() || !manifest.contains("clips") ||
        !manifest["clips"].is_array()) {
      return InvalidField("header.files", "manifest.json: not a JSON object with a list of clips");
    }
    int k = 0;
    for (const auto& entry : manifest["clips"]) {
      const std::string field = kinemo::StrCat("header.files: manifest.json: clips[", k++, "].path");
      if (!entry.is_object() || !entry.contains("path") || !entry["path"].is_string()) {
        return InvalidField(field, "missing");
      }
      const std::string clip = entry["path"].get<std::string>();
      KINEMO_RETURN_IF_ERROR(store::ValidateFileName(clip, field));
      if (!names.count(clip)) return InvalidField(field, "'", clip, "' is not one of the pushed files");
    }
    if (manifest.contains("meters_per_unit")) sources.meters_per_unit = 0;  // the manifest's
    sources.paths.push_back(path);
  } else {
    sources.paths.push_back(draft.dir());  // every *.bvh, in name order
  }
  auto lib = planner::LoadLibrary(id, sources);
  if (!lib.ok()) return PushError(lib.status(), draft, "header.files");
  if (Status s = CheckAnnotations(**lib); !s.ok()) return PushError(s, draft, "header.files");
  KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta meta,
                          StoreLibrary(*lib, sources, header.description(), header.overwrite(), "header.ref.id"));
  common::v1::PushArtifactResponse response;
  *response.mutable_artifact() = kinemo::ToProto(meta);
  for (const auto& w : (*lib)->warnings) {
    response.add_warnings(std::string(PushError(absl::UnknownError(w), draft, "").message()));
  }
  return response;
}

PlannerServiceImpl::ArtifactKind PlannerServiceImpl::LibraryKind() {
  ArtifactKind k;
  k.kind = std::string(store::kLibraries);
  k.served_version = [this](const std::string& id) { return libraries_.Version(id); };
  k.serve = [this](const store::ArtifactMeta& meta) -> Status {
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<Library> lib, ReadStoredLibrary(meta));
    libraries_.Set(meta.id, std::move(lib), static_cast<int>(meta.version));
    return absl::OkStatus();
  };
  k.unserve = [this](const std::string& id) { libraries_.Remove(id); };
  k.push = [this](store::Draft draft, const common::v1::PushArtifactHeader& header) {
    return PushLibrary(std::move(draft), header);
  };
  return k;
}

void SkeletonToProto(const motion::Skeleton& skeleton, double meters_per_unit, const motion::BodyRegionMap& regions,
                     std::string_view name, common::v1::Skeleton* out) {
  out->set_meters_per_unit(meters_per_unit);
  out->set_name(std::string(name));
  for (int j = 0; j < skeleton.num_joints(); ++j) {
    const motion::Joint& jt = skeleton.joint(j);
    auto* o = out->add_joints();
    o->set_name(jt.name);
    o->set_parent_index(jt.parent);
    o->mutable_offset()->set_x(jt.offset.x());
    o->mutable_offset()->set_y(jt.offset.y());
    o->mutable_offset()->set_z(jt.offset.z());
    for (auto c : jt.channels) o->add_channels(static_cast<common::v1::Channel>(static_cast<int>(c) + 1));
    if (jt.end_site) {
      o->set_has_end_site(true);
      o->mutable_end_site_offset()->set_x(jt.end_site->x());
      o->mutable_end_site_offset()->set_y(jt.end_site->y());
      o->mutable_end_site_offset()->set_z(jt.end_site->z());
    }
    if (static_cast<size_t>(j) < regions.region.size()) {
      o->set_region(static_cast<common::v1::BodyRegion>(static_cast<int>(regions.region[static_cast<size_t>(j)]) + 1));
    }
  }
}

void ClipToProto(const motion::Clip& clip, double meters_per_unit, const motion::BodyRegionMap& regions,
                 std::string_view name, common::v1::MotionClip* out) {
  SkeletonToProto(clip.skeleton, meters_per_unit, regions, name, out->mutable_skeleton());
  out->set_frame_time_s(clip.frame_time_s);
  for (int f = 0; f < clip.num_frames(); ++f) {
    auto* fr = out->add_frames();
    fr->set_time_s(f * clip.frame_time_s);
    const auto v = clip.frame(f);
    fr->mutable_values()->Assign(v.begin(), v.end());
  }
}

Status MotionToProto(const motion::Clip& clip, double meters_per_unit, const motion::BodyRegionMap& regions,
                     std::string_view skeleton_name, std::string_view clip_name, common::v1::MotionFormat format, const motion::BvhWriteOptions& bvh,
                     common::v1::Motion* out) {
  if (format == common::v1::MOTION_FORMAT_CLIP) {
    auto* c = out->mutable_clip();
    ClipToProto(clip, meters_per_unit, regions, skeleton_name, c);
    c->set_name(std::string(clip_name));
    return absl::OkStatus();
  }
  KINEMO_ASSIGN_OR_RETURN(std::string text, motion::WriteBvh(clip, bvh));
  out->set_bvh(std::move(text));
  return absl::OkStatus();
}

StatusOr<std::unique_ptr<MotionChunker>> MotionChunker::Create(MotionOut motion, common::v1::MotionFormat format) {
  std::unique_ptr<MotionChunker> c(new MotionChunker(std::move(motion)));
  c->clip_format_ = format == common::v1::MOTION_FORMAT_CLIP;
  if (c->clip_format_) {
    KINEMO_RETURN_IF_ERROR(c->motion_.clip.Validate());
  } else {
    // The writer points at the chunker's own clip, which stays where it is.
    KINEMO_ASSIGN_OR_RETURN(motion::BvhTextWriter w, motion::BvhTextWriter::Create(c->motion_.clip, c->motion_.bvh));
    c->bvh_.emplace(std::move(w));
  }
  return c;
}

bool MotionChunker::Next(common::v1::MotionChunk* out) {
  // Below 1 MiB by more than a frame line (a few kB) or a frame's values.
  constexpr std::size_t kPieceBytes = 960 << 10;
  const motion::Clip& clip = motion_.clip;
  if (!clip_format_) {
    std::string* text = out->mutable_bvh();
    text->reserve(kPieceBytes + 16384);
    if (bvh_->Next(kPieceBytes, text)) return true;
    out->Clear();
    return false;
  }
  if (!header_sent_) {
    header_sent_ = true;
    SkeletonToProto(clip.skeleton, motion_.meters_per_unit, motion_.regions, motion_.skeleton_name,
                    out->mutable_header()->mutable_skeleton());
    out->mutable_header()->set_frame_time_s(clip.frame_time_s);
    return true;
  }
  if (next_frame_ >= clip.num_frames()) return false;
  const int per_frame = static_cast<int>(clip.frames.cols()) * 9 + 24;  // packed doubles and the frame's fields
  const int end = std::min(clip.num_frames(), next_frame_ + std::max(1, static_cast<int>(kPieceBytes) / per_frame));
  auto* batch = out->mutable_frames();
  for (; next_frame_ < end; ++next_frame_) {
    auto* fr = batch->add_frames();
    fr->set_time_s(next_frame_ * clip.frame_time_s);
    const auto v = clip.frame(next_frame_);
    fr->mutable_values()->Assign(v.begin(), v.end());
  }
  return true;
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

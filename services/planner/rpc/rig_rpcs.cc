// "rigs" artifacts of the planner: users' characters (one GLB/VRM file),
// and the motion of a request on one (rig_motion.h).
#include <filesystem>

#include "services/planner/rpc/planner_service.h"

namespace kinemo::planner {

StatusOr<std::unique_ptr<rig::RigMotion>> PlannerServiceImpl::MotionOnRig(const std::string& rig_id,
                                                                          const Library& library, double frame_time_s,
                                                                          std::string_view field) {
  if (rig_id.empty()) return std::unique_ptr<rig::RigMotion>();
  auto stored = rigs_.Get(rig_id, field);
  if (!stored.ok()) {
    return absl::NotFoundError(
        kinemo::StrCat(field, ": no rig '", rig_id, "' is stored (kinemo rig push RIG.glb --name ", rig_id, ")"));
  }
  auto motion = rig::RigMotion::Create(library, *stored, frame_time_s);
  if (!motion.ok()) {
    return Status(motion.status().code(), kinemo::StrCat(field, ": rig '", rig_id, "' cannot take the motion of library '",
                                                         library.id, "': ", motion.status().message()));
  }
  return motion;
}

PlannerServiceImpl::ArtifactKind PlannerServiceImpl::RigKind() {
  ArtifactKind k;
  k.kind = std::string(store::kRigs);
  k.served_version = [this](const std::string& id) { return rigs_.Version(id); };
  k.unserve = [this](const std::string& id) { rigs_.Remove(id); };
  k.serve = [this](const store::ArtifactMeta& meta) -> Status {
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<rig::StoredRig> stored,
                            rig::LoadStoredRig(store_->FilePath(meta.ref(), rig::kRigFile)));
    stored->name = kinemo::StrCat("rig:", meta.id);
    rigs_.Set(meta.id, std::move(stored), static_cast<int>(meta.version));
    return absl::OkStatus();
  };
  // One .glb or .vrm file (kinemo rig push), checked by reading its skin and
  // role map, stored as rig.glb.
  k.push = [this](store::Draft draft,
                  const common::v1::PushArtifactHeader& header) -> StatusOr<common::v1::PushArtifactResponse> {
    const std::string name = header.files_size() == 1 ? header.files(0).name() : "";
    const std::string ext = std::filesystem::path(name).extension().string();
    if (header.files_size() != 1 || (ext != ".glb" && ext != ".vrm")) {
      return InvalidField("header.files", "a rig is one .glb or .vrm file (kinemo rig push RIG.glb)");
    }
    const std::string& id = header.ref().id();
    KINEMO_RETURN_IF_ERROR(CheckNewVersion(store::kRigs, id, header.overwrite(), "header.ref.id"));
    const std::string path = kinemo::StrCat(draft.dir(), "/", name);
    auto loaded = rig::LoadStoredRig(path);
    if (!loaded.ok()) return PushError(loaded.status(), draft, "header.files[0]");
    std::shared_ptr<rig::StoredRig> stored = *std::move(loaded);
    stored->name = kinemo::StrCat("rig:", id);
    if (name != rig::kRigFile) {
      std::error_code ec;
      std::filesystem::rename(path, kinemo::StrCat(draft.dir(), "/", rig::kRigFile), ec);
      if (ec) return absl::InternalError(kinemo::StrCat("store: cannot rename ", name, ": ", ec.message()));
    }
    store::ArtifactMeta meta;
    meta.description = header.description();
    meta.summary_json = stored->summary_json;
    KINEMO_ASSIGN_OR_RETURN(meta, CommitArtifact(std::move(draft), std::move(meta), header.overwrite(),
                                                 "header.ref.id",
                                                 [&](int version) { rigs_.Set(id, stored, version); }));
    common::v1::PushArtifactResponse response;
    *response.mutable_artifact() = kinemo::ToProto(meta);
    return response;
  };
  return k;
}

}  // namespace kinemo::planner

#include "services/planner/rig/rig_motion.h"

#include <nlohmann/json.hpp>

#include "common/retarget/face_map.h"
#include "common/retarget/measures.h"
#include "common/retarget/rig_info.h"

namespace kinemo::planner::rig {

StatusOr<std::shared_ptr<StoredRig>> LoadStoredRig(const std::string& path) {
  KINEMO_ASSIGN_OR_RETURN(retarget::Rig loaded, retarget::LoadGltfRig(path));
  KINEMO_RETURN_IF_ERROR(retarget::CheckRequiredRoles(loaded));
  auto stored = std::make_shared<StoredRig>();
  stored->regions = retarget::RegionsFromRoles(loaded);
  auto face = retarget::FaceMap::Create(loaded);
  if (!face.ok()) return face.status();
  stored->summary_json = retarget::RigSummaryJson(loaded, *face).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  stored->rig = std::make_shared<const retarget::Rig>(std::move(loaded));
  return stored;
}

StatusOr<std::unique_ptr<RigMotion>> RigMotion::Create(const Library& library, std::shared_ptr<const StoredRig> rig,
                                                       double frame_time_s) {
  KINEMO_ASSIGN_OR_RETURN(retarget::Rig source,
                          retarget::RigFromSkeleton(library.skeleton, library.meters_per_unit, library.id));
  retarget::RetargetOptions options;
  options.frame_time_s = frame_time_s;
  KINEMO_ASSIGN_OR_RETURN(retarget::Retargeter r,
                          retarget::Retargeter::Create(library.skeleton, source, *rig->rig, options));
  return std::unique_ptr<RigMotion>(new RigMotion(std::move(r), std::move(rig)));
}

StatusOr<motion::Clip> RigMotion::Clip(const motion::Clip& library_clip) {
  retargeter_.Reset();
  return retargeter_.RetargetClip(library_clip);
}

}  // namespace kinemo::planner::rig

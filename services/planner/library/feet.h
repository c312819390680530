// Foot planting (common/motion/feet.h) for motion made from a library's
// clips: every method (Gesture Controller, GMG, BodySpeech) plants with the
// library's scale and detects contacts from the level its clips stand at.
#pragma once

#include <vector>

#include "common/motion/feet.h"
#include "services/planner/library/library.h"

namespace kinemo::planner {

// `params` with contact.meters_per_unit (the library's, else 0.01) and
// contact.ground_height_m (EstimateGroundHeight over the clips) filled in.
// FAILED_PRECONDITION when the skeleton has no legs to plant.
inline StatusOr<motion::FootPlantParams> LibraryFootPlantParams(const Library& library,
                                                                motion::FootPlantParams params) {
  params.contact.meters_per_unit = library.meters_per_unit > 0 ? library.meters_per_unit : 0.01;
  KINEMO_ASSIGN_OR_RETURN(motion::FeetRig rig, motion::FeetRig::Find(library.skeleton, library.regions));
  std::vector<const motion::Clip*> clips;
  clips.reserve(library.clips.size());
  for (const LibraryClip& c : library.clips) clips.push_back(&c.clip);
  KINEMO_ASSIGN_OR_RETURN(params.contact.ground_height_m,
                          motion::EstimateGroundHeight(clips, rig, params.contact.meters_per_unit));
  return params;
}

}  // namespace kinemo::planner

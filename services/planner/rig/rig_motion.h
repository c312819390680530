// Motion on a user's rig: the planner's "rigs" artifacts (a character's
// GLB/VRM, common/retarget) and the retargeting of a library's motion onto
// one. Plain C++ (no gRPC); the RPC side is ../rpc/rig_rpcs.cc.
//
// A request that names a rig (SynthesizeRequest.rig_id, ControlConfig.rig_id,
// SynthesizeGesturesRequest.rig_id) gets its motion on the rig's skeleton:
// the library's clip, frame by frame, through a retarget::Retargeter from the
// library's skeleton (its role map detected) onto the rig, with the feet
// planted on the rig (RetargetOptions defaults).
#pragma once

#include <memory>
#include <span>
#include <string>

#include "common/motion/body_regions.h"
#include "common/motion/skeleton.h"
#include "common/retarget/retarget.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"
#include "services/planner/library/library.h"

namespace kinemo::planner::rig {

// The one file of a "rigs" version: a GLB (VRM 0.x/1.0 files are GLBs).
inline constexpr std::string_view kRigFile = "rig.glb";

// A rig served under its id (immutable once served).
struct StoredRig {
  int version = 0;
  std::string name;  // "rig:<id>": the skeleton's name in responses
  std::shared_ptr<const retarget::Rig> rig;
  motion::BodyRegionMap regions;  // from the rig's roles
  // {format, family, joints, mapped_roles, unmapped_roles, leg_length_m,
  //  face_channels_driven, mouth_family, jaw_bone} (retarget::RigSummaryJson)
  std::string summary_json;
};

// Reads and checks a rig file (a skin with the required roles): NOT_FOUND /
// INVALID_ARGUMENT as retarget::LoadGltfRig.
StatusOr<std::shared_ptr<StoredRig>> LoadStoredRig(const std::string& path);

// Retargets a library's motion onto a rig, frame by frame (one per stream or
// call: it keeps the previous frame for Euler unwrapping and foot planting).
class RigMotion {
 public:
  static StatusOr<std::unique_ptr<RigMotion>> Create(const Library& library, std::shared_ptr<const StoredRig> rig,
                                                     double frame_time_s);
  // One frame on the library's skeleton -> one on the rig's (num_channels()).
  // Allocation-free.
  Status Frame(std::span<const double> library_frame, std::span<double> rig_frame) {
    return retargeter_.RetargetFrame(library_frame, rig_frame);
  }
  // A whole clip on the library's skeleton (frame time kept).
  StatusOr<motion::Clip> Clip(const motion::Clip& library_clip);

  const motion::Skeleton& skeleton() const { return retargeter_.target_skeleton(); }
  int num_channels() const { return skeleton().num_channels(); }
  double meters_per_unit() const { return rig_->rig->meters_per_unit; }
  const motion::BodyRegionMap& regions() const { return rig_->regions; }
  const std::string& name() const { return rig_->name; }

 private:
  RigMotion(retarget::Retargeter r, std::shared_ptr<const StoredRig> rig)
      : retargeter_(std::move(r)), rig_(std::move(rig)) {}
  retarget::Retargeter retargeter_;
  std::shared_ptr<const StoredRig> rig_;
};

}  // namespace kinemo::planner::rig

// The AR view of the AvatAR (thesis §5.2): the character standing on the
// table beside the cube, drawn into the camera's frames. Plain C++/OpenCV
// (no gRPC): a small software rasteriser of the character's skinned mesh
// (common/retarget/mesh.h: linear-blend skinning), a z-buffer, Lambert
// lighting, and a contact shadow on the table.
//
// Frames (see cube/core/tracker.h): the surface frame has its origin on the
// table and z up; camera_from_surface is the table's pose in the camera (a
// calibrated surface, or the one the tracker took from the cube). The
// character's rig world is glTF's: y up, facing +z, metres, feet on y = 0.
// Its place (Placement) is a point of the table, a turn about the table's
// normal and a scale: surface = place + Rz(yaw) · A · scale · (x − origin),
// where A takes the rig's (x, y up, z forward) to the table's (z up):
// A·(x, y, z) = (x, −z, y), and origin is the hips' floor point of the
// clip's first frame (so that the character stays at its place while the
// clip sways).
#pragma once

#include <array>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/motion/skeleton.h"
#include "common/retarget/mesh.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/core/tracker.h"

namespace kinemo::cube::ar {

struct ArOptions {
  double character_height_m = 0.15;  // the character's standing height on the table
  double beside_m = 0.10;            // from the cube's centre along the camera's right, on the table
  double shadow_opacity = 0.35;      // contact shadow (0 = none)
};
Status ValidateArOptions(const ArOptions& options);

// Where and how big the character stands on the table.
struct Placement {
  cv::Vec2d position_m{0, 0};  // on the table (surface x, y)
  double yaw_rad = 0;          // turn about the table's normal of the character's forward
  double scale = 1;            // table metres per rig unit
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // rig point put at position_m (y ignored)
  double facing_rad = 0;       // the clip's own facing (its body's mean forward turned from +z about +y)
};

// The place beside the cube: `beside_m` from the cube's centre along the
// camera's right projected on the table, turned to face the camera.
// `rig_height` is the character's standing height in rig units.
Placement PlaceBeside(const cv::Vec2d& cube_position_m, const Pose& camera_from_surface, double rig_height,
                      const ArOptions& options);

// A rig point in the table's frame under a placement.
cv::Vec3d ToSurface(const Placement& placement, const Eigen::Vector3d& rig_point);

// What a drawn frame put where.
struct DrawInfo {
  bool drawn = false;
  int pixels = 0;                            // pixels of the character
  std::array<cv::Vec3d, 2> soles_surface_m;  // left, right sole (the foot's floor point) on the table frame
  std::array<cv::Point2d, 2> soles_px;       // and in the image
  std::array<Eigen::Vector3d, 2> soles_rig;  // and in the rig's world (posed)
  // The way the character's body faces, on the table (unit, surface x y):
  // perpendicular to its shoulder and hip lines (right -> left joints, the
  // two averaged), from the posed joints' positions.
  cv::Vec2d facing_surface{0, 0};
};

class CharacterView {
 public:
  // The character's mesh and its soles (the foot roles' end sites).
  static StatusOr<std::unique_ptr<CharacterView>> Create(std::shared_ptr<const retarget::Rig> rig,
                                                         double shadow_opacity = 0.35);

  // Draws the character posed by `frame` (channel values of the rig's
  // skeleton) at `placement` over `bgr` (8-bit BGR, the camera's size).
  Status Draw(std::span<const double> frame, const Placement& placement, const CameraModel& camera,
              const Pose& camera_from_surface, cv::Mat* bgr, DrawInfo* info);

  const retarget::Rig& rig() const { return *rig_; }
  // Standing height of the bind pose, rig units.
  double height() const { return static_cast<double>(mesh_.max_corner.y() - std::min(0.0f, mesh_.min_corner.y())); }

 private:
  CharacterView() = default;
  std::shared_ptr<const retarget::Rig> rig_;
  retarget::CharacterMesh mesh_;
  double shadow_opacity_ = 0.35;
  std::array<int, 2> sole_joint_{-1, -1};
  std::array<Eigen::Vector3d, 2> sole_offset_;
  // Scratch.
  retarget::SkinPose pose_;
  std::vector<Eigen::Vector3f> skinned_, normals_;
  std::vector<cv::Point3d> surface_;
  std::vector<cv::Point2d> image_;
  std::vector<double> depth_;
  cv::Mat1f zbuffer_;
};

// The character's motion per cube action: a clip per action (retargeted onto
// the rig, looping), the one the cube selects playing; a change of action
// starts the new clip from its beginning (a cut: no cross-fade).
class ActionPlayer {
 public:
  struct Source {
    Action action = Action::kIdle;
    motion::Clip clip;             // on any kinemo skeleton
    double meters_per_unit = 0;    // 0 = estimated from its legs
  };
  static StatusOr<ActionPlayer> Create(const retarget::Rig& rig, std::vector<Source> sources);

  // The frame for `action` at `time_s` (a monotonic clock); an action without
  // a clip keeps the previous one. Returns the rig's channel values, and the
  // clip's origin and facing in `placement`.
  std::span<const double> At(Action action, double time_s, Placement* placement);
  Action playing() const { return playing_; }

 private:
  struct Played {
    Action action = Action::kUnknown;
    motion::Clip clip;  // on the rig
    Eigen::Vector3d origin = Eigen::Vector3d::Zero();
    double facing_rad = 0;
  };
  std::vector<Played> clips_;
  Action playing_ = Action::kUnknown;
  int current_ = -1;
  double started_s_ = 0;
};

// The overlay of one tracked video: per frame, the tracker's state places the
// character (beside the cube where it was last seen; nothing before the cube
// was first seen or the table is known) and selects the action it plays
// (unknown: idle); the frame is drawn over.
class ArOverlay {
 public:
  ArOverlay(std::unique_ptr<CharacterView> view, ActionPlayer player, const ArOptions& options)
      : view_(std::move(view)), player_(std::move(player)), options_(options) {}
  // `surface` is the tracker's camera_from_surface (CubeTracker::surface()).
  Status Compose(const CubeState& state, const std::optional<Pose>& surface, const CameraModel& camera, double time_s,
                 cv::Mat* bgr, DrawInfo* info);
  // The placement of the last frame drawn.
  const Placement& placement() const { return placement_; }
  Action action() const { return player_.playing(); }
  const CharacterView& view() const { return *view_; }

 private:
  std::unique_ptr<CharacterView> view_;
  ActionPlayer player_;
  ArOptions options_;
  bool placed_ = false;
  cv::Vec2d cube_position_m_{0, 0};
  Placement placement_;
};

}  // namespace kinemo::cube::ar

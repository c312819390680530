// Skeleton and clip types for motion capture data (BVH and friends).
//
// A Skeleton is an immutable list of joints in depth-first order (every
// parent precedes its children). Each joint owns a contiguous run of channels
// (columns of Clip::frames) in the order the file lists them. A Clip pairs a
// skeleton with a dense frames × channels matrix of channel values: positions
// in the file's units, rotations in degrees.
//
// Translation convention (BVH): a joint's local translation in a frame is its
// OFFSET, except when the joint has position channels, in which case the
// channel values give the translation and replace the OFFSET (this is how the
// Bandai-Namco files, which have position channels on every joint, and the
// usual root joint are meant). Missing position axes fall back to the OFFSET
// component. Rotations compose intrinsically in channel order:
// R = R_c1 · R_c2 · R_c3 for channels listed c1 c2 c3.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::motion {

enum class ChannelType : uint8_t {
  kXPosition,
  kYPosition,
  kZPosition,
  kXRotation,
  kYRotation,
  kZRotation,
};

// "Xposition", "Zrotation", ... (the BVH spelling).
std::string_view ChannelTypeName(ChannelType type);
// Parses the BVH spelling (case-insensitive); nullopt when unknown.
std::optional<ChannelType> ParseChannelType(std::string_view name);
inline bool IsRotation(ChannelType t) { return t >= ChannelType::kXRotation; }
inline bool IsPosition(ChannelType t) { return !IsRotation(t); }
// 0 for X, 1 for Y, 2 for Z.
inline int ChannelAxis(ChannelType t) { return static_cast<int>(t) % 3; }

struct Joint {
  std::string name;
  int parent = -1;  // index into Skeleton::joints(), -1 for a root
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  std::vector<ChannelType> channels;        // in file order
  std::optional<Eigen::Vector3d> end_site;  // End Site OFFSET, if any
  // How position channels combine with OFFSET. BVH files disagree: most
  // (Bandai, CMU cgspeed) store the joint's absolute local translation, so the
  // channels replace OFFSET; some exporters (iClone's CMU conversion) store a
  // displacement added to OFFSET (root OFFSET y = 105 cm, channels near 0).
  // The BVH reader detects this per joint (see BvhReadOptions).
  bool position_relative_to_offset = false;

  // Filled by Skeleton::Create (inputs are ignored):
  int first_channel = 0;                              // column of channels[0]
  std::array<int, 3> position_column = {-1, -1, -1};  // column for X/Y/Z position, -1 = none
  int num_rotations = 0;                              // rotation channels, in order
  std::array<int, 3> rotation_axis = {0, 0, 0};       // axis of the k-th rotation channel
  std::array<int, 3> rotation_column = {-1, -1, -1};  // column of the k-th rotation channel

  int num_channels() const { return static_cast<int>(channels.size()); }
  bool has_position_channels() const {
    return position_column[0] >= 0 || position_column[1] >= 0 || position_column[2] >= 0;
  }
  // True when the rotation channels are three distinct axes (a Tait-Bryan
  // order such as ZXY); such joints are resampled by quaternion slerp.
  bool has_euler_rotation() const;
};

class Skeleton {
 public:
  Skeleton() = default;

  // Validates and indexes `joints`: names non-empty and unique, parents
  // precede children, at most 3 position and 3 rotation channels per joint,
  // no axis repeated among a joint's position channels.
  static StatusOr<Skeleton> Create(std::vector<Joint> joints);

  int num_joints() const { return static_cast<int>(joints_.size()); }
  int num_channels() const { return num_channels_; }
  const Joint& joint(int i) const { return joints_[static_cast<size_t>(i)]; }
  std::span<const Joint> joints() const { return joints_; }
  // Index of the joint called `name`, or -1.
  int FindJoint(std::string_view name) const;
  // Children of joint i, in file order.
  std::span<const int> children(int i) const { return children_[static_cast<size_t>(i)]; }
  int num_end_sites() const;
  // Depth of joint i (roots have depth 0).
  int depth(int i) const;

 private:
  std::vector<Joint> joints_;
  std::vector<std::vector<int>> children_;
  int num_channels_ = 0;
};

// Row-major so that one frame is a contiguous run of doubles.
using FrameMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

struct Clip {
  Skeleton skeleton;
  double frame_time_s = 1.0 / 30.0;
  FrameMatrix frames;  // num_frames × skeleton.num_channels()

  int num_frames() const { return static_cast<int>(frames.rows()); }
  double fps() const { return 1.0 / frame_time_s; }
  // Playing time: num_frames × frame_time_s.
  double duration_s() const { return num_frames() * frame_time_s; }
  // The channel values of frame f (contiguous).
  std::span<const double> frame(int f) const {
    return {frames.data() + static_cast<Eigen::Index>(f) * frames.cols(),
            static_cast<size_t>(frames.cols())};
  }
  // First column of joint j's channels (its channels are contiguous).
  int channel_offset(int j) const { return skeleton.joint(j).first_channel; }
  // Checks that frames has skeleton.num_channels() columns, finite values,
  // and a positive finite frame time.
  Status Validate() const;
};

// The local translation of joint j in a frame (OFFSET, or position channels
// where present). `frame` holds all channel values of the frame.
Eigen::Vector3d LocalTranslation(const Joint& joint, std::span<const double> frame);

}  // namespace kinemo::motion

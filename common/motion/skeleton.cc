#include "common/motion/skeleton.h"

#include <cmath>
#include <unordered_map>
#include <utility>

#include "common/motion/text_util.h"

namespace kinemo::motion {
namespace {

constexpr std::string_view kChannelNames[] = {"Xposition", "Yposition", "Zposition",
                                              "Xrotation", "Yrotation", "Zrotation"};

}  // namespace

std::string_view ChannelTypeName(ChannelType type) { return kChannelNames[static_cast<int>(type)]; }

std::optional<ChannelType> ParseChannelType(std::string_view name) {
  for (int i = 0; i < 6; ++i) {
    if (internal::EqualsIgnoreCase(name, kChannelNames[i])) return static_cast<ChannelType>(i);
  }
  return std::nullopt;
}

bool Joint::has_euler_rotation() const {
  if (num_rotations != 3) return false;
  return rotation_axis[0] != rotation_axis[1] && rotation_axis[1] != rotation_axis[2] &&
         rotation_axis[0] != rotation_axis[2];
}

StatusOr<Skeleton> Skeleton::Create(std::vector<Joint> joints) {
  Skeleton s;
  std::unordered_map<std::string_view, int> names;
  int column = 0;
  for (size_t i = 0; i < joints.size(); ++i) {
    Joint& j = joints[i];
    const std::string where = kinemo::StrCat("joint ", i, " '", j.name, "'");
    if (j.name.empty()) return InvalidField(where, "empty joint name");
    if (!names.emplace(j.name, static_cast<int>(i)).second) {
      return InvalidField(where, "duplicate joint name");
    }
    if (j.parent < -1 || j.parent >= static_cast<int>(i)) {
      return InvalidField(where, "parent index ", j.parent, " must be -1 or precede the joint");
    }
    if (!j.offset.allFinite() || (j.end_site && !j.end_site->allFinite())) {
      return InvalidField(where, "offset is not finite");
    }
    j.first_channel = column;
    j.position_column = {-1, -1, -1};
    j.rotation_column = {-1, -1, -1};
    j.rotation_axis = {0, 0, 0};
    j.num_rotations = 0;
    for (size_t c = 0; c < j.channels.size(); ++c) {
      const ChannelType t = j.channels[c];
      const int col = column + static_cast<int>(c);
      if (IsPosition(t)) {
        int& slot = j.position_column[static_cast<size_t>(ChannelAxis(t))];
        if (slot >= 0) {
          return InvalidField(where, "position channel ", ChannelTypeName(t), " listed twice");
        }
        slot = col;
      } else {
        if (j.num_rotations == 3) return InvalidField(where, "more than 3 rotation channels");
        j.rotation_axis[static_cast<size_t>(j.num_rotations)] = ChannelAxis(t);
        j.rotation_column[static_cast<size_t>(j.num_rotations)] = col;
        ++j.num_rotations;
      }
    }
    column += static_cast<int>(j.channels.size());
  }
  s.children_.resize(joints.size());
  for (size_t i = 0; i < joints.size(); ++i) {
    if (joints[i].parent >= 0) {
      s.children_[static_cast<size_t>(joints[i].parent)].push_back(static_cast<int>(i));
    }
  }
  s.joints_ = std::move(joints);
  s.num_channels_ = column;
  return s;
}

int Skeleton::FindJoint(std::string_view name) const {
  for (size_t i = 0; i < joints_.size(); ++i) {
    if (joints_[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

int Skeleton::num_end_sites() const {
  int n = 0;
  for (const Joint& j : joints_) n += j.end_site.has_value() ? 1 : 0;
  return n;
}

int Skeleton::depth(int i) const {
  int d = 0;
  for (int p = joint(i).parent; p >= 0; p = joint(p).parent) ++d;
  return d;
}

Status Clip::Validate() const {
  if (!(frame_time_s > 0.0) || !std::isfinite(frame_time_s)) {
    return InvalidField("clip.frame_time_s", frame_time_s, " must be positive and finite");
  }
  if (frames.cols() != skeleton.num_channels()) {
    return InvalidField("clip.frames", frames.cols(), " columns, skeleton has ",
                        skeleton.num_channels(), " channels");
  }
  if (!frames.allFinite()) return InvalidField("clip.frames", "contains non-finite values");
  return absl::OkStatus();
}

Eigen::Vector3d LocalTranslation(const Joint& joint, std::span<const double> frame) {
  Eigen::Vector3d t = joint.offset;
  for (int a = 0; a < 3; ++a) {
    const int col = joint.position_column[static_cast<size_t>(a)];
    if (col >= 0) {
      const double v = frame[static_cast<size_t>(col)];
      t[a] = joint.position_relative_to_offset ? joint.offset[a] + v : v;
    }
  }
  return t;
}

}  // namespace kinemo::motion

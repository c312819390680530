// Kinematic chains, split profiles, joint weights and per-frame features.
#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/motion/body_regions.h"
#include "common/motion/kinematics.h"
#include "services/planner/locomotion/locomotion.h"

namespace kinemo::planner::locomotion {
namespace {

using motion::BodyRegion;

Chain ChainOfRegion(BodyRegion r) {
  switch (r) {
    case BodyRegion::kHead:
      return Chain::kHead;
    case BodyRegion::kTrunk:
      return Chain::kTrunk;
    case BodyRegion::kRightArm:
    case BodyRegion::kRightHand:
      return Chain::kUpperRight;
    case BodyRegion::kLeftArm:
    case BodyRegion::kLeftHand:
      return Chain::kUpperLeft;
    case BodyRegion::kLeftLeg:
    case BodyRegion::kRightLeg:
      return Chain::kLower;
  }
  return Chain::kTrunk;
}

std::vector<int> Ancestors(const motion::Skeleton& s, int j) {  // j first, root last
  std::vector<int> out;
  for (; j >= 0; j = s.joint(j).parent) out.push_back(j);
  return out;
}

int CommonAncestor(const motion::Skeleton& s, int a, int b) {
  const std::vector<int> up = Ancestors(s, a);
  for (int j : Ancestors(s, b)) {
    if (std::find(up.begin(), up.end(), j) != up.end()) return j;
  }
  return -1;
}

// Joints strictly between `top` and `bottom` (top's descendant), top-down,
// that have rotation channels.
std::vector<int> Between(const motion::Skeleton& s, int top, int bottom) {
  std::vector<int> out;
  for (int j = s.joint(bottom).parent; j >= 0 && j != top; j = s.joint(j).parent) {
    if (s.joint(j).num_rotations > 0) out.push_back(j);
  }
  std::reverse(out.begin(), out.end());
  return out;
}

}  // namespace

std::string_view ChainName(Chain chain) {
  switch (chain) {
    case Chain::kHead:
      return "head";
    case Chain::kTrunk:
      return "trunk";
    case Chain::kUpperRight:
      return "upper_right";
    case Chain::kUpperLeft:
      return "upper_left";
    case Chain::kLower:
      return "lower";
  }
  return "?";
}

const std::vector<std::string>& BuiltinProfileNames() {
  static const std::vector<std::string> names = {"SMG", "SP2", "SP3a", "SP3b", "SP4a", "SP4b", "SP5"};
  return names;
}

StatusOr<SplitProfile> BuiltinProfile(std::string_view name) {
  using C = Chain;
  const C h = C::kHead, t = C::kTrunk, r = C::kUpperRight, l = C::kUpperLeft, lo = C::kLower;
  SplitProfile p;
  p.name = std::string(name);
  if (name == "SMG") {
    p.parts = {{lo, h, t, r, l}};
  } else if (name == "SP2") {
    p.parts = {{lo}, {h, t, r, l}};
  } else if (name == "SP3a") {
    p.parts = {{lo}, {h, t, r}, {l}};
  } else if (name == "SP3b") {
    p.parts = {{lo}, {h}, {t, r, l}};
  } else if (name == "SP4a") {
    p.parts = {{lo}, {h}, {t}, {r, l}};
  } else if (name == "SP4b") {
    p.parts = {{lo}, {h, t}, {r}, {l}};
  } else if (name == "SP5") {
    p.parts = {{lo}, {h}, {t}, {r}, {l}};
  } else {
    return InvalidField("profile.name", kinemo::StrCat("unknown split profile '", name,
                                                       "' (SMG, SP2, SP3a, SP3b, SP4a, SP4b, SP5)"));
  }
  return p;
}

Status ValidateProfile(const SplitProfile& profile) {
  std::array<int, kNumChains> seen{};
  if (profile.parts.empty()) return InvalidField("profile.parts", "no parts");
  for (const auto& part : profile.parts) {
    if (part.empty()) return InvalidField("profile.parts", "a part has no chains");
    for (Chain c : part) ++seen[static_cast<size_t>(c)];
  }
  for (int c = 0; c < kNumChains; ++c) {
    if (seen[static_cast<size_t>(c)] != 1) {
      return InvalidField("profile.parts", kinemo::StrCat("chain '", ChainName(static_cast<Chain>(c)),
                                                          "' must be in exactly one part (found ",
                                                          seen[static_cast<size_t>(c)], ")"));
    }
  }
  return absl::OkStatus();
}

StatusOr<GraphParams> ResolveParams(GraphParams p) {
  if (!(p.threshold >= 0) || !std::isfinite(p.threshold)) return InvalidField("params.threshold", "must be >= 0");
  if (p.threshold == 0) p.threshold = 0.105;
  if (p.progressive_window_frames < 0 || p.progressive_window_frames > 600) {
    return InvalidField("params.progressive_window_frames", "must be in [0, 600]");
  }
  if (!(p.max_path_length_ratio >= 0) || p.max_path_length_ratio > 10) {
    return InvalidField("params.max_path_length_ratio", "must be in [0, 10]");
  }
  if (p.max_path_length_ratio == 0) p.max_path_length_ratio = 0.2;
  if (!(p.contact_height_m >= 0) || p.contact_height_m > 1) {
    return InvalidField("params.contact_height_m", "must be in [0, 1]");
  }
  if (p.contact_height_m == 0) p.contact_height_m = 0.05;
  if (!(p.contact_speed_mps >= 0) || p.contact_speed_mps > 10) {
    return InvalidField("params.contact_speed_mps", "must be in [0, 10]");
  }
  if (p.contact_speed_mps == 0) p.contact_speed_mps = 0.8;
  if (!(p.filter_cutoff_hz >= 0) || p.filter_cutoff_hz > 1000) {
    return InvalidField("params.filter_cutoff_hz", "must be in [0, 1000]");
  }
  if (p.filter_cutoff_hz == 0) p.filter_cutoff_hz = 6;
  if (p.max_transitions_per_frame < 0 || p.max_transitions_per_frame > 100000) {
    return InvalidField("params.max_transitions_per_frame", "must be in [0, 100000]");
  }
  for (const auto& [name, w] : p.joint_weights) {
    if (!(w >= 0) || w > 100) return InvalidField("params.joint_weights", kinemo::StrCat("'", name, "' must be in [0, 100]"));
  }
  return p;
}

const double* LocomotionData::FrameValues(int g) const {
  const int c = clip_of[static_cast<size_t>(g)];
  const auto& clip = library->clips[static_cast<size_t>(c)].clip;
  return clip.frames.data() + static_cast<Eigen::Index>(g - clip_begin[static_cast<size_t>(c)]) * clip.frames.cols();
}

int LocomotionData::ClipIndex(std::string_view name) const {
  for (size_t c = 0; c < library->clips.size(); ++c) {
    if (library->clips[c].name == name) return static_cast<int>(c);
  }
  return -1;
}

std::vector<uint8_t> FootContacts(const LocomotionData& data, const motion::Clip& clip, double height_m,
                                  double speed_mps) {
  const int n = clip.num_frames();
  std::vector<uint8_t> out(static_cast<size_t>(n), 0);
  auto world = motion::ComputeWorldPositions(clip);
  if (!world.ok() || n == 0) return out;
  const double mpu = data.meters_per_unit;
  auto low_and_slow = [&](int joint, std::vector<uint8_t>* flags) {
    double min_y = 1e300;
    for (int f = 0; f < n; ++f) min_y = std::min(min_y, (*world)(f, 3 * joint + 1));
    for (int f = 0; f < n; ++f) {
      const int a = std::max(0, f - 1), b = std::min(n - 1, f + 1);
      const Eigen::Vector3d pa((*world)(a, 3 * joint), (*world)(a, 3 * joint + 1), (*world)(a, 3 * joint + 2));
      const Eigen::Vector3d pb((*world)(b, 3 * joint), (*world)(b, 3 * joint + 1), (*world)(b, 3 * joint + 2));
      const double speed = b > a ? (pb - pa).norm() * mpu / ((b - a) * clip.frame_time_s) : 0;
      const double h = ((*world)(f, 3 * joint + 1) - min_y) * mpu;
      (*flags)[static_cast<size_t>(f)] = (h < height_m && speed < speed_mps) ? 1 : 0;
    }
  };
  std::vector<uint8_t> ankle(static_cast<size_t>(n)), toe(static_cast<size_t>(n));
  const int feet[2] = {data.left_foot, data.right_foot};
  const int toes[2] = {data.left_toe, data.right_toe};
  for (int side = 0; side < 2; ++side) {
    low_and_slow(feet[side], &ankle);
    if (toes[side] >= 0) {
      low_and_slow(toes[side], &toe);
    } else {
      std::fill(toe.begin(), toe.end(), 0);
    }
    for (int f = 0; f < n; ++f) {
      if (ankle[static_cast<size_t>(f)] || toe[static_cast<size_t>(f)]) out[static_cast<size_t>(f)] |= static_cast<uint8_t>(1 << side);
    }
  }
  return out;
}

StatusOr<std::shared_ptr<const LocomotionData>> BuildLocomotionData(std::shared_ptr<const Library> library,
                                                                     const GraphParams& params) {
  if (!library) return InvalidField("library_id", "no library");
  if (library->clips.size() < 2) return InvalidField("library", "needs at least 2 clips");
  auto data = std::make_shared<LocomotionData>();
  data->library = library;
  data->fps = library->frame_rate_hz;
  data->meters_per_unit = library->meters_per_unit > 0 ? library->meters_per_unit : 0.01;
  const motion::Skeleton& s = library->skeleton;
  data->clip_begin.push_back(0);
  for (size_t c = 0; c < library->clips.size(); ++c) {
    const int n = library->clips[c].clip.num_frames();
    for (int f = 0; f < n; ++f) data->clip_of.push_back(static_cast<int>(c));
    data->clip_begin.push_back(data->clip_begin.back() + n);
  }
  data->num_frames = data->clip_begin.back();
  if (data->num_frames > kMaxFrames) {
    return InvalidField("library", kinemo::StrCat(data->num_frames, " frames; at most ", kMaxFrames,
                                                  " (use fewer or shorter clips)"));
  }
  KINEMO_ASSIGN_OR_RETURN(motion::KeyJoints keys, motion::FindKeyJoints(s, library->regions));
  data->left_foot = keys.left_foot;
  data->right_foot = keys.right_foot;
  data->left_toe = keys.left_toe;
  data->right_toe = keys.right_toe;
  data->hips = CommonAncestor(s, keys.head, keys.left_foot);
  if (data->hips < 0 || CommonAncestor(s, keys.head, keys.right_foot) != data->hips) {
    return InvalidField("library", "skeleton: head and feet have no common ancestor (hips)");
  }
  // Chains per joint.
  data->joint_chain.resize(static_cast<size_t>(s.num_joints()));
  for (int j = 0; j < s.num_joints(); ++j) {
    data->joint_chain[static_cast<size_t>(j)] = ChainOfRegion(library->regions.region[static_cast<size_t>(j)]);
  }
  for (int j : Ancestors(s, data->hips)) data->joint_chain[static_cast<size_t>(j)] = Chain::kLower;
  for (int foot : {keys.left_foot, keys.right_foot}) {
    for (int j : Between(s, data->hips, foot)) data->joint_chain[static_cast<size_t>(j)] = Chain::kLower;
    data->joint_chain[static_cast<size_t>(foot)] = Chain::kLower;
  }
  data->root_chain = Ancestors(s, data->hips);
  std::reverse(data->root_chain.begin(), data->root_chain.end());

  // Joint weights (§3.4) by position in the chains.
  std::map<int, double> weight;
  weight[data->hips] = 1.0;
  const std::vector<int> left_leg = Between(s, data->hips, keys.left_foot);
  const std::vector<int> right_leg = Between(s, data->hips, keys.right_foot);
  if (left_leg.size() < 2 || right_leg.size() < 2) return InvalidField("library", "skeleton: legs need thigh and knee joints");
  data->left_upleg = left_leg[left_leg.size() - 2];
  data->right_upleg = right_leg[right_leg.size() - 2];
  for (const auto* leg : {&left_leg, &right_leg}) {
    weight[(*leg)[leg->size() - 1]] = 1.0;  // leg (knee)
    weight[(*leg)[leg->size() - 2]] = 1.2;  // up-leg (thigh)
  }
  for (int wrist : {keys.left_hand, keys.right_hand}) {
    const int top = CommonAncestor(s, wrist, keys.head);
    const std::vector<int> arm = Between(s, top, wrist);
    if (arm.size() >= 1) weight[arm[arm.size() - 1]] = 0.3;  // forearm
    if (arm.size() >= 2) weight[arm[arm.size() - 2]] = 0.7;  // arm
  }
  {
    const int top = CommonAncestor(s, keys.left_hand, keys.head);
    for (int j : Between(s, top, keys.head)) {
      if (data->joint_chain[static_cast<size_t>(j)] == Chain::kHead) {
        weight[j] = 0.5;  // neck
        break;
      }
    }
    const std::vector<int> spine = Between(s, data->hips, keys.head);
    if (!spine.empty() && data->joint_chain[static_cast<size_t>(spine[0])] == Chain::kTrunk) weight[spine[0]] = 0.3;
  }
  for (const auto& [name, w] : params.joint_weights) {
    const int j = s.FindJoint(name);
    if (j < 0) return InvalidField("params.joint_weights", kinemo::StrCat("no joint '", name, "'"));
    weight[j] = w;
  }
  for (const auto& [j, w] : weight) {
    if (w <= 0) continue;
    WeightedJoint wj{j, data->joint_chain[static_cast<size_t>(j)], w, j == data->hips};
    data->weighted.push_back(wj);
    data->chain_weight[static_cast<size_t>(wj.chain)] += w;
  }

  // Per-frame features.
  const int n = data->num_frames;
  const size_t nw = data->weighted.size();
  data->quat.resize(static_cast<size_t>(n) * nw);
  data->hips_position_m.resize(static_cast<size_t>(n));
  data->heading_rad.resize(static_cast<size_t>(n));
  data->hips_rotation.resize(static_cast<size_t>(n));
  data->velocity_m.resize(static_cast<size_t>(n));
  data->turn_rad.resize(static_cast<size_t>(n));
  data->phase.resize(static_cast<size_t>(n));
  std::vector<Eigen::Vector3d> wp(static_cast<size_t>(s.num_joints()));
  std::vector<Eigen::Matrix3d> wr(static_cast<size_t>(s.num_joints()));
  for (size_t c = 0; c < library->clips.size(); ++c) {
    const motion::Clip& clip = library->clips[c].clip;
    const int begin = data->clip_begin[c];
    for (int f = 0; f < clip.num_frames(); ++f) {
      const int g = begin + f;
      KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(s, clip.frame(f), wp, wr));
      const Eigen::Vector3d lat = wp[static_cast<size_t>(data->left_upleg)] - wp[static_cast<size_t>(data->right_upleg)];
      // Surface (x, y) = world (X, -Z); forward = lateral turned clockwise.
      const Eigen::Vector2d lat_s(lat.x(), -lat.z());
      const double heading = std::atan2(-lat_s.x(), lat_s.y());
      data->heading_rad[static_cast<size_t>(g)] = heading;
      data->hips_position_m[static_cast<size_t>(g)] = wp[static_cast<size_t>(data->hips)] * data->meters_per_unit;
      const Eigen::Matrix3d unyaw = Eigen::AngleAxisd(-heading, Eigen::Vector3d::UnitY()).toRotationMatrix();
      data->hips_rotation[static_cast<size_t>(g)] = Eigen::Quaterniond(wr[static_cast<size_t>(data->hips)]).normalized();
      for (size_t k = 0; k < nw; ++k) {
        const WeightedJoint& wj = data->weighted[k];
        const int parent = s.joint(wj.joint).parent;
        Eigen::Matrix3d r;
        if (wj.hips) {
          r = unyaw * wr[static_cast<size_t>(wj.joint)];
        } else {
          const Eigen::Matrix3d pr = parent >= 0 ? wr[static_cast<size_t>(parent)] : Eigen::Matrix3d::Identity();
          r = pr.transpose() * wr[static_cast<size_t>(wj.joint)];
        }
        data->quat[static_cast<size_t>(g) * nw + k] = Eigen::Quaterniond(r).normalized();
      }
    }
    for (int f = 0; f < clip.num_frames(); ++f) {
      const int g = begin + f;
      const int a = f + 1 < clip.num_frames() ? g : g - 1;
      const Eigen::Vector3d d = data->hips_position_m[static_cast<size_t>(a + 1)] - data->hips_position_m[static_cast<size_t>(a)];
      const Eigen::Vector2d ds(d.x(), -d.z());
      const double h = data->heading_rad[static_cast<size_t>(a)];
      data->velocity_m[static_cast<size_t>(g)] =
          Eigen::Vector2d(std::cos(h) * ds.x() + std::sin(h) * ds.y(), -std::sin(h) * ds.x() + std::cos(h) * ds.y());
      data->turn_rad[static_cast<size_t>(g)] =
          WrapAngle(data->heading_rad[static_cast<size_t>(a + 1)] - data->heading_rad[static_cast<size_t>(a)]);
    }
    const std::vector<uint8_t> contacts = FootContacts(*data, clip, params.contact_height_m, params.contact_speed_mps);
    std::copy(contacts.begin(), contacts.end(), data->phase.begin() + begin);
  }
  // Distance maps per chain: Σ_k w_k ‖log(q_b⁻¹ q_a)‖² = Σ_k w_k acos(|q_a·q_b|)².
  for (int c = 0; c < kNumChains; ++c) {
    std::vector<size_t> ks;
    for (size_t k = 0; k < nw; ++k) {
      if (static_cast<int>(data->weighted[k].chain) == c) ks.push_back(k);
    }
    auto& m = data->chain_distance[static_cast<size_t>(c)];
    m.assign(static_cast<size_t>(n) * static_cast<size_t>(n), 0.0f);
    if (ks.empty()) continue;
    for (int a = 0; a < n; ++a) {
      for (int b = a + 1; b < n; ++b) {
        double d = 0;
        for (size_t k : ks) {
          const double dot = std::min(1.0, std::abs(data->quat[static_cast<size_t>(a) * nw + k].dot(
                                               data->quat[static_cast<size_t>(b) * nw + k])));
          const double th = std::acos(dot);
          d += data->weighted[k].weight * th * th;
        }
        m[static_cast<size_t>(a) * static_cast<size_t>(n) + static_cast<size_t>(b)] = static_cast<float>(d);
        m[static_cast<size_t>(b) * static_cast<size_t>(n) + static_cast<size_t>(a)] = static_cast<float>(d);
      }
    }
  }
  return std::shared_ptr<const LocomotionData>(std::move(data));
}

}  // namespace kinemo::planner::locomotion

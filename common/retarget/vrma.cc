// Reading a VRM Animation (.vrma) as motion on a BVH-style skeleton (gltf.h).
#include <algorithm>
#include <cmath>
#include <map>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "common/motion/kinematics.h"
#include "common/retarget/gltf.h"
#include "common/retarget/transform.h"

namespace kinemo::retarget {
namespace {

// One animated property of a node: key times and values (4 per key for a
// rotation x y z w, 3 for a translation), sampled as the file says.
struct Track {
  std::vector<float> times;
  std::vector<float> values;
  int size = 0;
  enum class Mode { kLinear, kStep, kCubic } mode = Mode::kLinear;

  // The value at key k (a cubic spline's keys hold in-tangent, value,
  // out-tangent: the value is the middle one).
  const float* Key(size_t k) const {
    return values.data() + (mode == Mode::kCubic ? (3 * k + 1) : k) * static_cast<size_t>(size);
  }
  // Value at time t, held at the ends; between keys linear (quaternions:
  // spherical), or the earlier key for STEP. A cubic spline is read through
  // its values without its tangents.
  void At(double t, double* out) const {
    const size_t n = times.size();
    size_t k = static_cast<size_t>(std::upper_bound(times.begin(), times.end(), static_cast<float>(t)) - times.begin());
    if (k == 0 || n == 1) {
      std::copy_n(Key(0), size, out);
      return;
    }
    if (k >= n) {
      std::copy_n(Key(n - 1), size, out);
      return;
    }
    const float* a = Key(k - 1);
    const float* b = Key(k);
    const double span = times[k] - times[k - 1];
    const double u = mode == Mode::kStep || span <= 0 ? 0.0 : std::clamp((t - times[k - 1]) / span, 0.0, 1.0);
    if (size == 4) {
      const Eigen::Quaterniond qa(a[3], a[0], a[1], a[2]), qb(b[3], b[0], b[1], b[2]);
      const Eigen::Quaterniond q = qa.normalized().slerp(u, qb.normalized());
      out[0] = q.x();
      out[1] = q.y();
      out[2] = q.z();
      out[3] = q.w();
      return;
    }
    for (int c = 0; c < size; ++c) out[c] = a[c] + u * (b[c] - a[c]);
  }
};

// VRM 1.0 bone name -> role.
std::map<std::string, Role, std::less<>> RolesByVrmName() {
  std::map<std::string, Role, std::less<>> out;
  for (Role r = 0; r < kNumRoles; ++r) {
    if (!VrmHumanBoneName(r).empty()) out.emplace(std::string(VrmHumanBoneName(r)), r);
  }
  return out;
}

}  // namespace

StatusOr<VrmAnimationClip> ReadVrmAnimation(const std::string& path, double fps) {
  if (!(fps >= 0 && fps <= 240)) return absl::InvalidArgumentError(kinemo::StrCat("fps must be in [0, 240], got ", fps));
  KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<GltfSource> src, ReadGltf(path));
  const tinygltf::Model& model = src->model;
  const auto ext = model.extensions.find("VRMC_vrm_animation");
  if (ext == model.extensions.end()) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": not a VRM Animation (no extensions.VRMC_vrm_animation)"));
  }
  const tinygltf::Value& bones = Member(Member(ext->second, "humanoid"), "humanBones");
  if (!bones.IsObject()) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": extensions.VRMC_vrm_animation.humanoid.humanBones: missing"));
  }
  KINEMO_ASSIGN_OR_RETURN(NodeTree tree, BuildNodeTree(model));
  const int num_nodes = static_cast<int>(model.nodes.size());

  // The humanoid's bones kinemo has roles for, parents first.
  struct Bone {
    std::string name;
    Role role;
    int node;
    int parent = -1;  // index into bones
  };
  static const auto kRoles = RolesByVrmName();
  std::vector<Bone> list;
  std::vector<int> bone_of_node(static_cast<size_t>(num_nodes), -1);
  for (const std::string& key : bones.Keys()) {
    const auto role = kRoles.find(key);
    if (role == kRoles.end()) continue;  // eyes (lookAt's), unknown names
    const tinygltf::Value& node = Member(Member(bones, key), "node");
    const double n = node.IsNumber() ? node.GetNumberAsDouble() : -1;
    if (!(n >= 0 && n < num_nodes) || n != std::floor(n)) {
      return absl::InvalidArgumentError(
          kinemo::StrCat(path, ": extensions.VRMC_vrm_animation.humanoid.humanBones.", key, ".node: not a node of the file"));
    }
    if (bone_of_node[static_cast<size_t>(n)] >= 0) {
      return absl::InvalidArgumentError(kinemo::StrCat(path, ": extensions.VRMC_vrm_animation.humanoid.humanBones.", key,
                                                       ".node: node ", n, " is already another bone"));
    }
    bone_of_node[static_cast<size_t>(n)] = 0;
    list.push_back({key, role->second, static_cast<int>(n)});
  }
  std::sort(list.begin(), list.end(), [&](const Bone& a, const Bone& b) {
    return std::make_pair(tree.depth[static_cast<size_t>(a.node)], a.node) <
           std::make_pair(tree.depth[static_cast<size_t>(b.node)], b.node);
  });
  for (size_t b = 0; b < list.size(); ++b) bone_of_node[static_cast<size_t>(list[b].node)] = static_cast<int>(b);
  if (list.empty() || list[0].role != roles::kHips) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": the humanoid has no hips above its other bones"));
  }
  for (size_t b = 1; b < list.size(); ++b) {
    for (int a = tree.parent[static_cast<size_t>(list[b].node)]; a >= 0; a = tree.parent[static_cast<size_t>(a)]) {
      if (bone_of_node[static_cast<size_t>(a)] >= 0) {
        list[b].parent = bone_of_node[static_cast<size_t>(a)];
        break;
      }
    }
    if (list[b].parent < 0) {
      return absl::InvalidArgumentError(kinemo::StrCat(path, ": humanoid bone ", list[b].name, " is not below the hips"));
    }
  }

  // The rest (the file's T-pose): world positions and rotations.
  std::vector<Eigen::Vector3d> rest_pos(list.size());
  std::vector<Eigen::Matrix3d> rest_rot(list.size());
  for (size_t b = 0; b < list.size(); ++b) {
    const Eigen::Matrix4d& g = tree.global[static_cast<size_t>(list[b].node)];
    rest_pos[b] = g.block<3, 1>(0, 3);
    rest_rot[b] = Orthonormalized(g.block<3, 3>(0, 0));
  }
  std::vector<motion::Joint> joints;
  using motion::ChannelType;
  for (size_t b = 0; b < list.size(); ++b) {
    motion::Joint j;
    j.name = list[b].name;
    j.parent = list[b].parent;
    j.offset = b == 0 ? rest_pos[0] : Eigen::Vector3d(rest_pos[b] - rest_pos[static_cast<size_t>(list[b].parent)]);
    if (b == 0) j.channels = {ChannelType::kXPosition, ChannelType::kYPosition, ChannelType::kZPosition};
    for (ChannelType c : {ChannelType::kZRotation, ChannelType::kXRotation, ChannelType::kYRotation}) j.channels.push_back(c);
    joints.push_back(std::move(j));
  }
  KINEMO_ASSIGN_OR_RETURN(motion::Skeleton skeleton, motion::Skeleton::Create(std::move(joints)));

  // The first animation (the specification's): each node's rotation and
  // translation tracks.
  std::map<int, Track> rotation, translation;
  double duration = 0;
  if (!model.animations.empty()) {
    const tinygltf::Animation& anim = model.animations[0];
    for (size_t c = 0; c < anim.channels.size(); ++c) {
      const tinygltf::AnimationChannel& ch = anim.channels[c];
      const bool rot = ch.target_path == "rotation";
      if ((!rot && ch.target_path != "translation") || ch.target_node < 0 || ch.target_node >= num_nodes) continue;
      const std::string field = kinemo::StrCat(path, ": animations[0].channels[", c, "]");
      if (ch.sampler < 0 || ch.sampler >= static_cast<int>(anim.samplers.size())) {
        return absl::InvalidArgumentError(field + ".sampler: not a sampler of the animation");
      }
      const tinygltf::AnimationSampler& s = anim.samplers[static_cast<size_t>(ch.sampler)];
      Track t;
      t.size = rot ? 4 : 3;
      t.mode = s.interpolation == "STEP" ? Track::Mode::kStep
               : s.interpolation == "CUBICSPLINE" ? Track::Mode::kCubic
                                                  : Track::Mode::kLinear;
      KINEMO_ASSIGN_OR_RETURN(t.times, ReadAccessor(model, s.input, 1, field + " input"));
      KINEMO_ASSIGN_OR_RETURN(t.values, ReadAccessor(model, s.output, t.size, field + " output"));
      const size_t per_key = t.mode == Track::Mode::kCubic ? 3 : 1;
      if (t.times.empty() || t.values.size() != t.times.size() * per_key * static_cast<size_t>(t.size)) {
        return absl::InvalidArgumentError(field + ": its keys and values do not match");
      }
      if (!std::is_sorted(t.times.begin(), t.times.end()) || t.times.front() < 0) {
        return absl::InvalidArgumentError(field + ": key times must be ascending from 0");
      }
      duration = std::max(duration, static_cast<double>(t.times.back()));
      (rot ? rotation : translation)[ch.target_node] = std::move(t);
    }
  }
  // The rate: `fps`, or (0) the keys' own: the median spacing of the track
  // with the most keys, a whole number of frames per second when within 1 %.
  if (fps == 0) {
    const Track* most = nullptr;
    for (const auto* tracks : {&rotation, &translation}) {
      for (const auto& [node, t] : *tracks) {
        if (most == nullptr || t.times.size() > most->times.size()) most = &t;
      }
    }
    fps = 30;
    if (most != nullptr && most->times.size() >= 2) {
      std::vector<float> dt(most->times.size() - 1);
      for (size_t k = 0; k + 1 < most->times.size(); ++k) dt[k] = most->times[k + 1] - most->times[k];
      std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
      const double median = dt[dt.size() / 2];
      if (median > 0) fps = std::clamp(1.0 / median, 1.0, 240.0);
      if (std::abs(fps - std::round(fps)) < 0.01 * fps) fps = std::round(fps);
    }
  }
  // The last key's frame counts when the keys' clock is a hair off the
  // rate's (keys written at 0.0333333 s for 30 fps).
  const double frames_d = std::floor(duration * fps + 0.01) + 1;
  if (frames_d > kMaxVrmaFrames) {
    return absl::InvalidArgumentError(
        kinemo::StrCat(path, ": ", duration, " s at ", fps, " fps is more than ", kMaxVrmaFrames, " frames"));
  }
  const int num_frames = static_cast<int>(frames_d);

  // Per frame: every node's world transform (the animated properties over
  // the node's own), then each bone's turn from its rest, relative to its
  // parent bone's, as Z X Y Euler angles; the hips' world position.
  std::vector<int> order(static_cast<size_t>(num_nodes));
  for (int n = 0; n < num_nodes; ++n) order[static_cast<size_t>(n)] = n;
  std::sort(order.begin(), order.end(),
            [&](int a, int b) { return tree.depth[static_cast<size_t>(a)] < tree.depth[static_cast<size_t>(b)]; });
  motion::Clip clip;
  clip.skeleton = skeleton;
  clip.frame_time_s = 1.0 / fps;
  clip.frames.resize(num_frames, skeleton.num_channels());
  std::vector<Eigen::Matrix4d> world(static_cast<size_t>(num_nodes));
  std::vector<Eigen::Matrix3d> turned(list.size());
  std::vector<Eigen::Vector3d> previous(list.size(), Eigen::Vector3d::Zero());
  const std::array<int, 3> zxy = {2, 0, 1};
  for (int f = 0; f < num_frames; ++f) {
    const double t = f / fps;
    for (int n : order) {
      tinygltf::Node node = model.nodes[static_cast<size_t>(n)];
      double v[4];
      const auto r = rotation.find(n);
      const auto p = translation.find(n);
      if (r != rotation.end() || p != translation.end()) {
        // An animated node: its TRS with the sampled parts (a matrix node is
        // split into TRS first).
        if (!node.matrix.empty()) {
          const Eigen::Matrix4d m = NodeLocalMatrix(node);
          const Eigen::Quaterniond q(Orthonormalized(m.block<3, 3>(0, 0)));
          node.matrix.clear();
          node.translation = {m(0, 3), m(1, 3), m(2, 3)};
          node.rotation = {q.x(), q.y(), q.z(), q.w()};
        }
        if (r != rotation.end()) {
          r->second.At(t, v);
          node.rotation = {v[0], v[1], v[2], v[3]};
        }
        if (p != translation.end()) {
          p->second.At(t, v);
          node.translation = {v[0], v[1], v[2]};
        }
      }
      const int parent = tree.parent[static_cast<size_t>(n)];
      const Eigen::Matrix4d local = NodeLocalMatrix(node);
      world[static_cast<size_t>(n)] = parent < 0 ? local : Eigen::Matrix4d(world[static_cast<size_t>(parent)] * local);
    }
    double* row = clip.frames.data() + static_cast<Eigen::Index>(f) * clip.frames.cols();
    for (size_t b = 0; b < list.size(); ++b) {
      const Eigen::Matrix4d& w = world[static_cast<size_t>(list[b].node)];
      turned[b] = Orthonormalized(w.block<3, 3>(0, 0)) * rest_rot[b].transpose();
      const Eigen::Matrix3d local =
          b == 0 ? turned[0] : Eigen::Matrix3d(turned[static_cast<size_t>(list[b].parent)].transpose() * turned[b]);
      const Eigen::Vector3d e = motion::MatrixToEuler(local, zxy, previous[b]);
      previous[b] = e;
      const motion::Joint& j = skeleton.joint(static_cast<int>(b));
      for (int k = 0; k < 3; ++k) row[j.rotation_column[static_cast<size_t>(k)]] = e[k];
      if (b == 0) {
        for (int k = 0; k < 3; ++k) row[j.position_column[static_cast<size_t>(k)]] = w(k, 3);
      }
    }
  }
  KINEMO_RETURN_IF_ERROR(clip.Validate());

  VrmAnimationClip out;
  out.clip = std::move(clip);
  nlohmann::json map = nlohmann::json::object();
  for (const Bone& b : list) map[std::string(RoleName(b.role))] = b.name;
  out.role_map_json = map.dump();
  return out;
}

}  // namespace kinemo::retarget

// The studio's characters (character.h).
#include "services/studio/core/character.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <system_error>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/retarget/face_map.h"
#include "common/retarget/rig_info.h"
#include "common/retarget/roles.h"


namespace kinemo::studio {
namespace {

namespace fs = std::filesystem;

constexpr std::size_t kMaxNameBytes = 256;
constexpr std::size_t kMaxMapBytes = 64 << 10;

bool IsCharacterFile(const std::string& name) {
  if (name.empty() || name[0] == '.') return false;
  std::string lower = name;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
  auto ends = [&](std::string_view s) { return lower.size() > s.size() && lower.ends_with(s); };
  return ends(".glb") || ends(".vrm");
}

// "x: no skin" -> "character.glb: x: no skin" (the field first).
Status InField(std::string_view field, const Status& s) {
  return Status(s.code(), kinemo::StrCat(field, ": ", s.message()));
}

// Appends floats as little-endian bytes (the machines kinemo runs on are
// little-endian; checked at compile time).
static_assert(std::endian::native == std::endian::little, "CharacterMotion's floats are written as in memory");
void AppendFloats(std::span<const float> values, std::string* out) {
  out->append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(float));
}

// The face channel behind a control: the input of its largest term ("aa",
// "PP", "jaw", "blink_left", "happy", ...), or that of the control it follows.
std::string ChannelOf(const std::vector<retarget::FaceControl>& all, const retarget::FaceControl& c) {
  const retarget::FaceControl* at = &c;
  for (int hops = 0; at->follows >= 0 && hops < 4; ++hops) at = &all[static_cast<std::size_t>(at->follows)];
  const retarget::FaceTerm* best = nullptr;
  for (const retarget::FaceTerm& t : at->terms) {
    if (best == nullptr || t.coefficient > best->coefficient) best = &t;
  }
  return best == nullptr ? std::string() : std::string(retarget::FaceInputName(best->input));
}

// The rig's face (common/retarget's FaceMap): the controls it drives and its
// jaw bone become CharacterInfo.face_targets, and `weights` evaluates them
// per face frame (the jaw as its opening over max_deg).
Status AddFace(const retarget::Rig& rig, v1::CharacterInfo* info, FaceWeights* weights) {
  KINEMO_ASSIGN_OR_RETURN(retarget::FaceMap made, retarget::FaceMap::Create(rig));
  auto map = std::make_shared<const retarget::FaceMap>(std::move(made));
  std::vector<int> driven;
  const auto& controls = map->controls();
  for (std::size_t i = 0; i < controls.size(); ++i) {
    const retarget::FaceControl& c = controls[i];
    if (!c.driven()) continue;
    driven.push_back(static_cast<int>(i));
    v1::FaceTarget* t = info->add_face_targets();
    t->set_kind(c.kind == retarget::FaceControlKind::kMorphTarget ? v1::FaceTarget::FACE_TARGET_KIND_MORPH
                                                                  : v1::FaceTarget::FACE_TARGET_KIND_EXPRESSION);
    t->set_name(c.name);
    t->set_channel(ChannelOf(controls, c));
  }
  const retarget::JawBone& jaw = map->jaw();
  const bool has_jaw = jaw.joint >= 0 && jaw.joint < rig.skeleton.num_joints() && jaw.max_deg > 0;
  if (has_jaw) {
    v1::FaceTarget* t = info->add_face_targets();
    t->set_kind(v1::FaceTarget::FACE_TARGET_KIND_JAW_BONE);
    t->set_name(jaw.name);
    t->set_node(rig.node[static_cast<std::size_t>(jaw.joint)]);
    // The hinge in the jaw node's own frame (its bind rotation is its world one).
    const Eigen::Vector3d local =
        (rig.bind_rotation[static_cast<std::size_t>(jaw.joint)].transpose() * jaw.hinge_axis).normalized();
    for (int k = 0; k < 3; ++k) t->add_axis(static_cast<float>(local[k]));
    t->set_max_deg(static_cast<float>(jaw.max_deg));
    t->set_channel("jaw");
  }
  if (info->face_targets_size() == 0) return absl::OkStatus();
  *weights = [map, driven = std::move(driven), has_jaw](const face::FaceFrame& frame, std::span<float> out) {
    thread_local std::vector<float> all;
    all.resize(map->controls().size());
    map->Weights(frame, all);
    std::size_t k = 0;
    for (int i : driven) out[k++] = all[static_cast<std::size_t>(i)];
    if (has_jaw) out[k] = static_cast<float>(map->JawAngleDeg(frame) / map->jaw().max_deg);
  };
  return absl::OkStatus();
}

StatusOr<std::shared_ptr<const Character>> MakeCharacter(std::shared_ptr<retarget::GltfSource> src,
                                                         const retarget::RoleMapChoice& choice, std::string name,
                                                         std::string url, std::string credit = {}) {
  KINEMO_ASSIGN_OR_RETURN(retarget::Rig rig, retarget::RigFromGltf(src, choice));
  KINEMO_ASSIGN_OR_RETURN(retarget::NodePoser poser, retarget::NodePoser::Create(rig));
  auto c = std::make_shared<Character>();
  v1::CharacterInfo& info = c->info;
  info.set_name(std::move(name));
  info.set_url(std::move(url));
  info.set_credit(std::move(credit));
  info.set_format(retarget::RigFormat(rig));
  std::vector<std::string> role_of(static_cast<std::size_t>(rig.skeleton.num_joints()));
  for (int r = 0; r < retarget::kNumRoles; ++r) {
    const int j = rig.roles.joint[r];
    if (j >= 0 && j < static_cast<int>(role_of.size())) role_of[j] = std::string(retarget::RoleName(r));
  }
  for (int j = 0; j < rig.skeleton.num_joints(); ++j) {
    auto* joint = info.add_joints();
    joint->set_name(rig.skeleton.joint(j).name);
    joint->set_node(rig.node[j]);
    joint->set_role(role_of[j]);
    for (int k = 0; k < 3; ++k) info.add_bind_translations(static_cast<float>(poser.bind_translation()[j][k]));
  }
  for (int j : poser.translated_joints()) info.add_translated_joints(j);
  KINEMO_RETURN_IF_ERROR(AddFace(rig, &info, &c->face_weights));
  for (int r = 0; r < retarget::kNumRoles; ++r) {
    (rig.roles.joint[r] >= 0 ? info.add_mapped_roles() : info.add_unmapped_roles())->assign(retarget::RoleName(r));
  }
  c->rig = std::move(rig);
  return std::shared_ptr<const Character>(std::move(c));
}

// Face weights 0..1 as bytes (0..255), rounded.
void AppendFaceBytes(std::span<const float> weights, std::string* out) {
  for (float w : weights) {
    const float c = std::clamp(w, 0.0f, 1.0f);
    out->push_back(static_cast<char>(static_cast<unsigned char>(std::lround(c * 255.0f))));
  }
}

}  // namespace

StatusOr<face::FaceFrame> FaceFrameFromProto(const common::v1::FaceFrame& p, std::string_view field) {
  face::FaceFrame f;
  f.time_s = p.time_s();
  const auto unit = [&](std::string_view member, double v, double lo, double hi) -> Status {
    if (!(v >= lo && v <= hi)) return InvalidField(kinemo::StrCat(field, ".", member), v, " is outside [", lo, ", ", hi, "]");
    return absl::OkStatus();
  };
  const auto weights = [&](std::string_view member, const auto& in, auto& out) -> Status {
    if (in.empty()) return absl::OkStatus();
    if (static_cast<std::size_t>(in.size()) != out.size()) {
      return InvalidField(kinemo::StrCat(field, ".", member), in.size(), " weights, not ", out.size());
    }
    for (int i = 0; i < in.size(); ++i) {
      KINEMO_RETURN_IF_ERROR(unit(kinemo::StrCat(member, "[", i, "]"), in[i], 0, 1));
      out[static_cast<std::size_t>(i)] = in[i];
    }
    return absl::OkStatus();
  };
  KINEMO_RETURN_IF_ERROR(weights("ovr_visemes", p.ovr_visemes(), f.ovr));
  KINEMO_RETURN_IF_ERROR(weights("categories", p.categories(), f.categories));
  // A jaw opens to ~30 degrees; a little below 0 is a clenched jaw.
  KINEMO_RETURN_IF_ERROR(unit("jaw_open_deg", p.jaw_open_deg(), -10, 45));
  KINEMO_RETURN_IF_ERROR(unit("blink_left", p.blink_left(), 0, 1));
  KINEMO_RETURN_IF_ERROR(unit("blink_right", p.blink_right(), 0, 1));
  KINEMO_RETURN_IF_ERROR(unit("brow_raise", p.brow_raise(), 0, 1));
  KINEMO_RETURN_IF_ERROR(unit("expression_weight", p.expression_weight(), 0, 1));
  KINEMO_RETURN_IF_ERROR(unit("emphasis", p.emphasis(), -1, 1));
  f.jaw_open_deg = p.jaw_open_deg();
  f.blink_left = p.blink_left();
  f.blink_right = p.blink_right();
  f.brow_raise = p.brow_raise();
  f.expression_weight = p.expression_weight();
  f.emphasis = p.emphasis();
  switch (p.expression()) {
    case common::v1::FACE_EXPRESSION_UNSPECIFIED:
    case common::v1::FACE_EXPRESSION_NEUTRAL: f.expression = face::Expression::kNeutral; break;
    case common::v1::FACE_EXPRESSION_HAPPY: f.expression = face::Expression::kHappy; break;
    case common::v1::FACE_EXPRESSION_ANGRY: f.expression = face::Expression::kAngry; break;
    case common::v1::FACE_EXPRESSION_SAD: f.expression = face::Expression::kSad; break;
    case common::v1::FACE_EXPRESSION_SURPRISED: f.expression = face::Expression::kSurprised; break;
    default: return InvalidField(kinemo::StrCat(field, ".expression"), "value ", p.expression(), " is not a FaceExpression");
  }
  return f;
}

CharacterLibrary::CharacterLibrary(const v1::StudioOptions& options)
    : dir_(options.character_dir()), max_bytes_(options.max_character_bytes()) {
  if (dir_.empty()) return;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir_, ec)) {
    if (!entry.is_regular_file(ec)) continue;
    const std::string name = entry.path().filename().string();
    if (!IsCharacterFile(name)) continue;
    File file{name, fs::absolute(entry.path(), ec).string(), entry.file_size(ec), {}};
    // The credit line (CC BY characters need one shown): at most 1 KiB.
    if (std::ifstream in(entry.path().string() + ".credit.txt"); in) {
      std::getline(in, file.credit);
      if (file.credit.size() > 1024) file.credit.resize(1024);
      while (!file.credit.empty() && std::isspace(static_cast<unsigned char>(file.credit.back()))) file.credit.pop_back();
    }
    files_.push_back(std::move(file));
  }
  // GLB files first, then VRM, each by name: the page shows the first one
  // (the Quaternius man of the bundled set).
  std::sort(files_.begin(), files_.end(), [](const File& a, const File& b) {
    const bool va = a.name.size() > 4 && a.name.ends_with(".vrm"), vb = b.name.size() > 4 && b.name.ends_with(".vrm");
    return va != vb ? vb : a.name < b.name;
  });
}

std::string CharacterLibrary::ListJson() const {
  nlohmann::json list = nlohmann::json::array();
  for (const File& f : files_) {
    list.push_back({{"name", f.name}, {"url", "/characters/" + f.name}, {"bytes", f.bytes}, {"credit", f.credit}});
  }
  return nlohmann::json{{"characters", list}}.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

const CharacterLibrary::File* CharacterLibrary::Find(std::string_view name) const {
  for (const File& f : files_) {
    if (f.name == name) return &f;
  }
  return nullptr;
}

StatusOr<std::shared_ptr<const Character>> CharacterLibrary::Select(const v1::SelectCharacter& request) {
  if (request.name().size() > kMaxNameBytes) {
    return InvalidField("character.name", request.name().size(), " bytes, at most ", kMaxNameBytes);
  }
  if (request.map_json().size() > kMaxMapBytes) {
    return InvalidField("character.map_json", request.map_json().size(), " bytes, at most ", kMaxMapBytes);
  }
  retarget::RoleMapChoice choice;
  choice.map_json = request.map_json();
  choice.map_source = "character.map_json";
  switch (request.source_case()) {
    case v1::SelectCharacter::kBundled: {
      const File* file = Find(request.bundled());
      if (file == nullptr) {
        std::string names;
        for (const File& f : files_) names += (names.empty() ? "" : ", ") + f.name;
        return absl::NotFoundError(kinemo::StrCat("character.bundled: no bundled character \"", request.bundled(),
                                                  "\" (the studio has: ", names.empty() ? "none" : names, ")"));
      }
      const std::string key = file->name + "\n" + request.map_json();
      {
        std::lock_guard<std::mutex> l(mu_);
        if (auto it = loaded_.find(key); it != loaded_.end()) return it->second;
      }
      auto src = retarget::ReadGltf(file->path);
      if (!src.ok()) return InField("character.bundled", src.status());
      auto made = MakeCharacter(*std::move(src), choice, file->name, "/characters/" + file->name, file->credit);
      if (!made.ok()) return InField("character.bundled", made.status());
      std::lock_guard<std::mutex> l(mu_);
      loaded_.emplace(key, *made);
      return *made;
    }
    case v1::SelectCharacter::kGlb: {
      const std::string& bytes = request.glb();
      if (bytes.empty()) return InvalidField("character.glb", "is empty");
      if (bytes.size() > max_bytes_) {
        return InvalidField("character.glb", bytes.size(), " bytes, at most ", max_bytes_,
                            " (StudioOptions.max_character_bytes)");
      }
      const std::string name = request.name().empty() ? "upload.glb" : request.name();
      auto src = retarget::ReadGlbFromMemory(bytes, name);
      if (!src.ok()) return InField("character.glb", src.status());
      auto made = MakeCharacter(*std::move(src), choice, name, "");
      if (!made.ok()) return InField("character.glb", made.status());
      return *made;
    }
    case v1::SelectCharacter::SOURCE_NOT_SET:
      break;
  }
  return InvalidField("character", "names no character (bundled or glb)");
}

CharacterDriver::CharacterDriver(std::shared_ptr<const Character> character, motion::Skeleton source,
                                 retarget::Retargeter retargeter, retarget::NodePoser poser, double frame_time_s)
    : character_(std::move(character)),
      source_(std::move(source)),
      retargeter_(std::move(retargeter)),
      poser_(std::move(poser)),
      frame_time_s_(frame_time_s) {
  target_frame_.resize(static_cast<std::size_t>(character_->rig.skeleton.num_channels()));
  rotations_.resize(static_cast<std::size_t>(character_->rig.skeleton.num_joints()) * 4);
  face_.resize(character_->face_weights ? static_cast<std::size_t>(character_->info.face_targets_size()) : 0);
  translations_.resize(poser_.translated_joints().size() * 3);
  const retarget::Rig& rig = character_->rig;
  // The soles: every joint from each foot down (toes, toe ends: the VALID
  // avatars' toe chains reach below the ankle's end) and their end sites.
  for (int side = 0; side < 2; ++side) {
    const int foot = rig.roles.joint[retarget::roles::Side(side, retarget::roles::kFoot)];
    if (foot < 0) continue;
    for (int j = foot; j < rig.skeleton.num_joints(); ++j) {
      bool below = j == foot;
      for (int a = rig.skeleton.joint(j).parent; a >= 0 && !below; a = rig.skeleton.joint(a).parent) below = a == foot;
      if (!below) continue;
      if (j != foot) feet_.emplace_back(j, Eigen::Vector3d::Zero());
      if (rig.skeleton.joint(j).end_site) feet_.emplace_back(j, *rig.skeleton.joint(j).end_site);
    }
  }
  const int hips = rig.roles.joint[retarget::roles::kHips];
  if (hips >= 0) hips_y_column_ = rig.skeleton.joint(hips).position_column[1];
  pos_.resize(static_cast<std::size_t>(rig.skeleton.num_joints()));
  rot_.resize(pos_.size());
}

void CharacterDriver::KeepAboveFloor() {
  if (feet_.empty() || hips_y_column_ < 0) return;
  const motion::Skeleton& skeleton = character_->rig.skeleton;
  if (!motion::ComputeWorldPose(skeleton, target_frame_, pos_, rot_).ok()) return;
  double lowest = 0;
  for (const auto& [j, offset] : feet_) lowest = std::min(lowest, (pos_[j] + rot_[j] * offset).y());
  // Rig units: metres for glTF.
  target_frame_[static_cast<std::size_t>(hips_y_column_)] -= lowest;
}

StatusOr<std::unique_ptr<CharacterDriver>> CharacterDriver::Create(std::shared_ptr<const Character> character,
                                                                   const motion::Skeleton& source,
                                                                   double meters_per_unit, double frame_time_s) {
  KINEMO_ASSIGN_OR_RETURN(retarget::Rig source_rig, retarget::RigFromSkeleton(source, 1.0, "source"));
  source_rig.meters_per_unit = meters_per_unit > 0 ? meters_per_unit : retarget::EstimateMetersPerUnit(source_rig);
  retarget::RetargetOptions options;
  options.frame_time_s = frame_time_s;
  // The motion kinemo makes already stands (its planner plants the feet);
  // the core's FootPlanter lifted a standing foot of the Quaternius man by
  // 15 cm on BodySpeech output (both source feet on the floor), so the
  // studio transfers the pose as it is and only keeps the soles out of the
  // floor (KeepAboveFloor).
  options.plant_feet = false;
  KINEMO_ASSIGN_OR_RETURN(retarget::Retargeter rt,
                          retarget::Retargeter::Create(source, source_rig, character->rig, options));
  KINEMO_ASSIGN_OR_RETURN(retarget::NodePoser poser, retarget::NodePoser::Create(character->rig));
  return std::unique_ptr<CharacterDriver>(
      new CharacterDriver(std::move(character), source, std::move(rt), std::move(poser), frame_time_s));
}

v1::CharacterMotion CharacterDriver::Start(double start_time_s) const {
  v1::CharacterMotion m;
  m.set_character(character_->info.name());
  m.set_frame_time_s(frame_time_s_);
  m.set_start_time_s(start_time_s);
  m.set_root_scale(retargeter_.root_scale());
  for (const std::string& r : retargeter_.MappedRoles()) m.add_mapped_roles(r);
  return m;
}

Status CharacterDriver::Drive(std::span<const double> frame, const face::FaceFrame* face, v1::CharacterMotion* out) {
  KINEMO_RETURN_IF_ERROR(retargeter_.RetargetFrame(frame, target_frame_));
  KeepAboveFloor();
  KINEMO_RETURN_IF_ERROR(poser_.Pose(target_frame_, rotations_, translations_));
  AppendFloats(rotations_, out->mutable_rotations());
  AppendFloats(translations_, out->mutable_translations());
  if (!face_.empty()) {
    if (face != nullptr) {
      character_->face_weights(*face, face_);
    } else {
      std::fill(face_.begin(), face_.end(), 0.0f);
    }
    AppendFaceBytes(face_, out->mutable_face_weights());
  }
  out->set_frames(out->frames() + 1);
  return absl::OkStatus();
}

StatusOr<face::FaceTrack> FaceTrackOf(const common::v1::FaceTrack& face, int motion_frames, std::string_view field) {
  face::FaceTrack track;
  if (face.frames_size() == 0) return track;
  if (face.frames_size() > motion_frames) {
    return InvalidField(kinemo::StrCat(field, ".frames"), face.frames_size(), " frames, the motion has ", motion_frames);
  }
  if (!(face.frame_time_s() > 0 && face.frame_time_s() <= 1)) {
    return InvalidField(kinemo::StrCat(field, ".frame_time_s"), face.frame_time_s(), " is outside (0, 1]");
  }
  track.frame_time_s = face.frame_time_s();
  track.frames.reserve(static_cast<std::size_t>(face.frames_size()));
  for (int i = 0; i < face.frames_size(); ++i) {
    KINEMO_ASSIGN_OR_RETURN(face::FaceFrame f, FaceFrameFromProto(face.frames(i), kinemo::StrCat(field, ".frames[", i, "]")));
    track.frames.push_back(f);
  }
  return track;
}

StatusOr<v1::ExportedFile> ExportBvh(std::shared_ptr<const Character> character, const v1::ExportMotion& request) {
  const retarget::Rig& rig = character->rig;
  const bool vrma = request.format() == v1::EXPORT_FORMAT_VRMA;
  if (!vrma && request.format() != v1::EXPORT_FORMAT_GLB) {
    return InvalidField("export_motion.format", "must be EXPORT_FORMAT_VRMA or EXPORT_FORMAT_GLB");
  }
  const std::string format = retarget::RigFormat(rig);
  if (vrma && format != "vrm0" && format != "vrm1") {
    return InvalidField("export_motion.format", "a VRM Animation needs a VRM character; ", character->info.name(),
                        " is ", format, " (export EXPORT_FORMAT_GLB)");
  }
  const std::string name = request.name().empty() ? std::string("motion") : request.name();
  auto clip = motion::ParseBvh(request.bvh(), name);
  if (!clip.ok()) return InField("export_motion.bvh", clip.status());
  if (clip->num_frames() < 1) return InvalidField("export_motion.bvh", "has no frames");
  if (clip->num_frames() > kMaxExportFrames) {
    return InvalidField("export_motion.bvh", clip->num_frames(), " frames, at most ", kMaxExportFrames);
  }
  KINEMO_ASSIGN_OR_RETURN(face::FaceTrack track, FaceTrackOf(request.face(), clip->num_frames(), "export_motion.face"));
  auto source = retarget::RigFromSkeleton(clip->skeleton, 1.0, name);
  if (!source.ok()) return InField("export_motion.bvh", source.status());
  auto moved = retarget::RetargetClip(*clip, retarget::EstimateMetersPerUnit(*source), rig);
  if (!moved.ok()) return InField("export_motion.bvh", moved.status());
  motion::Clip& out = moved->clip;
  KINEMO_ASSIGN_OR_RETURN(retarget::FaceMap face_map, retarget::FaceMap::Create(rig));
  std::optional<retarget::FaceAnimation> sampled;
  if (!track.frames.empty()) {
    auto made = retarget::SampleFace(face_map, track, out.num_frames(), out.frame_time_s);
    if (!made.ok()) return InField("export_motion.face", made.status());
    sampled = *std::move(made);
    KINEMO_RETURN_IF_ERROR(retarget::ApplyJawToClip(face_map, *sampled, &out));
  }
  // The writers write files: a private temporary one, read back and removed.
  std::random_device random;
  const fs::path path = fs::temp_directory_path() /
                        kinemo::StrCat("kinemo-studio-export-", random(), random(), vrma ? ".vrma" : ".glb");
  const Status written = retarget::WriteCharacterAnimation(rig, out, path.string(), vrma, sampled ? &face_map : nullptr,
                                                           sampled ? &*sampled : nullptr);
  v1::ExportedFile file;
  if (written.ok()) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    file.set_data(bytes.str());
  }
  std::error_code ec;
  fs::remove(path, ec);
  KINEMO_RETURN_IF_ERROR(written);
  if (file.data().empty()) return absl::InternalError(kinemo::StrCat("export_motion: could not read back ", path.string()));
  std::string stem = fs::path(name).stem().string();
  if (stem.empty()) stem = "motion";
  file.set_file_name(kinemo::StrCat(stem, vrma ? ".vrma" : ".glb"));
  file.set_media_type("model/gltf-binary");
  return file;
}

StatusOr<v1::CharacterMotion> RetargetBvh(std::shared_ptr<const Character> character, std::string_view bvh,
                                          std::string_view name, const common::v1::FaceTrack* face) {
  auto clip = motion::ParseBvh(bvh, name.empty() ? "bvh" : name);
  if (!clip.ok()) return InField("retarget.bvh", clip.status());
  if (clip->num_frames() < 1) return InvalidField("retarget.bvh", "has no frames");
  if (clip->num_frames() > kMaxRetargetFrames) {
    return InvalidField("retarget.bvh", clip->num_frames(), " frames, at most ", kMaxRetargetFrames);
  }
  std::vector<face::FaceFrame> faces;
  if (face != nullptr) {
    KINEMO_ASSIGN_OR_RETURN(face::FaceTrack track, FaceTrackOf(*face, clip->num_frames(), "retarget.face"));
    faces = std::move(track.frames);
  }
  auto driver = CharacterDriver::Create(std::move(character), clip->skeleton, 0, clip->frame_time_s);
  if (!driver.ok()) return InField("retarget.bvh", driver.status());
  v1::CharacterMotion out = (*driver)->Start(0);
  const std::size_t joints = static_cast<std::size_t>((*driver)->character().rig.skeleton.num_joints());
  out.mutable_rotations()->reserve(joints * 16 * static_cast<std::size_t>(clip->num_frames()));
  for (int f = 0; f < clip->num_frames(); ++f) {
    const face::FaceFrame* at = nullptr;
    if (!faces.empty()) {  // the face frame at this frame's time
      const double t = f * clip->frame_time_s;
      const auto k = static_cast<std::size_t>(std::llround(t / face->frame_time_s()));
      at = &faces[std::min(k, faces.size() - 1)];
    }
    if (Status s = (*driver)->Drive(clip->frame(f), at, &out); !s.ok()) return InField("retarget.bvh", s);
  }
  return out;
}

StatusOr<motion::Skeleton> SkeletonFromProto(const common::v1::Skeleton& skeleton) {
  std::vector<motion::Joint> joints;
  for (int i = 0; i < skeleton.joints_size(); ++i) {
    const auto& pj = skeleton.joints(i);
    motion::Joint j;
    j.name = pj.name();
    j.parent = pj.parent_index();
    j.offset = {pj.offset().x(), pj.offset().y(), pj.offset().z()};
    for (int c : pj.channels()) {
      if (c < common::v1::CHANNEL_X_POSITION || c > common::v1::CHANNEL_Z_ROTATION) {
        return InvalidField(kinemo::StrCat("header.skeleton.joints[", i, "].channels"), "channel ", c, " is not valid");
      }
      j.channels.push_back(static_cast<motion::ChannelType>(c - common::v1::CHANNEL_X_POSITION));
    }
    if (pj.has_end_site()) {
      j.end_site = Eigen::Vector3d(pj.end_site_offset().x(), pj.end_site_offset().y(), pj.end_site_offset().z());
    }
    joints.push_back(std::move(j));
  }
  auto made = motion::Skeleton::Create(std::move(joints));
  if (!made.ok()) return InField("header.skeleton", made.status());
  return made;
}

Status LiveCharacter::SetHeader(const common::v1::MotionStreamHeader& header) {
  KINEMO_ASSIGN_OR_RETURN(skeleton_, SkeletonFromProto(header.skeleton()));
  if (!(header.frame_time_s() > 0 && header.frame_time_s() <= 1)) {
    return InvalidField("header.frame_time_s", header.frame_time_s(), " is outside (0, 1]");
  }
  frame_time_s_ = header.frame_time_s();
  meters_per_unit_ = header.skeleton().meters_per_unit();
  has_header_ = true;
  driver_.reset();
  return absl::OkStatus();
}

StatusOr<std::unique_ptr<v1::CharacterMotion>> LiveCharacter::Drive(const std::shared_ptr<const Character>& character,
                                                                    const common::v1::MotionFrameBatch& batch) {
  if (!character || !has_header_ || batch.frames_size() == 0) return std::unique_ptr<v1::CharacterMotion>();
  if (!driver_ || &driver_->character() != character.get()) {
    auto made = CharacterDriver::Create(character, skeleton_, meters_per_unit_, frame_time_s_);
    if (!made.ok()) return InField("stream.header.skeleton", made.status());
    driver_ = *std::move(made);
  }
  auto out = std::make_unique<v1::CharacterMotion>(driver_->Start(batch.frames(0).time_s()));
  const int channels = skeleton_.num_channels();
  for (int f = 0; f < batch.frames_size(); ++f) {
    const auto& frame = batch.frames(f);
    if (frame.values_size() != channels) {
      return InvalidField(kinemo::StrCat("stream.frames.frames[", f, "].values"), frame.values_size(),
                          " values, the skeleton has ", channels, " channels");
    }
    values_.assign(frame.values().begin(), frame.values().end());
    const face::FaceFrame* face = nullptr;
    if (frame.has_face()) {
      KINEMO_ASSIGN_OR_RETURN(face_, FaceFrameFromProto(frame.face(), kinemo::StrCat("stream.frames.frames[", f, "].face")));
      face = &face_;
    }
    KINEMO_RETURN_IF_ERROR(driver_->Drive(values_, face, out.get()));
  }
  return out;
}

}  // namespace kinemo::studio

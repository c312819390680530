#include "services/planner/library/library.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/motion/resample.h"
#include "common/motion/text_util.h"

namespace kinemo::planner {
namespace {

namespace fs = std::filesystem;

struct PendingClip {
  std::string name;
  std::string source;
  std::string tone;  // empty = from style
  std::vector<std::string> keywords;
  std::string annotation_json;
  int inline_index = -1;
  double meters_per_unit = 0;
  motion::Clip clip;
};

std::string Stem(const std::string& path) { return fs::path(path).stem().string(); }

bool HasExtension(const fs::path& p, std::string_view ext) {
  return motion::internal::EqualsIgnoreCase(p.extension().string(), ext);
}

Status AddBvhFile(const std::string& path, std::vector<PendingClip>* out) {
  KINEMO_ASSIGN_OR_RETURN(motion::Clip clip, motion::ReadBvhFile(path));
  PendingClip pending;
  pending.name = Stem(path);
  pending.source = path;
  pending.clip = std::move(clip);
  out->push_back(std::move(pending));
  return absl::OkStatus();
}

StatusOr<std::vector<std::string>> StringList(const nlohmann::json& j, const std::string& field) {
  std::vector<std::string> out;
  if (!j.is_array()) return InvalidField(field, "must be a list of strings");
  for (const auto& item : j) {
    if (!item.is_string()) return InvalidField(field, "must be a list of strings");
    out.push_back(motion::internal::ToLower(item.get<std::string>()));
  }
  return out;
}

Status AddManifest(const std::string& path, std::vector<PendingClip>* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(kinemo::StrCat(path, ": cannot open manifest"));
  std::stringstream text;
  text << in.rdbuf();
  nlohmann::json manifest = nlohmann::json::parse(text.str(), nullptr, /*allow_exceptions=*/false);
  if (manifest.is_discarded() || !manifest.is_object()) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": not a JSON object"));
  }
  double mpu = 0;
  if (manifest.contains("meters_per_unit")) {
    const auto& v = manifest["meters_per_unit"];
    if (!v.is_number() || !(v.get<double>() >= kMinMetersPerUnit && v.get<double>() <= kMaxMetersPerUnit)) {
      return absl::InvalidArgumentError(kinemo::StrCat(path, ": meters_per_unit must be in [", kMinMetersPerUnit,
                                                       ", ", kMaxMetersPerUnit, "]"));
    }
    mpu = v.get<double>();
  }
  if (!manifest.contains("clips") || !manifest["clips"].is_array()) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": clips must be a list"));
  }
  const fs::path dir = fs::path(path).parent_path();
  int index = 0;
  for (const auto& entry : manifest["clips"]) {
    const std::string where = kinemo::StrCat(path, ": clips[", index++, "]");
    if (!entry.is_object() || !entry.contains("path") || !entry["path"].is_string()) {
      return absl::InvalidArgumentError(kinemo::StrCat(where, ".path: missing"));
    }
    fs::path clip_path = entry["path"].get<std::string>();
    if (clip_path.is_relative()) clip_path = dir / clip_path;
    Status s = AddBvhFile(clip_path.string(), out);
    if (!s.ok()) return Annotate(s, where);
    PendingClip& clip = out->back();
    clip.meters_per_unit = mpu;
    if (entry.contains("name")) {
      if (!entry["name"].is_string() || entry["name"].get<std::string>().empty()) {
        return absl::InvalidArgumentError(kinemo::StrCat(where, ".name: must be a non-empty string"));
      }
      clip.name = entry["name"].get<std::string>();
    }
    if (entry.contains("tone")) {
      if (!entry["tone"].is_string()) {
        return absl::InvalidArgumentError(kinemo::StrCat(where, ".tone: must be a string"));
      }
      clip.tone = motion::internal::ToLower(entry["tone"].get<std::string>());
    }
    if (entry.contains("keywords")) {
      auto kw = StringList(entry["keywords"], kinemo::StrCat(where, ".keywords"));
      if (!kw.ok()) return kw.status();
      clip.keywords = *std::move(kw);
    }
    if (entry.contains("phrases")) clip.annotation_json = entry["phrases"].dump();
  }
  return absl::OkStatus();
}

Status AddPath(const std::string& path, std::vector<PendingClip>* out) {
  std::error_code ec;
  const fs::path p(path);
  if (fs::is_directory(p, ec)) {
    std::vector<std::string> files;
    for (auto it = fs::recursive_directory_iterator(p, ec); !ec && it != fs::recursive_directory_iterator();
         it.increment(ec)) {
      if (it->is_regular_file(ec) && HasExtension(it->path(), ".bvh")) files.push_back(it->path().string());
    }
    if (ec) return absl::NotFoundError(kinemo::StrCat(path, ": ", ec.message()));
    std::sort(files.begin(), files.end());
    if (files.empty()) return absl::InvalidArgumentError(kinemo::StrCat(path, ": no *.bvh files in folder"));
    for (const auto& f : files) KINEMO_RETURN_IF_ERROR(AddBvhFile(f, out));
    return absl::OkStatus();
  }
  if (!fs::exists(p, ec)) return absl::NotFoundError(kinemo::StrCat(path, ": no such file or folder"));
  if (HasExtension(p, ".json")) return AddManifest(path, out);
  if (HasExtension(p, ".bvh")) return AddBvhFile(path, out);
  return absl::InvalidArgumentError(kinemo::StrCat(path, ": expected a .bvh file, a .json manifest or a folder"));
}

// Same joints (names, parents, channels, position convention) in the same
// order: the clip's frames can be used as they are.
bool SameSkeleton(const motion::Skeleton& a, const motion::Skeleton& b) {
  if (a.num_joints() != b.num_joints()) return false;
  for (int j = 0; j < a.num_joints(); ++j) {
    const auto& ja = a.joint(j);
    const auto& jb = b.joint(j);
    if (ja.name != jb.name || ja.parent != jb.parent || ja.channels != jb.channels) return false;
    if (ja.has_position_channels() && ja.position_relative_to_offset != jb.position_relative_to_offset) return false;
  }
  return true;
}

// The library skeleton: `first` restricted to the joints named in every clip.
// A joint whose parent is dropped hangs from its nearest kept ancestor (the
// dropped joints' rest offsets are added to its offset); a joint that becomes
// a root gets position channels (absolute) in front of its rotations.
StatusOr<motion::Skeleton> CommonSkeleton(const motion::Skeleton& first, const std::set<std::string>& keep) {
  std::vector<motion::Joint> joints;
  std::vector<int> new_index(static_cast<size_t>(first.num_joints()), -1);
  for (int j = 0; j < first.num_joints(); ++j) {
    const auto& src = first.joint(j);
    if (!keep.count(src.name)) continue;
    motion::Joint out;
    out.name = src.name;
    out.offset = src.offset;
    out.channels = src.channels;
    out.end_site = src.end_site;
    out.position_relative_to_offset = src.position_relative_to_offset;
    int p = src.parent;
    while (p >= 0 && new_index[static_cast<size_t>(p)] < 0) {
      out.offset += first.joint(p).offset;
      p = first.joint(p).parent;
    }
    out.parent = p >= 0 ? new_index[static_cast<size_t>(p)] : -1;
    if (out.parent < 0 && !src.has_position_channels()) {
      out.channels.insert(out.channels.begin(), {motion::ChannelType::kXPosition, motion::ChannelType::kYPosition,
                                                 motion::ChannelType::kZPosition});
      out.position_relative_to_offset = false;
    }
    new_index[static_cast<size_t>(j)] = static_cast<int>(joints.size());
    joints.push_back(std::move(out));
  }
  return motion::Skeleton::Create(std::move(joints));
}

}  // namespace

StatusOr<motion::Clip> RetargetByJointName(const motion::Clip& src, const motion::Skeleton& dst) {
  const motion::Skeleton& ss = src.skeleton;
  std::vector<int> map(static_cast<size_t>(dst.num_joints()), -1);
  for (int j = 0; j < dst.num_joints(); ++j) {
    map[static_cast<size_t>(j)] = ss.FindJoint(dst.joint(j).name);
    if (map[static_cast<size_t>(j)] < 0) {
      return absl::InvalidArgumentError(kinemo::StrCat("joint '", dst.joint(j).name, "' is missing"));
    }
  }
  motion::Clip out;
  out.skeleton = dst;
  out.frame_time_s = src.frame_time_s;
  out.frames = motion::FrameMatrix::Zero(src.num_frames(), dst.num_channels());
  std::vector<Eigen::Vector3d> sp(static_cast<size_t>(ss.num_joints())), dp(static_cast<size_t>(dst.num_joints()));
  std::vector<Eigen::Matrix3d> sr(static_cast<size_t>(ss.num_joints())), dr(static_cast<size_t>(dst.num_joints()));
  for (int f = 0; f < src.num_frames(); ++f) {
    KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(ss, src.frame(f), sp, sr));
    double* row = out.frames.data() + static_cast<Eigen::Index>(f) * out.frames.cols();
    const std::span<const double> frame(row, static_cast<size_t>(out.frames.cols()));
    for (int j = 0; j < dst.num_joints(); ++j) {
      const auto& joint = dst.joint(j);
      const auto& sjoint = ss.joint(map[static_cast<size_t>(j)]);
      const size_t m = static_cast<size_t>(map[static_cast<size_t>(j)]);
      const Eigen::Matrix3d rp = joint.parent >= 0 ? dr[static_cast<size_t>(joint.parent)] : Eigen::Matrix3d::Identity();
      const Eigen::Vector3d pp = joint.parent >= 0 ? dp[static_cast<size_t>(joint.parent)] : Eigen::Vector3d::Zero();
      if (joint.has_position_channels()) {
        const Eigen::Vector3d t = rp.transpose() * (sp[m] - pp);
        for (int a = 0; a < 3; ++a) {
          if (joint.position_column[static_cast<size_t>(a)] < 0) continue;
          row[joint.position_column[static_cast<size_t>(a)]] =
              t[a] - (joint.position_relative_to_offset ? joint.offset[a] : 0.0);
        }
      }
      if (joint.has_euler_rotation()) {
        const Eigen::Matrix3d local = rp.transpose() * sr[m];
        Eigen::Vector3d ref = Eigen::Vector3d::Zero();
        if (f > 0) {
          for (int k = 0; k < 3; ++k) ref[k] = out.frames(f - 1, joint.rotation_column[static_cast<size_t>(k)]);
        }
        const Eigen::Vector3d e = motion::MatrixToEuler(local, joint.rotation_axis, ref);
        for (int k = 0; k < 3; ++k) row[joint.rotation_column[static_cast<size_t>(k)]] = e[k];
      } else {
        // Fewer than three rotation axes: copy the values of the same channels.
        for (int k = 0; k < joint.num_rotations; ++k) {
          for (int c = 0; c < sjoint.num_channels(); ++c) {
            if (IsRotation(sjoint.channels[static_cast<size_t>(c)]) &&
                motion::ChannelAxis(sjoint.channels[static_cast<size_t>(c)]) == joint.rotation_axis[static_cast<size_t>(k)]) {
              row[joint.rotation_column[static_cast<size_t>(k)]] = src.frames(f, sjoint.first_channel + c);
            }
          }
        }
      }
      dp[static_cast<size_t>(j)] = pp + rp * motion::LocalTranslation(joint, frame);
      dr[static_cast<size_t>(j)] = rp * motion::LocalRotation(joint, frame);
    }
  }
  return out;
}

namespace {

// A clip name as a file name: [A-Za-z0-9._-], not starting with '.', at most
// 100 characters.
std::string FileSafe(std::string_view name) {
  std::string out;
  for (char c : name.substr(0, 100)) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
                    c == '_' || c == '-';
    out.push_back(ok ? c : '_');
  }
  if (out.empty()) out = "clip";
  if (out[0] == '.') out[0] = '_';
  return out;
}

}  // namespace

Status WriteLibraryFiles(const Library& library, const LibrarySources& sources, const std::string& dir) {
  std::error_code ec;
  fs::create_directories(fs::path(dir) / "clips", ec);
  if (ec) return absl::PermissionDeniedError(kinemo::StrCat(dir, ": cannot create clips/: ", ec.message()));
  nlohmann::json clips = nlohmann::json::array();
  std::set<std::string> used;
  for (const LibraryClip& c : library.clips) {
    const std::string base = FileSafe(c.name);
    std::string file = base;
    for (int k = 2; used.count(file); ++k) file = kinemo::StrCat(base, "-", k);
    used.insert(file);
    const std::string relative = kinemo::StrCat("clips/", file, ".bvh");
    const fs::path target = fs::path(dir) / relative;
    if (c.inline_index >= 0) {
      if (static_cast<size_t>(c.inline_index) >= sources.inline_clips.size()) {
        return absl::InternalError(kinemo::StrCat(c.name, ": inline clip ", c.inline_index, " is not in the sources"));
      }
      const std::string& text = sources.inline_clips[static_cast<size_t>(c.inline_index)].bvh_text;
      std::ofstream out(target, std::ios::binary | std::ios::trunc);
      out.write(text.data(), static_cast<std::streamsize>(text.size()));
      if (!out.flush()) return absl::ResourceExhaustedError(kinemo::StrCat(target.string(), ": write failed"));
    } else {
      fs::copy_file(c.source, target, fs::copy_options::overwrite_existing, ec);
      if (ec) return absl::NotFoundError(kinemo::StrCat(c.source, ": cannot copy: ", ec.message()));
    }
    nlohmann::json entry = {{"path", relative}, {"name", c.name}, {"tone", c.tone}, {"keywords", c.keywords}};
    if (!c.annotation_json.empty()) {
      nlohmann::json phrases = nlohmann::json::parse(c.annotation_json, nullptr, /*allow_exceptions=*/false);
      if (phrases.is_discarded()) return absl::InternalError(kinemo::StrCat(c.name, ": phrase annotation is not JSON"));
      entry["phrases"] = std::move(phrases);
    }
    clips.push_back(std::move(entry));
  }
  const nlohmann::json manifest = {{"meters_per_unit", library.meters_per_unit}, {"clips", std::move(clips)}};
  std::ofstream out(fs::path(dir) / "manifest.json", std::ios::binary | std::ios::trunc);
  out << manifest.dump(1) << "\n";
  if (!out.flush()) return absl::ResourceExhaustedError(kinemo::StrCat(dir, "/manifest.json: write failed"));
  return absl::OkStatus();
}

double Library::duration_s() const {
  double total = 0;
  for (const auto& c : clips) total += c.clip.duration_s();
  return total;
}

std::vector<std::string> Library::tones() const {
  std::set<std::string> s;
  for (const auto& c : clips) s.insert(c.tone);
  return {s.begin(), s.end()};
}

std::vector<std::string> Library::keywords() const {
  std::set<std::string> s;
  for (const auto& c : clips) s.insert(c.keywords.begin(), c.keywords.end());
  return {s.begin(), s.end()};
}

const LibraryClip* Library::FindClip(std::string_view name) const {
  for (const auto& c : clips) {
    if (c.name == name) return &c;
  }
  return nullptr;
}

std::string ToneForStyle(std::string_view style) {
  static const std::set<std::string, std::less<>> kEnergetic = {"active", "angry", "happy", "proud",
                                                                "energetic", "masculinity", "chimpira",
                                                                "childish", "musical", "giant"};
  static const std::set<std::string, std::less<>> kSubdued = {"sad", "tired", "old", "not-confident",
                                                              "subdued", "feminine"};
  const std::string s = motion::internal::ToLower(style);
  if (kEnergetic.count(s)) return "energetic";
  if (kSubdued.count(s)) return "subdued";
  return "neutral";
}

std::optional<BandaiName> ParseBandaiName(std::string_view stem) {
  // dataset-<n>_<content>_<style>_<nnn>
  if (stem.substr(0, 8) != "dataset-") return std::nullopt;
  std::vector<std::string_view> parts;
  size_t start = 0;
  for (size_t i = 0; i <= stem.size(); ++i) {
    if (i == stem.size() || stem[i] == '_') {
      parts.push_back(stem.substr(start, i - start));
      start = i + 1;
    }
  }
  if (parts.size() != 4 || parts[1].empty() || parts[2].empty()) return std::nullopt;
  if (!std::all_of(parts[3].begin(), parts[3].end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return std::nullopt;
  }
  return BandaiName{std::string(parts[1]), std::string(parts[2])};
}

double EstimateMetersPerUnit(const motion::Skeleton& skeleton) {
  // Bone lengths along the tree path head -> foot are pose independent; for
  // an adult the head joint sits about 1.50 m above the ankle joint.
  const motion::BodyRegionMap regions = motion::MapBodyRegions(skeleton);
  auto keys = motion::FindKeyJoints(skeleton, regions);
  if (!keys.ok()) return 0.01;
  auto ancestors = [&](int j) {
    std::vector<int> chain;
    for (; j >= 0; j = skeleton.joint(j).parent) chain.push_back(j);
    return chain;
  };
  const std::vector<int> up = ancestors(keys->head);
  const std::vector<int> down = ancestors(keys->left_foot);
  double length = 0;
  // Sum bone lengths from each end up to (not including) the common ancestor.
  auto common = [&](int j) { return std::find(up.begin(), up.end(), j) != up.end(); };
  int lca = -1;
  for (int j : down) {
    if (common(j)) {
      lca = j;
      break;
    }
    length += skeleton.joint(j).offset.norm();
  }
  for (int j : up) {
    if (j == lca) break;
    length += skeleton.joint(j).offset.norm();
  }
  return length > 0 ? 1.50 / length : 0.01;
}

bool IsValidId(std::string_view id) {
  if (id.empty() || id.size() > 64) return false;
  return std::all_of(id.begin(), id.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
  });
}

StatusOr<std::shared_ptr<Library>> LoadLibrary(std::string id, const LibrarySources& sources) {
  if (!IsValidId(id)) return InvalidField("library_id", "must match [a-z0-9_-]{1,64}");
  std::vector<PendingClip> pending;
  for (const auto& path : sources.paths) {
    KINEMO_RETURN_IF_ERROR(AddPath(path, &pending));
    if (pending.size() > sources.max_clips) {
      return absl::ResourceExhaustedError(kinemo::StrCat("paths: more than ", sources.max_clips, " clips"));
    }
  }
  for (size_t i = 0; i < sources.inline_clips.size(); ++i) {
    const InlineClipSource& in = sources.inline_clips[i];
    if (in.name.empty()) return InvalidField("clips.name", "must not be empty");
    KINEMO_ASSIGN_OR_RETURN(motion::Clip clip, motion::ParseBvh(in.bvh_text, in.name));
    PendingClip p;
    p.name = in.name;
    p.source = kinemo::StrCat("inline:", in.name);
    p.inline_index = static_cast<int>(i);
    p.tone = motion::internal::ToLower(in.tone);
    for (const auto& k : in.keywords) p.keywords.push_back(motion::internal::ToLower(k));
    p.clip = std::move(clip);
    pending.push_back(std::move(p));
  }
  if (pending.empty()) return InvalidField("paths", "no clips given");
  if (pending.size() > sources.max_clips) {
    return absl::ResourceExhaustedError(kinemo::StrCat("clips: more than ", sources.max_clips, " clips"));
  }

  auto lib = std::make_shared<Library>();
  lib->id = std::move(id);
  // Clips of other exports are mapped by joint name onto the joints every
  // clip has (in the first clip's hierarchy).
  const motion::Skeleton& first = pending.front().clip.skeleton;
  std::set<std::string> common;
  for (const auto& j : first.joints()) common.insert(j.name);
  for (const auto& p : pending) {
    if (SameSkeleton(first, p.clip.skeleton)) continue;
    std::set<std::string> here;
    for (const auto& j : p.clip.skeleton.joints()) {
      if (common.count(j.name)) here.insert(j.name);
    }
    if (here.size() * 2 < static_cast<size_t>(first.num_joints())) {
      return absl::InvalidArgumentError(kinemo::StrCat(p.source, ": skeleton shares ", here.size(), " of ",
                                                       first.num_joints(), " joint names with the library's"));
    }
    common = std::move(here);
  }
  if (common.size() == static_cast<size_t>(first.num_joints())) {
    lib->skeleton = first;
  } else {
    KINEMO_ASSIGN_OR_RETURN(lib->skeleton, CommonSkeleton(first, common));
    std::string dropped;
    for (const auto& j : first.joints()) {
      if (!common.count(j.name)) dropped += (dropped.empty() ? "" : ", ") + j.name;
    }
    lib->warnings.push_back(kinemo::StrCat("skeleton: joints missing in some clips dropped: ", dropped));
  }
  lib->regions = motion::MapBodyRegions(lib->skeleton);
  lib->frame_rate_hz = sources.frame_rate_hz > 0 ? sources.frame_rate_hz : pending.front().clip.fps();
  lib->meters_per_unit = sources.meters_per_unit > 0           ? sources.meters_per_unit
                         : pending.front().meters_per_unit > 0 ? pending.front().meters_per_unit
                                                               : EstimateMetersPerUnit(lib->skeleton);
  std::set<std::string> names;
  for (auto& p : pending) {
    if (!SameSkeleton(lib->skeleton, p.clip.skeleton)) {
      auto mapped = RetargetByJointName(p.clip, lib->skeleton);
      if (!mapped.ok()) return Annotate(mapped.status(), p.source);
      p.clip = *std::move(mapped);
      lib->warnings.push_back(kinemo::StrCat(p.source, ": other skeleton export, mapped by joint name"));
    }
    if (p.clip.num_frames() < 2) {
      return absl::InvalidArgumentError(kinemo::StrCat(p.source, ": fewer than 2 frames"));
    }
    // Unique names: suffix duplicates.
    std::string name = p.name;
    for (int k = 2; names.count(name); ++k) name = kinemo::StrCat(p.name, "#", k);
    if (name != p.name) lib->warnings.push_back(kinemo::StrCat(p.source, ": renamed to '", name, "' (duplicate name)"));
    names.insert(name);
    LibraryClip c;
    c.name = name;
    c.source = p.source;
    if (auto bandai = ParseBandaiName(Stem(p.source))) c.style = bandai->style;
    c.tone = !p.tone.empty() ? p.tone : ToneForStyle(c.style);
    c.keywords = std::move(p.keywords);
    c.annotation_json = std::move(p.annotation_json);
    c.inline_index = p.inline_index;
    if (std::abs(p.clip.fps() - lib->frame_rate_hz) > 1e-3 * lib->frame_rate_hz) {
      KINEMO_ASSIGN_OR_RETURN(c.clip, motion::Resample(p.clip, lib->frame_rate_hz));
      lib->warnings.push_back(kinemo::StrCat(p.source, ": resampled from ", p.clip.fps(), " to ",
                                             lib->frame_rate_hz, " fps"));
    } else {
      c.clip = std::move(p.clip);
    }
    lib->clips.push_back(std::move(c));
  }
  if (lib->regions.num_from_rule() == 0) {
    lib->warnings.push_back("skeleton: no joint matched a body-region rule; regions are guesses");
  }
  return lib;
}

RestFrame FindRestFrame(const Library& library, int only_clip) {
  RestFrame best;
  if (only_clip >= 0) best.clip = only_clip;
  StatusOr<motion::KeyJoints> key = motion::FindKeyJoints(library.skeleton, library.regions);
  if (!key.ok()) return best;
  double best_score = std::numeric_limits<double>::infinity();
  for (size_t c = 0; c < library.clips.size(); ++c) {
    if (only_clip >= 0 && static_cast<int>(c) != only_clip) continue;
    const motion::Clip& clip = library.clips[c].clip;
    StatusOr<Eigen::MatrixXd> world = motion::ComputeWorldPositions(clip);
    if (!world.ok() || clip.num_frames() < 1) continue;
    const int n = clip.num_frames();
    auto y = [&](int f, int j) { return (*world)(f, 3 * j + 1); };
    auto p = [&](int f, int j) { return Eigen::Vector3d((*world).row(f).segment<3>(3 * j).transpose()); };
    const double height = y(0, key->head) - std::min(y(0, key->left_foot), y(0, key->right_foot));
    if (!(height > 0)) continue;
    const double fps = clip.frame_time_s > 0 ? 1.0 / clip.frame_time_s : 30.0;
    std::vector<double> speed(static_cast<size_t>(n), 0.0);
    for (int f = 1; f < n; ++f)
      speed[static_cast<size_t>(f)] = std::max((p(f, key->left_hand) - p(f - 1, key->left_hand)).norm(),
                                               (p(f, key->right_hand) - p(f - 1, key->right_hand)).norm()) *
                                      fps / height;
    const int half = std::max(1, static_cast<int>(std::lround(0.25 * fps)));
    for (int f = 0; f < n; ++f) {
      const double feet = std::min(y(f, key->left_foot), y(f, key->right_foot));
      const double hands = std::max(y(f, key->left_hand), y(f, key->right_hand)) - feet;
      double v = 0;
      for (int g = std::max(1, f - half); g <= std::min(n - 1, f + half); ++g) v = std::max(v, speed[static_cast<size_t>(g)]);
      const double score = hands / height + 0.5 * v;
      if (score < best_score) {
        best_score = score;
        best = {static_cast<int>(c), f};
      }
    }
  }
  return best;
}

}  // namespace kinemo::planner

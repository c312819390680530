// The planner's motion library: BVH clips that share one skeleton and one
// frame rate, with style tones and keyword tags. Gesture segments (Gesture
// Controller), gesture phrases (GMG/BodySpeech) and locomotion graphs are
// computed from a Library by their own modules; a Library is immutable once
// loaded and safe to read from many threads.
//
// Sources: BVH files, folders (every *.bvh inside, recursively, in sorted
// order) and manifest files (*.json):
//
//   {
//     "meters_per_unit": 0.01,          // optional, for every clip listed
//     "clips": [
//       {"path": "dataset-1_bye_normal_001.bvh",   // relative to the manifest
//        "name": "bye_1",                            // optional, default: file stem
//        "tone": "neutral",                          // optional, see below
//        "keywords": ["bye", "goodbye"],             // optional
//        "phrases": [ ... ]}                         // optional annotation, kept
//     ]                                              // verbatim for the GMG module
//   }
//
// Tones: a clip's tone comes from the manifest, or else from the style token
// of a Bandai file name (dataset-N_<content>_<style>_NNN): normal -> neutral;
// active, angry, happy, proud, energetic -> energetic; sad, tired, old,
// feminine -> subdued... see ToneForStyle(); anything else -> neutral.
//
// Scale: meters_per_unit from the request, the manifest, or else estimated
// from the skeleton (EstimateMetersPerUnit).
#pragma once

#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/motion/body_regions.h"
#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::planner {

// Bounds of a library's scale (meters per BVH unit: 0.001 for millimetres,
// 0.01 for centimetres, 1 for metres), from a request or a manifest.
inline constexpr double kMinMetersPerUnit = 1e-6;
inline constexpr double kMaxMetersPerUnit = 1000;

struct LibraryClip {
  std::string name;             // unique in the library
  std::string source;           // file path, or "inline:<name>"
  std::string style;            // raw style token (Bandai file name), may be empty
  std::string tone = "neutral"; // style tone
  std::vector<std::string> keywords;  // lower case
  std::string annotation_json;  // the manifest's "phrases" value, verbatim, or empty
  int inline_index = -1;        // index into LibrarySources::inline_clips, or -1 (read from `source`)
  motion::Clip clip;            // resampled to the library's frame rate
};

struct Library {
  std::string id;
  int version = 1;
  double frame_rate_hz = 0;
  double meters_per_unit = 0;
  motion::Skeleton skeleton;        // shared by every clip
  motion::BodyRegionMap regions;    // body regions of `skeleton`
  std::vector<LibraryClip> clips;
  std::vector<std::string> warnings;  // non-fatal notes from loading

  double duration_s() const;
  std::vector<std::string> tones() const;     // sorted, unique
  std::vector<std::string> keywords() const;  // sorted, unique
  const LibraryClip* FindClip(std::string_view name) const;
};

// A pose to begin and end a motion with, as people do (hands settled): the
// library frame whose higher wrist is lowest above the feet (in body
// heights: both hands down, not one hanging and one raised) and
// stillest (their largest speed over ±0.25 s, body heights per second,
// weighted 0.5 s). Every generator (Gesture Controller, GMG, BodySpeech)
// starts from it and returns to it. {0, 0} when the skeleton has no hands or
// feet (FindKeyJoints). `only_clip` ≥ 0: the best frame of that clip.
struct RestFrame {
  int clip = 0;
  int frame = 0;
};
RestFrame FindRestFrame(const Library& library, int only_clip = -1);

// A clip passed in memory (e.g. InlineClip of the gRPC API).
struct InlineClipSource {
  std::string name;
  std::string bvh_text;
  std::string tone;
  std::vector<std::string> keywords;
};

struct LibrarySources {
  std::vector<std::string> paths;  // files, folders, manifests (already resolved)
  std::vector<InlineClipSource> inline_clips;
  double meters_per_unit = 0;      // 0 = manifest or estimate
  double frame_rate_hz = 0;        // 0 = the first clip's rate
  size_t max_clips = 10000;
};

// Loads and validates every source. Clips whose skeleton differs from the
// first one's (another export of the same rig: extra or missing joints, other
// root, other position convention) are mapped by joint name: the library
// keeps the joints every clip names (a warning lists the dropped ones) and
// each such clip is retargeted by world pose (RetargetByJointName). A clip
// sharing fewer than half of the first clip's joint names is refused. Errors name the file (and line
// for BVH syntax) or the manifest field that is wrong.
StatusOr<std::shared_ptr<Library>> LoadLibrary(std::string id, const LibrarySources& sources);

// Writes the files of a stored library version into the folder `dir`:
// clips/<clip name>.bvh, each clip's source bytes (the file it was read
// from, or its inline text; names made file-safe and unique), and
// manifest.json listing every clip in order with its path, name, tone,
// keywords and phrase annotation, and the library's meters_per_unit. Loading
// <dir>/manifest.json gives the same library (same clips, skeleton, rate,
// scale) without the original sources. `sources` are those `library` was
// loaded from (for the inline clips' text).
Status WriteLibraryFiles(const Library& library, const LibrarySources& sources, const std::string& dir);

// The clip re-expressed on `dst`, whose joints must all be named in the
// clip's skeleton: every joint gets the clip's world rotation (and, where it
// has position channels, world position) frame by frame. Bone lengths come
// from `dst`. Errors name the missing joint.
StatusOr<motion::Clip> RetargetByJointName(const motion::Clip& src, const motion::Skeleton& dst);

// Style token -> tone ("neutral", "energetic", "subdued").
std::string ToneForStyle(std::string_view style);

// Parses a Bandai-style file stem "dataset-1_bye_normal_001" into
// {content, style}; nullopt if it has another shape.
struct BandaiName {
  std::string content;
  std::string style;
};
std::optional<BandaiName> ParseBandaiName(std::string_view stem);

// Metres per skeleton unit estimated from the bone lengths between the head
// and a foot (ankle) joint, taken as 1.50 m; 0.01 if those joints are unknown.
double EstimateMetersPerUnit(const motion::Skeleton& skeleton);

// Ids of stored objects: [a-z0-9_-]{1,64}.
bool IsValidId(std::string_view id);

// Thread-safe map of the immutable objects a service serves, by id: one
// version of each (the newest in the artifact store, whose version numbers
// it carries). T has an `int version` member.
template <typename T>
class VersionedStore {
 public:
  // Serves `value` as version `version` of `id` (sets its `version` member),
  // replacing what was served under `id`.
  void Set(const std::string& id, std::shared_ptr<T> value, int version) {
    value->version = version;
    std::lock_guard lock(mu_);
    items_[id] = Item{version, std::move(value)};
  }
  // Stops serving `id` (objects in use elsewhere stay alive).
  void Remove(const std::string& id) {
    std::lock_guard lock(mu_);
    items_.erase(id);
  }
  // The version served, or NOT_FOUND naming `what`.
  StatusOr<std::shared_ptr<const T>> Get(const std::string& id, std::string_view what) const {
    std::lock_guard lock(mu_);
    auto it = items_.find(id);
    if (it == items_.end()) {
      return absl::NotFoundError(kinemo::StrCat(what, ": no '", id, "'"));
    }
    return it->second.value;
  }
  // The version served, 0 if none.
  int Version(const std::string& id) const {
    std::lock_guard lock(mu_);
    auto it = items_.find(id);
    return it == items_.end() ? 0 : it->second.version;
  }
  size_t size() const {
    std::lock_guard lock(mu_);
    return items_.size();
  }

 private:
  struct Item {
    int version = 0;
    std::shared_ptr<const T> value;
  };
  mutable std::mutex mu_;
  std::map<std::string, Item> items_;
};

using LibraryStore = VersionedStore<Library>;

}  // namespace kinemo::planner

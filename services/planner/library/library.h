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

struct LibraryClip {
  std::string name;             // unique in the library
  std::string source;           // file path, or "inline:<name>"
  std::string style;            // raw style token (Bandai file name), may be empty
  std::string tone = "neutral"; // style tone
  std::vector<std::string> keywords;  // lower case
  std::string annotation_json;  // the manifest's "phrases" value, verbatim, or empty
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

// Thread-safe store of immutable objects by id, with versions. T has an
// `int version` member.
template <typename T>
class VersionedStore {
 public:
  // Stores `value` under `id` and sets its `version` member (1, 2, ...);
  // ALREADY_EXISTS if present and !overwrite. Returns the version stored.
  StatusOr<int> Put(const std::string& id, std::shared_ptr<T> value, bool overwrite) {
    std::lock_guard lock(mu_);
    auto it = items_.find(id);
    if (it != items_.end() && !overwrite) {
      return absl::AlreadyExistsError(kinemo::StrCat("id: '", id, "' exists (set overwrite)"));
    }
    int version = it == items_.end() ? 1 : it->second.version + 1;
    value->version = version;
    items_[id] = Item{version, std::move(value)};
    return version;
  }
  // The latest version, or NOT_FOUND naming `what`.
  StatusOr<std::shared_ptr<const T>> Get(const std::string& id, std::string_view what) const {
    std::lock_guard lock(mu_);
    auto it = items_.find(id);
    if (it == items_.end()) {
      return absl::NotFoundError(kinemo::StrCat(what, ": no '", id, "'"));
    }
    return it->second.value;
  }
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

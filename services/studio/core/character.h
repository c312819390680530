// The studio's characters: the bundled glTF characters
// (StudioOptions.character_dir, GET /characters/) and the user's uploaded
// GLB / VRM, and motion on them. The studio retargets (common/retarget) and
// sends the page each frame as glTF node transforms (CharacterMotion); the
// page only skins. No gRPC here.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/face/face_frame.h"
#include "common/motion/skeleton.h"
#include "common/retarget/gltf.h"
#include "common/retarget/retarget.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"
#include "kinemo/common/v1/motion.pb.h"
#include "kinemo/studio/v1/options.pb.h"
#include "kinemo/studio/v1/studio.pb.h"

namespace kinemo::studio {

// The weights (0..1) of a character's face targets (CharacterInfo.
// face_targets, in order) for one face frame: the rig's face mapping
// (common/retarget) evaluated; `out` has one entry per target.
using FaceWeights = std::function<void(const face::FaceFrame& frame, std::span<float> out)>;

// A loaded character; immutable, shared by every socket that chose it.
struct Character {
  retarget::Rig rig;
  v1::CharacterInfo info;
  // Set when info.face_targets is not empty.
  FaceWeights face_weights;
};

// A FaceFrame of the wire as the core's, every number checked against its
// documented range (face.proto); INVALID_ARGUMENT naming `field`'s member
// ("<field>.jaw_open_deg: ...").
StatusOr<face::FaceFrame> FaceFrameFromProto(const common::v1::FaceFrame& frame, std::string_view field);

// Frames a `retarget` call may carry (30 minutes at 30 fps).
inline constexpr int kMaxRetargetFrames = 54000;

class CharacterLibrary {
 public:
  // Lists the bundled characters (.glb, .vrm) of options.character_dir
  // (resolved; empty = none).
  explicit CharacterLibrary(const v1::StudioOptions& options);

  struct File {
    std::string name;  // file name: what `character.bundled` names
    std::string path;  // absolute
    std::uintmax_t bytes = 0;
    std::string credit;  // <name>.credit.txt beside it (first line), shown by the page
  };
  const std::vector<File>& files() const { return files_; }
  // GET /characters/: {"characters": [{"name", "url", "bytes", "credit"}]},
  // GLB files before VRM files, each by name (the page shows the first).
  std::string ListJson() const;
  // The file `name` names, or null.
  const File* Find(std::string_view name) const;

  // The character a `character` message asks for: a bundled one (loaded on
  // first use, then cached) or an upload. INVALID_ARGUMENT naming
  // "character.<field>" for an unknown name, an oversized, malformed or
  // unrigged upload, or a rig missing required roles; NOT_FOUND for an
  // unknown bundled name.
  StatusOr<std::shared_ptr<const Character>> Select(const v1::SelectCharacter& request);

 private:
  std::string dir_;
  std::uint64_t max_bytes_;
  std::vector<File> files_;
  std::mutex mu_;
  std::map<std::string, std::shared_ptr<const Character>> loaded_;  // guarded by mu_
};

// Motion of one source skeleton (SMPL-X, Bandai, CMU, ...) onto one
// character, frame by frame: Retargeter then NodePoser.
class CharacterDriver {
 public:
  // `meters_per_unit` of the source (0 = estimated from its legs).
  static StatusOr<std::unique_ptr<CharacterDriver>> Create(std::shared_ptr<const Character> character,
                                                           const motion::Skeleton& source, double meters_per_unit,
                                                           double frame_time_s);

  // Appends one source frame (channel values) to `out` (rotations,
  // translations, frames) and, for a character with face targets, the
  // weights of `face` (null: the face at rest, all zero).
  Status Drive(std::span<const double> frame, const face::FaceFrame* face, v1::CharacterMotion* out);
  // An empty CharacterMotion for this character (name, frame time, roles).
  v1::CharacterMotion Start(double start_time_s) const;

  const Character& character() const { return *character_; }
  const motion::Skeleton& source() const { return source_; }

 private:
  CharacterDriver(std::shared_ptr<const Character> character, motion::Skeleton source,
                  retarget::Retargeter retargeter, retarget::NodePoser poser, double frame_time_s);
  std::shared_ptr<const Character> character_;
  motion::Skeleton source_;
  retarget::Retargeter retargeter_;
  retarget::NodePoser poser_;
  double frame_time_s_;
  // Keeps the feet out of the floor: raises the hips when a foot's lowest
  // point (its end site, which the rig puts on the sole) is below y = 0.
  void KeepAboveFloor();
  std::vector<double> target_frame_;
  std::vector<float> rotations_, translations_, face_;
  std::vector<std::pair<int, Eigen::Vector3d>> feet_;  // sole points: joint, offset (below each foot)
  int hips_y_column_ = -1;     // the hips' Y position channel
  std::vector<Eigen::Vector3d> pos_;
  std::vector<Eigen::Matrix3d> rot_;
};

// `retarget`: a whole BVH onto `character`, with its face track when
// `face` is not null (frame i of the motion takes the face frame at its
// time; past the track's end the last one). INVALID_ARGUMENT naming
// "retarget.bvh" for a malformed BVH, a skeleton without the required
// roles, or more than kMaxRetargetFrames frames; "retarget.face..." for a
// track with more frames than the motion, a frame time outside (0, 1] or a
// number outside its range.
StatusOr<v1::CharacterMotion> RetargetBvh(std::shared_ptr<const Character> character, std::string_view bvh,
                                          std::string_view name, const common::v1::FaceTrack* face = nullptr);

// A face track of the wire (`field`: "retarget.face") as the core's, every
// frame checked (FaceFrameFromProto); at most `motion_frames` frames, a frame
// time in (0, 1]. An empty track gives an empty one.
StatusOr<face::FaceTrack> FaceTrackOf(const common::v1::FaceTrack& face, int motion_frames, std::string_view field);

// Frames an `export_motion` call may carry (5 minutes at 30 fps: the
// character's GLB grows by about 2 kB a frame).
inline constexpr int kMaxExportFrames = 9000;

// `export_motion`: a whole BVH and its face onto `character`, written as
// what `kinemo retarget IN.bvh --to RIG -o OUT.vrma|OUT.glb --visemes`
// writes (retarget::WriteVrmAnimation / WriteAnimatedGlb). INVALID_ARGUMENT
// naming "export_motion.<field>": no format, a VRMA for a character that is
// no VRM, a malformed BVH or one over kMaxExportFrames, a bad face track.
StatusOr<v1::ExportedFile> ExportBvh(std::shared_ptr<const Character> character, const v1::ExportMotion& request);

// A live stream's skeleton (MotionStreamHeader.skeleton) as a
// motion::Skeleton; INVALID_ARGUMENT naming "header.skeleton..." when bad.
StatusOr<motion::Skeleton> SkeletonFromProto(const common::v1::Skeleton& skeleton);

// Live: the frames of one stream onto the socket's character. The driver
// is made from the stream's header, and made again when the socket's
// character changes.
class LiveCharacter {
 public:
  // Remembers the stream's header.
  Status SetHeader(const common::v1::MotionStreamHeader& header);
  // The batch on `character` (null: nothing to send), each frame's face
  // with it. Errors name "stream.frames".
  StatusOr<std::unique_ptr<v1::CharacterMotion>> Drive(const std::shared_ptr<const Character>& character,
                                                       const common::v1::MotionFrameBatch& batch);

 private:
  bool has_header_ = false;
  motion::Skeleton skeleton_;
  double meters_per_unit_ = 0, frame_time_s_ = 1.0 / 30;
  std::unique_ptr<CharacterDriver> driver_;
  std::vector<double> values_;
  face::FaceFrame face_;
};

}  // namespace kinemo::studio

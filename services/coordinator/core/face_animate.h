// The face in the speech -> animation pipeline (docs/face.md), plain C++ on
// the protos (no gRPC): the prosody service's speech face (10 ms frames),
// its accents and the tone become a face track on the motion's clock
// (common/face/face_compose.h); every motion frame carries its face
// (MotionFrame.face) and the SMPL-X `jaw` joint is driven by the face's jaw
// opening (common/face/jaw.h) instead of the library's.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/face/face_compose.h"
#include "common/status/status.h"
#include "kinemo/common/v1/motion.pb.h"
#include "kinemo/planner/v1/planner.pb.h"
#include "kinemo/prosody/v1/prosody.pb.h"

namespace kinemo::coordinator {

// The expression of a style: the tone with the largest weight (neutral when
// none), its weight.
std::pair<face::Expression, float> ExpressionOfStyle(const planner::v1::StyleVector& style);

// Offline: composes the face of every frame of `motion` (clip or BVH text)
// from the track's speech face and accents, writes it into the clip's frames
// (MotionFrame.face) and, when the skeleton is SMPL-X (joints pelvis, spine3
// and jaw, the jaw with Z, X and Y rotation channels), the jaw's rotation (a BVH is parsed, changed and written
// again); returns the face track. FAILED_PRECONDITION when the track has no
// speech face; INTERNAL for a BVH that does not parse.
StatusOr<face::FaceTrack> AddFaceToMotion(const prosody::v1::ProsodyTrack& track, face::Expression expression,
                                          float expression_weight, double face_emphasis,
                                          common::v1::Motion* motion);

// Columns of the (Z, X, Y) rotation channels of the `jaw` joint of an
// SMPL-X skeleton (one with pelvis and spine3 too), or nullopt.
std::optional<std::array<int, 3>> JawColumns(const common::v1::Skeleton& skeleton);

// AnimateChunked: the face of a motion that passes through in pieces (the
// planner's MotionChunk: BVH text, or a clip's header and frame batches),
// composed as each piece goes by. The speech face and accents of the whole
// recording are known first (prosody answers before the planner starts);
// each motion frame gets the face AddFaceToMotion gives the same frame of
// the whole motion, and the SMPL-X `jaw` joint its jaw (in BVH text, the
// jaw's three values of each frame line are rewritten, written as WriteBvh
// writes numbers; every other byte passes through). Holds the speech face
// (88 bytes per 10 ms) and at most one incomplete BVH line.
class ChunkedMotionFace {
 public:
  ChunkedMotionFace(face::Expression expression, float expression_weight, double face_emphasis);
  // Before the first piece: the track's accents, then its speech face in
  // batches (prosody AnalyzeChunked's `face`).
  void AddAccents(const prosody::v1::ProsodyTrack& track);
  void AddSpeech(const prosody::v1::SpeechFaceBatch& batch);
  // Speech frames received (0: no face; pieces then pass unchanged).
  std::int64_t speech_frames() const { return speech_frames_; }
  // One motion piece, changed in place: a BVH piece's frame lines get the
  // driven jaw (a line cut at the piece's end is held back and goes out at
  // the front of the next piece, or from Finish); clip frames get their
  // MotionFrame.face and jaw. The faces of the frames it completed are
  // appended to `faces`. INTERNAL for a BVH header that does not parse.
  Status Add(common::v1::MotionChunk* piece, std::vector<face::FaceFrame>* faces);
  // After the last piece: the held-back end of BVH text without a final
  // newline (usually empty), its frame's face appended to `faces`.
  Status Finish(std::string* rest, std::vector<face::FaceFrame>* faces);
  // The motion's frame time (0 before its header), frames seen so far.
  double frame_time_s() const { return frame_time_s_; }
  std::int64_t frames() const { return frames_; }

 private:
  Status AddBvh(std::string* text, std::vector<face::FaceFrame>* faces);
  void Line(std::string_view line, std::string* out, std::vector<face::FaceFrame>* faces);

  face::FaceComposer composer_;
  std::int64_t speech_frames_ = 0;
  bool header_done_ = false;
  std::string carry_;  // header text until it is whole, then an incomplete frame line
  std::optional<std::array<int, 3>> jaw_;  // columns of the jaw's Z, X, Y rotations
  double frame_time_s_ = 0;
  std::int64_t frames_ = 0;
};

// Live: the face of a StreamAnimate stream. Speech-face batches, accents and
// tone changes go in as prosody and the session send them; each motion frame
// the planner makes gets its face once the speech face reaches its time
// (Ready), never from later audio.
class LiveFace {
 public:
  explicit LiveFace(double face_emphasis);
  // The stream's header: where its jaw is (nothing is driven without one).
  void SetSkeleton(const common::v1::Skeleton& skeleton);
  void AddSpeech(const prosody::v1::SpeechFaceBatch& batch);
  void AddAccent(const common::v1::PitchAccent& accent);
  void SetTone(double time_s, const std::string& tone, double weight);
  // Prosody ended: frames past the last speech frame take it as it was.
  void FinishSpeech() { composer_.FinishSpeech(); }
  bool Ready(double time_s) const { return composer_.Ready(time_s); }
  // Fills frame.face and the jaw channels.
  void Fill(common::v1::MotionFrame* frame);
  // Audio time the speech face reaches.
  double speech_until_s() const { return composer_.speech_until_s(); }

 private:
  face::FaceComposer composer_;
  std::optional<std::array<int, 3>> jaw_;
};

}  // namespace kinemo::coordinator

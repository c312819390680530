#include "services/coordinator/core/face_animate.h"

#include <cmath>

#include "common/face/face_proto.h"
#include "common/face/jaw.h"
#include "common/motion/bvh.h"

namespace kinemo::coordinator {
namespace {

face::FaceAccent ToFaceAccent(const common::v1::PitchAccent& a) {
  return {a.time_s(), a.strength(), a.syllable_start_s(), a.syllable_end_s()};
}

void SetJaw(const std::array<int, 3>& columns, double open_deg, double* values) {
  const std::array<double, 3> zxy = face::SmplxJawZxyDeg(open_deg);
  for (int i = 0; i < 3; ++i) values[columns[i]] = zxy[i];
}

}  // namespace

std::pair<face::Expression, float> ExpressionOfStyle(const planner::v1::StyleVector& style) {
  std::string best;
  double best_w = 0, sum = 0;
  for (const auto& [tone, w] : style.tone_weights()) {
    sum += std::max(0.0, w);
    if (w > best_w || (w == best_w && tone < best)) {
      best = tone;
      best_w = w;
    }
  }
  if (best.empty() || !(sum > 0)) return {face::Expression::kNeutral, 0.0f};
  return {face::ExpressionForTone(best), static_cast<float>(best_w / sum)};
}

std::optional<std::array<int, 3>> JawColumns(const common::v1::Skeleton& skeleton) {
  // Only an SMPL-X skeleton (its pelvis and spine3 beside the jaw): the hinge
  // is that joint's (a rig's jaw bone is driven by its face mapping).
  bool pelvis = false, spine3 = false;
  for (const auto& j : skeleton.joints()) {
    pelvis = pelvis || j.name() == "pelvis";
    spine3 = spine3 || j.name() == "spine3";
  }
  if (!pelvis || !spine3) return std::nullopt;
  int column = 0;
  for (const auto& j : skeleton.joints()) {
    if (j.name() == "jaw") {
      std::array<int, 3> out = {-1, -1, -1};  // Z, X, Y
      for (int c = 0; c < j.channels_size(); ++c) {
        if (j.channels(c) == common::v1::CHANNEL_Z_ROTATION) out[0] = column + c;
        if (j.channels(c) == common::v1::CHANNEL_X_ROTATION) out[1] = column + c;
        if (j.channels(c) == common::v1::CHANNEL_Y_ROTATION) out[2] = column + c;
      }
      if (out[0] < 0 || out[1] < 0 || out[2] < 0) return std::nullopt;
      return out;
    }
    column += j.channels_size();
  }
  return std::nullopt;
}

StatusOr<face::FaceTrack> AddFaceToMotion(const prosody::v1::ProsodyTrack& track, face::Expression expression,
                                          float expression_weight, double face_emphasis,
                                          common::v1::Motion* motion) {
  if (track.face_size() == 0) return absl::FailedPreconditionError("prosody: no speech face in the track");
  std::vector<face::SpeechFaceFrame> speech;
  speech.reserve(static_cast<std::size_t>(track.face_size()));
  for (const auto& f : track.face()) speech.push_back(face::FromProto(f));
  std::vector<face::FaceAccent> accents;
  for (const auto& a : track.accents()) accents.push_back(ToFaceAccent(a));
  face::ComposeOptions options;
  options.face_emphasis = face_emphasis;
  if (motion->has_clip()) {
    common::v1::MotionClip* clip = motion->mutable_clip();
    const int n = clip->frames_size();
    face::FaceTrack face = face::ComposeTrack(speech, accents, expression, expression_weight, clip->frame_time_s(),
                                              n > 0 ? (n - 1) * clip->frame_time_s() : 0.0, options);
    const auto jaw = JawColumns(clip->skeleton());
    for (int i = 0; i < n && i < static_cast<int>(face.frames.size()); ++i) {
      common::v1::MotionFrame* f = clip->mutable_frames(i);
      face::ToProto(face.frames[i], f->mutable_face());
      f->mutable_face()->set_time_s(f->time_s());
      if (jaw && std::max({(*jaw)[0], (*jaw)[1], (*jaw)[2]}) < f->values_size()) {
        SetJaw(*jaw, face.frames[i].jaw_open_deg, f->mutable_values()->mutable_data());
      }
    }
    return face;
  }
  // BVH text: parse, drive the jaw, write again.
  auto clip = motion::ParseBvh(motion->bvh(), "motion");
  if (!clip.ok()) return absl::InternalError(kinemo::StrCat("planner BVH: ", clip.status().message()));
  const int n = clip->num_frames();
  face::FaceTrack face = face::ComposeTrack(speech, accents, expression, expression_weight, clip->frame_time_s,
                                            n > 0 ? (n - 1) * clip->frame_time_s : 0.0, options);
  const int j = clip->skeleton.FindJoint("jaw");
  if (j >= 0 && clip->skeleton.FindJoint("pelvis") >= 0 && clip->skeleton.FindJoint("spine3") >= 0) {
    const motion::Joint& joint = clip->skeleton.joint(j);
    std::array<int, 3> cols = {-1, -1, -1};
    for (int c = 0; c < joint.num_channels(); ++c) {
      if (joint.channels[c] == motion::ChannelType::kZRotation) cols[0] = joint.first_channel + c;
      if (joint.channels[c] == motion::ChannelType::kXRotation) cols[1] = joint.first_channel + c;
      if (joint.channels[c] == motion::ChannelType::kYRotation) cols[2] = joint.first_channel + c;
    }
    if (cols[0] >= 0 && cols[1] >= 0 && cols[2] >= 0) {
      for (int i = 0; i < n && i < static_cast<int>(face.frames.size()); ++i) {
        SetJaw(cols, face.frames[i].jaw_open_deg, clip->frames.data() + static_cast<Eigen::Index>(i) * clip->frames.cols());
      }
      KINEMO_ASSIGN_OR_RETURN(std::string text, motion::WriteBvh(*clip));
      motion->set_bvh(std::move(text));
    }
  }
  return face;
}

LiveFace::LiveFace(double face_emphasis) : composer_([&] {
  face::ComposeOptions o;
  o.face_emphasis = face_emphasis;
  return o;
}()) {}

void LiveFace::SetSkeleton(const common::v1::Skeleton& skeleton) { jaw_ = JawColumns(skeleton); }

void LiveFace::AddSpeech(const prosody::v1::SpeechFaceBatch& batch) {
  for (const auto& f : batch.frames()) composer_.AddSpeech(face::FromProto(f));
}

void LiveFace::AddAccent(const common::v1::PitchAccent& accent) { composer_.AddAccent(ToFaceAccent(accent)); }

void LiveFace::SetTone(double time_s, const std::string& tone, double weight) {
  composer_.SetExpression(time_s, face::ExpressionForTone(tone), static_cast<float>(weight));
}

void LiveFace::Fill(common::v1::MotionFrame* frame) {
  const face::FaceFrame f = composer_.Compose(frame->time_s());
  face::ToProto(f, frame->mutable_face());
  if (jaw_ && std::max({(*jaw_)[0], (*jaw_)[1], (*jaw_)[2]}) < frame->values_size()) {
    SetJaw(*jaw_, f.jaw_open_deg, frame->mutable_values()->mutable_data());
  }
}

}  // namespace kinemo::coordinator

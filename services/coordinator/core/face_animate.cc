#include "services/coordinator/core/face_animate.h"

#include <algorithm>
#include <charconv>
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

// The SMPL-X jaw's Z, X, Y rotation columns in a BVH skeleton (one with a
// jaw, pelvis and spine3 joint), or none.
std::optional<std::array<int, 3>> JawColumns(const motion::Skeleton& skeleton) {
  const int j = skeleton.FindJoint("jaw");
  if (j < 0 || skeleton.FindJoint("pelvis") < 0 || skeleton.FindJoint("spine3") < 0) return std::nullopt;
  const motion::Joint& joint = skeleton.joint(j);
  std::array<int, 3> cols = {-1, -1, -1};
  for (int c = 0; c < joint.num_channels(); ++c) {
    if (joint.channels[c] == motion::ChannelType::kZRotation) cols[0] = joint.first_channel + c;
    if (joint.channels[c] == motion::ChannelType::kXRotation) cols[1] = joint.first_channel + c;
    if (joint.channels[c] == motion::ChannelType::kYRotation) cols[2] = joint.first_channel + c;
  }
  if (cols[0] < 0 || cols[1] < 0 || cols[2] < 0) return std::nullopt;
  return cols;
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
  if (const auto cols = JawColumns(clip->skeleton)) {
    for (int i = 0; i < n && i < static_cast<int>(face.frames.size()); ++i) {
      SetJaw(*cols, face.frames[i].jaw_open_deg, clip->frames.data() + static_cast<Eigen::Index>(i) * clip->frames.cols());
    }
    KINEMO_ASSIGN_OR_RETURN(std::string text, motion::WriteBvh(*clip));
    motion->set_bvh(std::move(text));
  }
  return face;
}

namespace {

face::ComposeOptions ComposeOptionsWith(double face_emphasis) {
  face::ComposeOptions o;
  o.face_emphasis = face_emphasis;
  return o;
}

bool IsBvhSpace(char c) { return c == ' ' || c == '\t' || c == '\r'; }

// A number as WriteBvh writes it (the shortest text that reads back the same).
void AppendBvhNumber(double v, std::string* out) {
  char buf[64];
  const std::to_chars_result r = std::to_chars(buf, buf + sizeof(buf), v);
  out->append(buf, r.ptr);
}

}  // namespace

ChunkedMotionFace::ChunkedMotionFace(face::Expression expression, float expression_weight, double face_emphasis)
    : composer_(ComposeOptionsWith(face_emphasis)) {
  // As ComposeTrack: one expression from the start.
  composer_.SetExpression(0, expression, expression_weight);
}

void ChunkedMotionFace::AddAccents(const prosody::v1::ProsodyTrack& track) {
  for (const auto& a : track.accents()) composer_.AddAccent(ToFaceAccent(a));
}

void ChunkedMotionFace::AddSpeech(const prosody::v1::SpeechFaceBatch& batch) {
  for (const auto& f : batch.frames()) composer_.AddSpeech(face::FromProto(f));
  speech_frames_ += batch.frames_size();
}

Status ChunkedMotionFace::Add(common::v1::MotionChunk* piece, std::vector<face::FaceFrame>* faces) {
  if (speech_frames_ == 0) return absl::OkStatus();
  composer_.FinishSpeech();  // every speech frame came before the motion
  if (piece->has_bvh()) return AddBvh(piece->mutable_bvh(), faces);
  if (piece->has_header()) {
    jaw_ = JawColumns(piece->header().skeleton());
    frame_time_s_ = piece->header().frame_time_s();
    return absl::OkStatus();
  }
  if (piece->has_frames()) {
    for (common::v1::MotionFrame& f : *piece->mutable_frames()->mutable_frames()) {
      face::FaceFrame face = composer_.Compose(static_cast<double>(frames_++) * frame_time_s_);
      face::ToProto(face, f.mutable_face());
      f.mutable_face()->set_time_s(f.time_s());
      if (jaw_ && std::max({(*jaw_)[0], (*jaw_)[1], (*jaw_)[2]}) < f.values_size()) {
        SetJaw(*jaw_, face.jaw_open_deg, f.mutable_values()->mutable_data());
      }
      faces->push_back(face);
    }
  }
  return absl::OkStatus();
}

Status ChunkedMotionFace::AddBvh(std::string* text, std::vector<face::FaceFrame>* faces) {
  std::string in = std::move(carry_);
  carry_.clear();
  in.append(*text);
  text->clear();
  std::size_t at = 0;
  if (!header_done_) {
    // The header ends with the "Frame Time:" line.
    const std::size_t ft = in.find("Frame Time:");
    const std::size_t end = ft == std::string::npos ? std::string::npos : in.find('\n', ft);
    if (end == std::string::npos) {
      carry_ = std::move(in);
      return absl::OkStatus();
    }
    at = end + 1;
    // Its skeleton and frame time: the header parsed as a BVH of no frames.
    std::string header = in.substr(0, at);
    const std::size_t count = header.rfind("Frames:", ft);
    if (count == std::string::npos) return absl::InternalError("planner BVH: no Frames: line before Frame Time:");
    header.replace(count, ft - count, "Frames: 0\n");
    auto clip = motion::ParseBvh(header, "motion");
    if (!clip.ok()) return absl::InternalError(kinemo::StrCat("planner BVH: ", clip.status().message()));
    frame_time_s_ = clip->frame_time_s;
    jaw_ = JawColumns(clip->skeleton);
    header_done_ = true;
    text->append(in, 0, at);
  }
  text->reserve(text->size() + in.size() - at);
  while (at < in.size()) {
    const std::size_t nl = in.find('\n', at);
    if (nl == std::string::npos) {
      carry_.assign(in, at, std::string::npos);
      break;
    }
    Line(std::string_view(in).substr(at, nl + 1 - at), text, faces);
    at = nl + 1;
  }
  return absl::OkStatus();
}

void ChunkedMotionFace::Line(std::string_view line, std::string* out, std::vector<face::FaceFrame>* faces) {
  bool blank = true;
  for (char c : line) blank = blank && (IsBvhSpace(c) || c == '\n');
  if (blank) {  // not a frame
    out->append(line);
    return;
  }
  const face::FaceFrame face = composer_.Compose(static_cast<double>(frames_++) * frame_time_s_);
  faces->push_back(face);
  if (!jaw_) {
    out->append(line);
    return;
  }
  // The jaw's three values replaced, every other byte as it came.
  const std::array<double, 3> zxy = face::SmplxJawZxyDeg(face.jaw_open_deg);
  int column = 0;
  std::size_t i = 0;
  while (i < line.size()) {
    std::size_t j = i;
    while (j < line.size() && (IsBvhSpace(line[j]) || line[j] == '\n')) ++j;
    out->append(line.substr(i, j - i));
    if (j >= line.size()) break;
    std::size_t k = j;
    while (k < line.size() && !IsBvhSpace(line[k]) && line[k] != '\n') ++k;
    int which = -1;
    for (int a = 0; a < 3; ++a) {
      if ((*jaw_)[a] == column) which = a;
    }
    if (which >= 0) {
      AppendBvhNumber(zxy[which], out);
    } else {
      out->append(line.substr(j, k - j));
    }
    ++column;
    i = k;
  }
}

Status ChunkedMotionFace::Finish(std::string* rest, std::vector<face::FaceFrame>* faces) {
  rest->clear();
  if (carry_.empty()) return absl::OkStatus();
  if (!header_done_) return absl::InternalError("planner BVH: the motion ended inside its header");
  std::string line = std::move(carry_);
  carry_.clear();
  Line(line, rest, faces);
  return absl::OkStatus();
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

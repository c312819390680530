#include "common/face/face_proto.h"

#include <algorithm>

namespace kinemo::face {

void ToProto(const FaceFrame& f, common::v1::FaceFrame* out) {
  out->set_time_s(f.time_s);
  out->mutable_ovr_visemes()->Assign(f.ovr.begin(), f.ovr.end());
  out->mutable_categories()->Assign(f.categories.begin(), f.categories.end());
  out->set_jaw_open_deg(f.jaw_open_deg);
  out->set_blink_left(f.blink_left);
  out->set_blink_right(f.blink_right);
  out->set_brow_raise(f.brow_raise);
  out->set_expression(static_cast<common::v1::FaceExpression>(static_cast<int>(f.expression) + 1));
  out->set_expression_weight(f.expression_weight);
  out->set_emphasis(f.emphasis);
}

void ToProto(const FaceTrack& t, common::v1::FaceTrack* out) {
  out->set_frame_time_s(t.frame_time_s);
  for (const FaceFrame& f : t.frames) ToProto(f, out->add_frames());
}

FaceFrame FromProto(const common::v1::FaceFrame& p) {
  FaceFrame f;
  f.time_s = p.time_s();
  for (int i = 0; i < std::min(p.ovr_visemes_size(), kNumOvrVisemes); ++i) f.ovr[i] = p.ovr_visemes(i);
  for (int i = 0; i < std::min(p.categories_size(), kNumCategories); ++i) f.categories[i] = p.categories(i);
  f.jaw_open_deg = p.jaw_open_deg();
  f.blink_left = p.blink_left();
  f.blink_right = p.blink_right();
  f.brow_raise = p.brow_raise();
  const int e = static_cast<int>(p.expression()) - 1;
  f.expression = e >= 0 && e < static_cast<int>(kExpressionNames.size()) ? static_cast<Expression>(e) : Expression::kNeutral;
  f.expression_weight = p.expression_weight();
  f.emphasis = p.emphasis();
  return f;
}

FaceTrack FromProto(const common::v1::FaceTrack& p) {
  FaceTrack t;
  t.frame_time_s = p.frame_time_s();
  t.frames.reserve(static_cast<std::size_t>(p.frames_size()));
  for (const auto& f : p.frames()) t.frames.push_back(FromProto(f));
  return t;
}

SpeechFaceFrame FromProto(const prosody::v1::SpeechFaceFrame& p) {
  SpeechFaceFrame f;
  f.time_s = p.time_s();
  f.jaw_open_deg = p.jaw_open_deg();
  if (p.classes_size() == kNumPhoneClasses) {
    std::copy(p.classes().begin(), p.classes().end(), f.classes.begin());
  } else {
    f.classes[static_cast<int>(PhoneClass::kSil)] = 1;
  }
  return f;
}

}  // namespace kinemo::face

// The face's plain types <-> their protos (kinemo.common.v1.FaceFrame /
// FaceTrack, kinemo.prosody.v1.SpeechFaceFrame).
#pragma once

#include "common/face/face_compose.h"
#include "common/face/face_frame.h"
#include "kinemo/common/v1/face.pb.h"
#include "kinemo/prosody/v1/prosody.pb.h"

namespace kinemo::face {

void ToProto(const FaceFrame& frame, common::v1::FaceFrame* out);
void ToProto(const FaceTrack& track, common::v1::FaceTrack* out);
FaceFrame FromProto(const common::v1::FaceFrame& frame);
FaceTrack FromProto(const common::v1::FaceTrack& track);
// A speech-face frame of the prosody service (classes missing or of another
// count read as silence).
SpeechFaceFrame FromProto(const prosody::v1::SpeechFaceFrame& frame);

}  // namespace kinemo::face

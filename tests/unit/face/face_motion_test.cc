// The face on real motion (services/coordinator/core/face_animate.h): the
// speech face of BEAT2 take 2_2 (a model trained on take 1_1) put on take
// 2_2's own SMPL-X capture as BVH text: every frame gets a face, and the
// `jaw` joint is rewritten from it (rest + opening x hinge), no longer the
// capture's; other joints are untouched. A skeleton that is not SMPL-X (CMU)
// keeps its motion. In pieces (AnimateChunked), the same text and faces.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "common/audio/decode.h"
#include "common/face/face_proto.h"
#include "common/face/jaw.h"
#include "common/motion/bvh.h"
#include "services/coordinator/core/face_animate.h"
#include "services/prosody/core/face_corpus.h"
#include "services/prosody/core/face_model.h"

namespace kinemo::coordinator {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

std::string ReadText(const std::string& path) {
  auto bytes = audio::ReadFileBytes(path, 64u << 20);
  return bytes.ok() ? std::string(bytes->begin(), bytes->end()) : std::string();
}

prosody::v1::ProsodyTrack SpeechFaceTrack() {
  auto train = prosody::ReadFaceTake(kData + "/paired/beat2", "2_scott_0_1_1");
  auto test = prosody::ReadFaceTake(kData + "/paired/beat2", "2_scott_0_2_2");
  EXPECT_TRUE(train.ok() && test.ok());
  auto model = prosody::TrainFaceModel(std::span(&*train, 1), {});
  EXPECT_TRUE(model.ok());
  prosody::v1::ProsodyTrack track;
  for (const auto& f : prosody::AnalyzeFace(test->samples, *model)) {
    auto* p = track.add_face();
    p->set_time_s(f.time_s);
    p->set_jaw_open_deg(f.jaw_open_deg);
    p->mutable_classes()->Add(f.classes.begin(), f.classes.end());
  }
  return track;
}

TEST(FaceOnMotion, TheSmplxJawFollowsTheFace) {
  const prosody::v1::ProsodyTrack track = SpeechFaceTrack();
  common::v1::Motion motion;
  const std::string original = ReadText(kData + "/paired/beat2/2_scott_0_2_2.bvh");
  motion.set_bvh(original);
  auto face = AddFaceToMotion(track, face::Expression::kHappy, 0.5f, 0, &motion);
  ASSERT_TRUE(face.ok()) << face.status();
  auto before = motion::ParseBvh(original, "before");
  auto after = motion::ParseBvh(motion.bvh(), "after");
  ASSERT_TRUE(before.ok() && after.ok());
  ASSERT_EQ(after->num_frames(), before->num_frames());
  ASSERT_EQ(face->frames.size(), static_cast<std::size_t>(after->num_frames()));
  const motion::Joint& jaw = after->skeleton.joint(after->skeleton.FindJoint("jaw"));
  const int x = jaw.first_channel + 1;  // Z X Y
  int changed = 0;
  for (int f = 0; f < after->num_frames(); ++f) {
    EXPECT_NEAR(after->frame(f)[x], face::SmplxJawZxyDeg(face->frames[f].jaw_open_deg)[1], 1e-6);
    changed += std::abs(after->frame(f)[x] - before->frame(f)[x]) > 1e-3;
    // The rest of the body is the planner's.
    EXPECT_DOUBLE_EQ(after->frame(f)[0], before->frame(f)[0]);
    EXPECT_EQ(face->frames[f].expression, face::Expression::kHappy);
  }
  EXPECT_GT(changed, after->num_frames() / 2);
}

TEST(FaceOnMotion, ANonSmplxSkeletonKeepsItsMotionAndGetsTheFace) {
  const prosody::v1::ProsodyTrack track = SpeechFaceTrack();
  common::v1::Motion motion;
  const std::string original = ReadText(kData + "/motion/cmu_007_12_first40.bvh");
  motion.set_bvh(original);
  auto face = AddFaceToMotion(track, face::Expression::kNeutral, 0, 0, &motion);
  ASSERT_TRUE(face.ok()) << face.status();
  EXPECT_EQ(motion.bvh(), original);
  EXPECT_EQ(face->frames.size(), 40u);
}

// AnimateChunked's face (ChunkedMotionFace): the same BVH text, byte for
// byte, and the same faces as AddFaceToMotion gives the whole motion, however
// the text is cut into pieces (inside the header, inside a frame line) and
// the speech face into batches.
TEST(FaceOnMotion, InPiecesTheBvhAndFaceAreTheWholeMotions) {
  const prosody::v1::ProsodyTrack track = SpeechFaceTrack();
  // The capture as the planner writes BVH (WriteBvh's numbers).
  auto capture = motion::ParseBvh(ReadText(kData + "/paired/beat2/2_scott_0_2_2.bvh"), "2_2");
  ASSERT_TRUE(capture.ok()) << capture.status();
  auto text = motion::WriteBvh(*capture);
  ASSERT_TRUE(text.ok());
  common::v1::Motion whole;
  whole.set_bvh(*text);
  auto expected = AddFaceToMotion(track, face::Expression::kAngry, 0.7f, 0.2, &whole);
  ASSERT_TRUE(expected.ok()) << expected.status();
  ASSERT_NE(whole.bvh(), *text);  // the jaw was driven
  for (std::size_t piece_bytes : {std::size_t{500}, std::size_t{7777}, std::size_t{1} << 20}) {
    SCOPED_TRACE(piece_bytes);
    ChunkedMotionFace chunked(face::Expression::kAngry, 0.7f, 0.2);
    chunked.AddAccents(track);
    for (int at = 0; at < track.face_size(); at += 1000) {
      prosody::v1::SpeechFaceBatch batch;
      for (int i = at; i < std::min(track.face_size(), at + 1000); ++i) *batch.add_frames() = track.face(i);
      chunked.AddSpeech(batch);
    }
    EXPECT_EQ(chunked.speech_frames(), track.face_size());
    std::string got;
    std::vector<face::FaceFrame> faces;
    for (std::size_t at = 0; at < text->size(); at += piece_bytes) {
      common::v1::MotionChunk piece;
      piece.set_bvh(text->substr(at, piece_bytes));
      ASSERT_TRUE(chunked.Add(&piece, &faces).ok());
      got += piece.bvh();
    }
    std::string rest;
    ASSERT_TRUE(chunked.Finish(&rest, &faces).ok());
    got += rest;
    EXPECT_TRUE(got == whole.bvh()) << "the text differs from AddFaceToMotion's";
    EXPECT_NEAR(chunked.frame_time_s(), capture->frame_time_s, 1e-12);
    ASSERT_EQ(faces.size(), expected->frames.size());
    EXPECT_EQ(chunked.frames(), capture->num_frames());
    common::v1::FaceTrack a, b;
    face::ToProto(*expected, &a);
    for (const face::FaceFrame& f : faces) face::ToProto(f, b.add_frames());
    b.set_frame_time_s(expected->frame_time_s);
    EXPECT_TRUE(a.SerializeAsString() == b.SerializeAsString()) << "the faces differ from AddFaceToMotion's";
  }
  // No speech face: the pieces pass unchanged, no faces.
  ChunkedMotionFace none(face::Expression::kNeutral, 0, 0);
  common::v1::MotionChunk piece;
  piece.set_bvh(*text);
  std::vector<face::FaceFrame> faces;
  ASSERT_TRUE(none.Add(&piece, &faces).ok());
  EXPECT_TRUE(piece.bvh() == *text);
  EXPECT_TRUE(faces.empty());
}

TEST(FaceOnMotion, NoSpeechFaceIsRefused) {
  common::v1::Motion motion;
  motion.set_bvh(ReadText(kData + "/motion/cmu_007_12_first40.bvh"));
  auto face = AddFaceToMotion(prosody::v1::ProsodyTrack(), face::Expression::kNeutral, 0, 0, &motion);
  EXPECT_EQ(face.status().code(), absl::StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace kinemo::coordinator

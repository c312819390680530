// The face on the body's clock (common/face/face_compose.h): brows lift
// around a pitch accent by its strength, the tone's expression ramps in and a
// change of tone fades the old one out first, vowels of an accented syllable
// carry the thesis's emphasis, frames wait for the speech face (live).
#include <gtest/gtest.h>

#include "common/face/face_compose.h"

namespace kinemo::face {
namespace {

SpeechFaceFrame Vowel(double t) {
  SpeechFaceFrame f;
  f.time_s = t;
  f.jaw_open_deg = 2;
  f.classes[static_cast<int>(PhoneClass::kAA)] = 1;
  return f;
}

TEST(FaceCompose, BrowsLiftAroundAnAccentByItsStrength) {
  FaceComposer c;
  for (int k = 0; k <= 200; ++k) c.AddSpeech(Vowel(k * 0.01));
  c.AddAccent({1.0, 0.8, 0.9, 1.1});
  EXPECT_FLOAT_EQ(c.Compose(0.5).brow_raise, 0.0f);
  EXPECT_NEAR(c.Compose(0.925).brow_raise, 0.8 * 0.5, 1e-3);  // halfway up, 75 ms before
  EXPECT_NEAR(c.Compose(1.05).brow_raise, 0.8, 1e-6);          // held
  const FaceFrame f = c.Compose(1.06);
  EXPECT_NEAR(f.emphasis, 2 * 0.8 - 1, 1e-6);  // a vowel inside the accented syllable
  EXPECT_FLOAT_EQ(c.Compose(1.7).brow_raise, 0.0f);
  EXPECT_FLOAT_EQ(c.Compose(1.7).emphasis, 0.0f);
}

TEST(FaceCompose, TheToneSetsTheExpressionAndChangesFadeThroughZero) {
  EXPECT_EQ(ExpressionForTone("energetic"), Expression::kSurprised);
  EXPECT_EQ(ExpressionForTone("subdued"), Expression::kSad);
  EXPECT_EQ(ExpressionForTone("whatever"), Expression::kNeutral);
  FaceComposer c;
  for (int k = 0; k <= 300; ++k) c.AddSpeech(Vowel(k * 0.01));
  c.SetExpression(0, Expression::kHappy, 1);
  c.SetExpression(1, Expression::kAngry, 0.5f);
  EXPECT_EQ(c.Compose(0).expression, Expression::kHappy);
  EXPECT_FLOAT_EQ(c.Compose(0.5).expression_weight, 1.0f);
  for (int i = 16; i < 30; ++i) c.Compose(i / 30.0);
  const FaceFrame fading = c.Compose(31 / 30.0);  // the happy face fades out first
  EXPECT_EQ(fading.expression, Expression::kHappy);
  EXPECT_LT(fading.expression_weight, 1.0f);
  FaceFrame f;
  for (int i = 32; i <= 60; ++i) f = c.Compose(i / 30.0);
  EXPECT_EQ(f.expression, Expression::kAngry);
  EXPECT_FLOAT_EQ(f.expression_weight, 0.5f);
}

TEST(FaceCompose, LiveFramesWaitForTheSpeechFace) {
  FaceComposer c;
  EXPECT_FALSE(c.Ready(0.0));
  c.AddSpeech(Vowel(0));
  c.AddSpeech(Vowel(0.01));
  EXPECT_TRUE(c.Ready(0.01));
  EXPECT_FALSE(c.Ready(1.0 / 30));
  c.FinishSpeech();
  EXPECT_TRUE(c.Ready(1.0 / 30));
  const FaceFrame f = c.Compose(1.0 / 30);
  EXPECT_FLOAT_EQ(f.jaw_open_deg, 2.0f);
  EXPECT_FLOAT_EQ(f.ovr[static_cast<int>(OvrViseme::kAA)], 1.0f);
}

}  // namespace
}  // namespace kinemo::face

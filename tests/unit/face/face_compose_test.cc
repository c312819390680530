// The face on the body's clock (common/face/face_compose.h): brows lift
// around a pitch accent by its strength, the tone's expression ramps in and a
// change of tone fades the old one out first, vowels of an accented syllable
// carry the thesis's emphasis, frames wait for the speech face (live).
#include <gtest/gtest.h>

#include <utility>
#include <vector>

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

// A long recording's accents (a composer scans only those near the frame):
// 40 min with an accent every 0.8 s, composed at 30 fps, gives the same
// brows and emphasis whether the accents come in time order (the scan stops
// after the frame, old ones are dropped) or shuffled (every accent not yet
// over is looked at).
TEST(FaceCompose, ManyAccentsInOrderOrShuffledGiveTheSameFace) {
  std::vector<FaceAccent> accents;
  for (int k = 0; k < 3000; ++k) {
    const double t = 0.5 + 0.8 * k;
    accents.push_back({t, 0.2 + 0.7 * ((k * 37) % 11) / 10.0, t - 0.12 - 0.01 * (k % 5), t + 0.1 + 0.02 * (k % 7)});
  }
  std::vector<FaceAccent> shuffled = accents;
  for (std::size_t i = 0; i < shuffled.size(); ++i) std::swap(shuffled[i], shuffled[(i * 7919) % shuffled.size()]);
  FaceComposer in_order, out_of_order;
  for (int k = 0; k <= 240000; ++k) {
    in_order.AddSpeech(Vowel(k * 0.01));
    out_of_order.AddSpeech(Vowel(k * 0.01));
  }
  for (const FaceAccent& a : accents) in_order.AddAccent(a);
  for (const FaceAccent& a : shuffled) out_of_order.AddAccent(a);
  int lifted = 0, emphatic = 0;
  for (int i = 0; i < 72000; ++i) {
    const double t = i / 30.0;
    const FaceFrame a = in_order.Compose(t), b = out_of_order.Compose(t);
    ASSERT_EQ(a.brow_raise, b.brow_raise) << "t = " << t;
    ASSERT_EQ(a.emphasis, b.emphasis) << "t = " << t;
    lifted += a.brow_raise > 0;
    emphatic += a.emphasis != 0;
  }
  EXPECT_GT(lifted, 72000 / 2);
  EXPECT_GT(emphatic, 72000 / 10);
}

}  // namespace
}  // namespace kinemo::face

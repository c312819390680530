// Visemes against a forced alignment (common/face/viseme_scores.h) on a small
// track whose scores are counted by hand.
#include "common/face/viseme_scores.h"

#include <gtest/gtest.h>

#include <vector>

#include "common/face/visemes.h"

namespace kinemo::face {
namespace {

struct Row {
  PhoneClass reference;
  Category shown;
};

TEST(VisemeScores, CountedByHandOnThirteenFrames) {
  using P = PhoneClass;
  using C = Category;
  const std::vector<Row> rows = {
      {P::kSil, C::kPau},   // 0  pause, mouth at rest (OVR sil)
      {P::kAA, C::kAa},     // 1  right
      {P::kBPM, C::kBPM},   // 2  right, closed: b/p/m phone 1 (frames 2-3) gets a closure
      {P::kBPM, C::kAa},    // 3  wrong
      {P::kAA, C::kBPM},    // 4  wrong, closed elsewhere; its closure touches frame 3's b/p/m
      {P::kDT, C::kNDTL},   // 5  right
      {P::kBPM, C::kNDTL},  // 6  wrong: b/p/m phone 2 (frame 6) gets none
      {P::kSZ, C::kBPM},    // 7  wrong, closed elsewhere; touches frame 6
      {P::kSZ, C::kSZZh},   // 8  right
      {P::kAA, C::kBPM},    // 9  wrong, closed elsewhere: closure 9-10 touches no b/p/m
      {P::kAA, C::kBPM},    // 10 wrong, closed elsewhere
      {P::kAA, C::kAa},     // 11 right
      {P::kSil, C::kAa},    // 12 pause, mouth open (OVR aa)
  };
  FaceTrack track;
  track.frame_time_s = 5;  // 13 frames: 0 .. 60 s, one minute
  std::vector<int> reference;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    FaceFrame f;
    f.time_s = 5.0 * static_cast<double>(i);
    f.categories[static_cast<int>(rows[i].shown)] = 1;
    f.ovr[static_cast<int>(rows[i].shown == C::kPau ? OvrViseme::kSil : OvrViseme::kAA)] = 1;
    track.frames.push_back(f);
    reference.push_back(static_cast<int>(rows[i].reference));
  }
  const VisemeScores s = ScoreVisemes(reference, track);
  EXPECT_EQ(s.speech_frames, 11);
  EXPECT_EQ(s.pause_frames, 2);
  EXPECT_DOUBLE_EQ(s.accuracy, 5.0 / 11);  // frames 1, 2, 5, 8, 11
  EXPECT_DOUBLE_EQ(s.chance, 5.0 / 11);    // AA: frames 1, 4, 9, 10, 11
  EXPECT_EQ(s.bpm_frames, 3);
  EXPECT_DOUBLE_EQ(s.bpm_closed, 1.0 / 3);          // frame 2 of 2, 3, 6
  EXPECT_DOUBLE_EQ(s.closed_outside_bpm, 4.0 / 8);  // 4, 7, 9, 10 of the 8 others
  EXPECT_DOUBLE_EQ(s.pauses_at_rest, 0.5);
  EXPECT_EQ(s.bpm_phones, 2);
  EXPECT_DOUBLE_EQ(s.bpm_phones_closed, 0.5);
  EXPECT_EQ(s.closures, 4);  // 2, 4, 7, 9-10
  EXPECT_EQ(s.spurious_closures, 1);
  EXPECT_DOUBLE_EQ(s.spurious_closures_per_min, 1.0);

  // A reference shorter than the track scores only the frames it covers
  // (0-6: one closure 9-10 fewer, half a minute).
  const VisemeScores half = ScoreVisemes(std::span(reference).first(7), track);
  EXPECT_EQ(half.speech_frames, 6);
  EXPECT_EQ(half.closures, 2);
  EXPECT_EQ(half.spurious_closures, 0);
  EXPECT_DOUBLE_EQ(half.bpm_phones_closed, 0.5);
}

}  // namespace
}  // namespace kinemo::face

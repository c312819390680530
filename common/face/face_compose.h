// The face track on the body's clock (docs/face.md): the speech face (jaw and
// mouth-shape class posteriors every 10 ms, from the prosody service's face
// model) sampled at each motion frame, plus what the voice's analysis and the
// tone add: eye blinks, brows lifted on pitch accents, vowel emphasis (thesis
// §4.5.2) and the expression of the tone. One composer serves offline
// (everything known, then every frame composed) and live (speech, accents and
// tone changes fed as they arrive, each frame composed once the speech face
// reaches its time); it never looks at speech after the frame it composes.
//
// Blinks (figures and sources in docs/face.md): a random process (fixed seed,
// so a recording gets the same blinks offline and live) at 20 blinks/min
// during speech and 40/min in pauses, and at each pause onset (the silence
// class dominant for 0.25 s) a blink with probability 0.5, at least 0.4 s
// between blinks; giving about 26/min in conversation (Bentivoglio et al.
// 1997). Each blink lasts 0.25 s: closing 75 ms, closed 25 ms, reopening
// 150 ms (the lid falls faster than it rises, VanderWerf et al. 2003).
//
// Brows: each pitch accent of strength s (thesis appendix 8.2) lifts them by
// clamp(s + face_emphasis, 0, 1): rising over the 150 ms before the accent,
// held for 100 ms, falling over 400 ms; overlapping lifts take the maximum.
//
// Emphasis (thesis §4.5.2): on frames inside an accented syllable, the
// vowel classes' share times 2 clamp(s + face_emphasis, 0, 1) - 1.
//
// Expression: the tone's (ExpressionForTone), its weight ramping at most
// 1 per 0.3 s; a change of expression first fades the old one out.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <string_view>
#include <vector>

#include "common/face/face_frame.h"
#include "common/face/visemes.h"

namespace kinemo::face {

// The face the voice implies at one 10 ms analysis frame (the prosody
// service's SpeechFaceFrame).
struct SpeechFaceFrame {
  double time_s = 0;
  float jaw_open_deg = 0;
  std::array<float, kNumPhoneClasses> classes{};  // posteriors, sum 1
};

struct FaceAccent {
  double time_s = 0;    // PAPT
  double strength = 0;  // [0, 1]
  double syllable_start_s = 0, syllable_end_s = 0;  // 0, 0 = unknown
};

// Controller tone -> expression: neutral -> neutral, happy -> happy, angry ->
// angry, energetic -> surprised, subdued -> sad; any other tone -> neutral.
Expression ExpressionForTone(std::string_view tone);

struct ComposeOptions {
  double face_emphasis = 0;  // the thesis's face slider, [-1, 1]
  std::uint64_t seed = 1;    // blinks
  double speech_blinks_per_min = 20;
  double pause_blinks_per_min = 40;
  double pause_onset_blink_probability = 0.5;
  double pause_onset_s = 0.25;
  double min_blink_gap_s = 0.4;
  double blink_close_s = 0.075, blink_hold_s = 0.025, blink_open_s = 0.15;
};

class FaceComposer {
 public:
  explicit FaceComposer(const ComposeOptions& options = {});
  // Speech-face frames, in time order (10 ms apart).
  void AddSpeech(const SpeechFaceFrame& frame);
  // A pitch accent (any order; live, as the analysis decides it).
  void AddAccent(const FaceAccent& accent);
  // The expression from `time_s` on (live: the tone reached the motion).
  void SetExpression(double time_s, Expression expression, float weight);
  // No more speech: frames after the last speech frame hold it.
  void FinishSpeech() { finished_ = true; }
  // Time the speech face reaches (-1 before the first frame).
  double speech_until_s() const { return speech_.empty() ? last_speech_s_ : speech_.back().time_s; }
  // True when the frame at `time_s` can be composed now.
  bool Ready(double time_s) const { return finished_ || speech_until_s() >= time_s - 1e-9; }
  // The face at `time_s` (times non-decreasing from call to call).
  FaceFrame Compose(double time_s);

 private:
  SpeechFaceFrame SpeechAt(double time_s);
  double NextUniform();
  void UpdateBlinks(double time_s, bool silent);
  float BrowAt(double time_s) const;
  float EmphasisAt(double time_s, const std::array<float, kNumPhoneClasses>& classes) const;

  ComposeOptions o_;
  std::deque<SpeechFaceFrame> speech_;
  double last_speech_s_ = -1;
  bool finished_ = false;
  std::vector<FaceAccent> accents_;
  // Accents before this one can touch no frame any more (Compose's times
  // only grow); they are dropped now and then, so a long recording or an
  // hour's stream scans only the accents near the frame.
  std::size_t first_accent_ = 0;
  // Each accent's earliest frame is no earlier than the previous one's (as
  // a track's accents are): the scan then stops at the first accent after
  // the frame.
  bool accents_ordered_ = true;
  struct ExpressionChange {
    double time_s;
    Expression expression;
    float weight;
  };
  std::deque<ExpressionChange> expressions_;
  Expression shown_ = Expression::kNeutral;
  float shown_weight_ = 0;
  Expression target_ = Expression::kNeutral;
  float target_weight_ = 0;
  std::uint64_t rng_;
  double last_t_ = -1;
  double blink_start_ = -1e9;  // start of the current / last blink
  double silent_since_ = -1;   // start of the current silence, -1 in speech
  bool onset_checked_ = false;
};

// The face track of a whole recording: speech frames (10 ms), accents and one
// expression, composed at frame_time_s from 0 to duration_s.
FaceTrack ComposeTrack(const std::vector<SpeechFaceFrame>& speech, const std::vector<FaceAccent>& accents,
                       Expression expression, float expression_weight, double frame_time_s, double duration_s,
                       const ComposeOptions& options = {});

}  // namespace kinemo::face

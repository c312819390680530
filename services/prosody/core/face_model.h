// The speech part of a talking face (docs/face.md): from the voice alone, at
// the analysis rate (one frame per 10 ms), the jaw opening in degrees and the
// posteriors of the 18 mouth-shape classes (common/face/visemes.h).
//
// Features (FaceFeatureStream): per 10 ms frame k, a 25 ms Hamming window
// that *ends* at t_k = k * 10 ms (causal), pre-emphasis 0.97, 512-point FFT,
// 26 mel bands (60-7600 Hz), 13 MFCCs (DCT-II of the log band energies) and
// the log energy: 14 values. They are normalised by the model's mean and
// deviation of the training speech, the mean then following the speaker
// (cepstral mean normalisation with a 3 s exponential window over frames with
// speech, starting from the training mean), so a quieter microphone or
// another room shifts the features less.
//
// Model (FaceModel): the features of frames k + offsets (past frames only for
// the live head, past and future for the offline head) are stacked into one
// vector x; the jaw is a ridge regression w·x, the classes a linear
// discriminant (Gaussian classes with one shared, shrunk covariance:
// score_c = a_c·x + b_c, softmax). The class posteriors are smoothed by an
// HMM whose states are the classes (stay probability `stay`): live, the
// forward filter (causal: frame k uses audio up to t_k only); offline,
// forward-backward. A lips-pressed (B/P/M) run is then held for at least
// min_closure_frames offline (centred on it) and live_min_closure_frames live
// (from its start). The live
// head trains on features normalised as the live stream does (running mean).
// Trained in closed form (Eigen) by TrainFaceModel.
//
// Live, the face of frame k needs audio up to t_k only: FaceStream emits it as
// soon as a chunk reaches t_k; nothing waits for later audio.
#pragma once

#include <array>
#include <complex>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/face/face_compose.h"
#include "common/face/visemes.h"
#include "common/status/status.h"
#include "services/prosody/core/fft.h"

namespace kinemo::prosody {

inline constexpr int kFaceSampleRateHz = 16000;
inline constexpr double kFaceStepS = 0.01;
inline constexpr int kFaceFeatureDims = 14;  // 13 MFCCs + log energy

// Causal MFCC frames of a stream of 16 kHz samples. Allocates nothing per
// frame once constructed.
class FaceFeatureStream {
 public:
  FaceFeatureStream();
  // Appends samples; writes the features of every frame whose window is now
  // complete (t_k <= audio received; frame 0, whose window is all before the
  // stream, comes with the first call), 14 floats per frame, to `out`.
  void Push(std::span<const float> samples, std::vector<float>* out);
  int64_t frames() const { return next_frame_; }

 private:
  RealFft fft_;
  std::vector<float> window_;   // Hamming, 400
  std::vector<float> history_;  // samples from base_ on
  int64_t base_ = 0;
  int64_t received_ = 0;
  int64_t next_frame_ = 0;
  std::vector<float> frame_;
  std::vector<std::complex<float>> spectrum_, work_;
  std::vector<float> power_;
  struct Band {
    int first_bin = 0;
    std::vector<float> weights;
  };
  std::vector<Band> bands_;
  std::vector<float> dct_;  // 13 x 26
};

// One linear head: frames k + offsets stacked (14 values each, clamped to
// the signal), then jaw = jaw_w·x + jaw_b and class scores = class_w x + class_b.
struct FaceHead {
  std::vector<int> offsets;         // frame offsets, e.g. {0, -1, -2, ...}
  std::vector<float> jaw_w;         // 14 * offsets.size()
  float jaw_b = 0;
  std::vector<float> class_w;       // 18 x (14 * offsets.size()), row-major
  std::array<float, face::kNumPhoneClasses> class_b{};
  int dims() const { return kFaceFeatureDims * static_cast<int>(offsets.size()); }
};

struct FaceModel {
  static constexpr int kFormatVersion = 1;
  std::array<float, kFaceFeatureDims> mean{}, inv_sd{};
  FaceHead live;     // past frames only
  FaceHead offline;  // past and future frames
  float stay = 0.9f;         // HMM: probability a class stays from one frame to the next
  float jaw_smooth = 0.5f;   // live jaw: one-pole smoothing factor per frame (1 = none)
  // The jaw is also read from the classes: each class's mean jaw opening in
  // the training speech, weighted by the frame's class posteriors, mixed in
  // with this weight (0 = the regression alone).
  std::array<float, face::kNumPhoneClasses> class_jaw{};
  float class_jaw_mix = 0;
  // B/P/M: a run of frames where the lips-pressed class dominates lasts at
  // least this many frames (a shorter one is held: offline centred on it,
  // live after its start), so a short closure is not lost (0 = off).
  // Offline and live apart: the live classifier closes the lips on other
  // sounds far more often, and a longer hold would show those longer.
  int min_closure_frames = 0;       // offline (AnalyzeFace)
  int live_min_closure_frames = 0;  // live (FaceStream)
  // What it was trained on (artifact summary).
  double training_s = 0;
  std::string description;
};

// The model as JSON and back (the artifact's face_model.json). Errors name
// `name` and the member.
std::string FaceModelToJson(const FaceModel& model);
StatusOr<FaceModel> FaceModelFromJson(std::string_view text, std::string_view name);

// The face of one 10 ms frame: time t_k = k * 10 ms, jaw opening in degrees
// (0 = the speaker's jaw at rest, common/face/jaw.h), class posteriors (sum 1).
using SpeechFaceFrame = face::SpeechFaceFrame;

// Live: the face of every frame as soon as a chunk completes its window.
class FaceStream {
 public:
  explicit FaceStream(std::shared_ptr<const FaceModel> model);
  // 16 kHz mono samples in; the frames they complete out (appended).
  void Push(std::span<const float> samples, std::vector<SpeechFaceFrame>* out);

 private:
  std::shared_ptr<const FaceModel> model_;
  FaceFeatureStream features_;
  std::vector<float> raw_;            // features of the newest frames (ring of `span_` frames)
  std::vector<float> ring_;           // normalised, ring of span_ frames
  int span_ = 1;                      // frames the live head looks back (1 - min offset)
  std::array<float, kFaceFeatureDims> cmn_{};
  std::vector<float> x_;
  std::array<double, face::kNumPhoneClasses> alpha_{};
  int closure_frames_ = 0;  // frames of the current B/P/M run shown so far
  std::array<float, face::kNumPhoneClasses> closure_{};  // the run's most closed frame
  bool started_ = false;
  float jaw_ = 0;
  int64_t frame_ = 0;
};

// Timed phones of a recording (the recogniser's: ARPAbet, time order).
struct FacePhone {
  double start_s = 0, end_s = 0;
  std::string phone;
};

// Offline: every frame of a whole recording (16 kHz), with the offline head
// and forward-backward smoothing; frames cover [0, duration]. With `phones`
// (the recogniser's force-aligned phones), each frame's class posteriors are
// also weighed by the phone under it: its class counts `phone_weight` times
// as likely as each other class (1 = ignore the phones).
//
// The recogniser (PocketSphinx) times a phone by its first frame's *start*
// (frame i = i * 10 ms) while that frame's 25.6 ms window is centred
// 12.8 ms later; `phone_delay_s` moves the phones by that much onto the
// sound's time (on the two BEAT2 takes the recogniser's phones match the
// forced alignment best 10-20 ms later: docs/face.md).
inline constexpr double kRecognizerPhoneDelayS = 0.0128;
std::vector<SpeechFaceFrame> AnalyzeFace(std::span<const float> samples, const FaceModel& model,
                                         std::span<const FacePhone> phones = {}, double phone_weight = 1000,
                                         double phone_delay_s = kRecognizerPhoneDelayS);
// AnalyzeFace in two steps, so that a long recording's samples can be freed
// between them: every frame's features (14 floats per 10 ms, 5.6 kB a
// second against 64 kB of samples), then the face from them (the same
// frames as AnalyzeFace).
std::vector<float> OfflineFaceFeatures(std::span<const float> samples);
std::vector<SpeechFaceFrame> AnalyzeFaceFeatures(std::vector<float> features, const FaceModel& model,
                                                 std::span<const FacePhone> phones = {}, double phone_weight = 1000,
                                                 double phone_delay_s = kRecognizerPhoneDelayS);
// The live path run over a whole recording in `chunk_s` pieces (what a
// stream would have sent), for evaluation.
std::vector<SpeechFaceFrame> AnalyzeFaceLive(std::span<const float> samples, std::shared_ptr<const FaceModel> model,
                                             double chunk_s);

// ---- Training -------------------------------------------------------------

// One recording with its captured face: 16 kHz samples, the jaw opening
// (degrees, at `jaw_frame_time_s`; empty = no jaw) and the phones (ARPAbet,
// time order; silence as "" or SIL).
struct FaceTrainingTake {
  std::string name;
  std::vector<float> samples;
  std::vector<double> jaw_open_deg;
  double jaw_frame_time_s = 1.0 / 30.0;
  struct Phone {
    double start_s = 0, end_s = 0;
    std::string phone;
  };
  std::vector<Phone> phones;
};

struct FaceTrainOptions {
  std::vector<int> live_offsets = {0, -1, -2, -3, -4, -6, -8, -10, -13, -16, -20};
  std::vector<int> offline_offsets = {-20, -15, -10, -7, -5, -3, -2, -1, 0, 1, 2, 3, 5, 7, 10, 15, 20};
  double jaw_ridge = 10;       // ridge penalty (features standardised)
  double class_shrink = 0.1;   // covariance shrinkage toward its mean variance
  double stay = 0.8;
  double jaw_smooth = 0.7;
  double class_jaw_mix = 0.3;
  // Class scores: the log class prior is kept with weight 1 - prior_power
  // (0 = the discriminant's own posteriors; 1 = scaled likelihoods, which
  // favour rare classes such as bpm), then every score is multiplied by
  // score_scale (< 1 flattens the posteriors the HMM smooths).
  double prior_power = 0;
  double score_scale = 1;
  // prior_power for the B/P/M class alone: lips that close on m, b and p are
  // the cue a viewer reads first. 0.25 (docs/face.md, BEAT2 leave-one-take-
  // out): B/P/M frames with the lips closed live 0.42 -> 0.60 and
  // 0.26 -> 0.42, with phones 0.60 -> 0.63 and 0.65 -> 0.67, for accuracy
  // -0.000 / -0.004 and pauses at rest 0.905 / 0.891 (was 0.905 / 0.900).
  double bpm_prior_power = 0.25;
  // Train the live head on features normalised as the live stream does (the
  // running mean), not on each take's own mean.
  bool live_running_cmn = true;
  // FaceModel::min_closure_frames (offline), in seconds: 0.1 s, three frames
  // at 30 fps, so that a closure shows on at least three body frames
  // (docs/face.md: B/P/M frames closed 0.63 -> 0.73 and 0.67 -> 0.72 with
  // phones, b/p/m phones that get a closure and closures on other sounds
  // unchanged, accuracy -0.012 / -0.009).
  double min_closure_s = 0.1;
  // FaceModel::live_min_closure_frames, in seconds (60 ms, the median b/p/m).
  double live_min_closure_s = 0.06;
};

// INVALID_ARGUMENT naming the take when it has no jaw frames, no phones or
// under 1 s of audio.
StatusOr<FaceModel> TrainFaceModel(std::span<const FaceTrainingTake> takes, const FaceTrainOptions& options);

}  // namespace kinemo::prosody

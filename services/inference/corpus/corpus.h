// Paired speech + motion corpora in the common layout (`<name>.wav` +
// `<name>.bvh` per recording, as Trinity/GENEA and ZEGGS ship them):
// an importer computing prosody features and kinematic parameters on a
// common time step (one step = one syllable; y_t = the parameters of the
// motion segment active at the step's midpoint), and a builder that makes
// such a corpus honestly from unpaired real speech and real motion.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/motion/skeleton.h"
#include "common/status/status.h"
#include "services/inference/core/remapped_model.h"
#include "services/inference/corpus/prosody_adapter.h"
#include "services/inference/corpus/prosody_features.h"

namespace kinemo::inference {

// Kinematic parameters of one motion segment (Gesture Controllers §5.1).
struct KinematicSegment {
  double start_s = 0.0;
  double end_s = 0.0;
  Eigen::Matrix<double, 6, 1> params;  // T, D, V, A, C, H
};

struct KinematicOptions {
  // Segment boundaries where the mean speed of the two hands crosses this,
  // in body heights per second (0.15 ≈ 0.25 m/s for a 1.7 m body).
  double speed_threshold_heights_per_s = 0.15;
  // Shorter segments are merged into their predecessor.
  double min_segment_s = 0.1;
};

// Segments a clip at hand-speed threshold crossings and computes, per segment
// of frames 1..n (dt = frame time, positions in body heights, p/v/a the two
// hands' 6-D position/velocity/acceleration, h the sum of hand heights above
// the floor):
//   T = log(n·dt / 1 s)          D = log ‖mean_i (p_i − p_1)‖
//   V = log mean_i ‖v_i‖         A = log mean_i ‖a_i‖
//   C = log mean_i ‖v_i × a_i‖   H = log mean_i h_i
// (logs of values + 1e-3). The paper's B_* are these unit choices (seconds,
// body heights); its W_* are 1 — the HMM's per-state covariances absorb the
// remaining scale. V, A, C use mean magnitudes rather than the magnitude of
// the summed vectors, which vanishes for strokes that return.
StatusOr<std::vector<KinematicSegment>> ComputeKinematicSegments(const motion::Clip& clip,
                                                                 const KinematicOptions& options = {});

// y_t for each step: the segment containing the step's midpoint (the nearest
// one outside the clip).
Eigen::MatrixXd KinematicsOnSteps(const std::vector<KinematicSegment>& segments,
                                  const std::vector<ProsodyStep>& steps);

// Reads mono samples of a WAV/FLAC/... file.
struct Speech {
  std::vector<float> samples;
  int sample_rate_hz = 0;
};
StatusOr<Speech> ReadSpeechFile(const std::string& path);

// Imports every `<name>.wav` with a `<name>.bvh` in `dir` (sorted by name).
// NOT_FOUND if the directory has no pair. The default extractor is the
// prosody service's core (ExtractProsodyWithProsodyCore); ExtractProsody is
// the minimal stand-in.
StatusOr<std::vector<PairedSequence>> ImportPairedCorpus(
    const std::string& dir, const ProsodyExtractor& extractor = ExtractProsodyWithProsodyCore);

// Builds a paired corpus from unpaired real data:
//   for each speech file and each rendition r = 0..renditions-1, a BVH the
//   length of the speech: a rest pose, and at each detected accent a real
//   gesture excerpt from the gesture clips, its stroke (fastest hand frame)
//   placed 0.03..0.22 s before the accent, its length growing with the
//   accent's strength, and its clip drawn from an energy tier chosen by the
//   strength (files named *_active_/_angry_/... are energetic, *_sad_/
//   _tired_/... subdued, others neutral; one tier when only one exists).
//   Excerpts blend in and out of the rest pose over 0.2 s.
// Writes `<speech stem>_r<r>.wav` (a copy) and `.bvh` plus README.txt saying
// how it was made. Deterministic for a given seed.
struct SyntheticCorpusOptions {
  std::vector<std::string> speech_files;
  std::vector<std::string> gesture_files;  // BVH clips sharing one skeleton
  std::string out_dir;
  int renditions = 1;
  std::uint64_t seed = 1;
  ProsodyExtractor extractor = ExtractProsodyWithProsodyCore;  // accents come from here
};
struct SyntheticCorpusReport {
  int recordings = 0;
  int gestures_placed = 0;
  double speech_s = 0.0;
};
StatusOr<SyntheticCorpusReport> BuildSyntheticCorpus(const SyntheticCorpusOptions& options);

}  // namespace kinemo::inference

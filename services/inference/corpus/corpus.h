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

#include "common/audio/textgrid.h"
#include "common/gesture/kinematics.h"
#include "common/motion/skeleton.h"
#include "common/status/status.h"
#include "services/inference/core/remapped_model.h"
#include "services/inference/corpus/prosody_adapter.h"
#include "services/inference/corpus/prosody_features.h"

namespace kinemo::inference {

// y_t for each step (kinematic parameters: common/gesture/kinematics.h): the segment containing the step's midpoint (the nearest
// one outside the clip).
Eigen::MatrixXd KinematicsOnSteps(const std::vector<gesture::KinematicSegment>& segments,
                                  const std::vector<ProsodyStep>& steps);

// Reads mono samples of a WAV/FLAC/... file.
struct Speech {
  std::vector<float> samples;
  int sample_rate_hz = 0;
};
StatusOr<Speech> ReadSpeechFile(const std::string& path);

// One recording of a paired corpus: the sequence the model trains on, and,
// when a `<name>.TextGrid` lies beside it (BEAT2, Montreal Forced Aligner),
// its word and phone alignments without the silences — a real reference for
// the keyword spotter and the phone recognizer.
struct PairedRecording {
  PairedSequence sequence;
  std::string wav_path, bvh_path, textgrid_path;  // textgrid_path "" when absent
  double speech_s = 0;                            // length of the recording
  double motion_s = 0;                            // length of the capture
  std::vector<audio::TextGridInterval> words;     // tier "words" (or "word")
  std::vector<audio::TextGridInterval> phones;    // tier "phones" (or "phone")
};

// Imports every `<name>.wav` with a `<name>.bvh` in `dir` (sorted by name).
// NOT_FOUND if the directory has no pair. The default extractor is the
// prosody service's core (ExtractProsodyWithProsodyCore); ExtractProsody is
// the minimal stand-in. Steps past the end of the capture are dropped (a
// BEAT2 capture may end before its audio).
StatusOr<std::vector<PairedRecording>> ImportPairedRecordings(
    const std::string& dir, const ProsodyExtractor& extractor = ExtractProsodyWithProsodyCore);
// The sequences of ImportPairedRecordings.
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

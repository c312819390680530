// The whole analysis of a recording as the CLI and the service run it:
// resample to the analysis rate, prosody, and (optionally) the recognizer;
// plus the output formats (JSON, CSV, Praat TextGrid).
#pragma once

#include <span>
#include <string>
#include <vector>

#include "common/status/cancel.h"
#include "common/status/status.h"
#include "services/prosody/core/options.h"
#include "services/prosody/core/types.h"

namespace kinemo::prosody {

class SphinxRecognizer;
struct RecognizedWord;
struct RecognizedPhone;

// True when the build includes the Sphinx recognizer.
bool RecognizerBuiltIn();

struct Word {
  std::string word;
  double start_s = 0;
  double end_s = 0;
  double confidence = 0;
  bool keyword = false;
};

struct Phone {
  std::string phone;
  double start_s = 0;
  double end_s = 0;
};

struct PipelineRequest {
  AnalysisOptions options;
  // Rate the audio is resampled to before analysis; 0 = keep the input rate.
  int analysis_rate_hz = 16000;
  // Words and timed phones.
  bool recognize = false;
  // Keywords to spot (then `words` holds only them).
  std::vector<std::string> keywords;
  double keyword_threshold = 0;  // 0 = the recognizer's default
  // Checked before each stage (resampling, analysis, recognition; null =
  // never stops): DEADLINE_EXCEEDED or CANCELLED ("analysis: ...") once
  // stopped, e.g. when the caller's deadline passed while the request
  // waited for a worker or for the recognizer.
  const CancelToken* cancel = nullptr;
};

struct PipelineResult {
  ProsodyResult prosody;
  std::vector<Word> words;
  std::vector<Phone> phones;
  bool recognizer_ran = false;
  // CPU seconds the recognizer took (words, keywords and phones).
  double recognizer_compute_s = 0;
};

// `recognizer` may be null when neither recognition nor keywords are asked
// for; otherwise FAILED_PRECONDITION.
StatusOr<PipelineResult> RunPipeline(std::span<const float> mono, int sample_rate_hz,
                                     const PipelineRequest& request,
                                     SphinxRecognizer* recognizer);

// Output formats. JSON: one object with frames, syllables, accents, pauses,
// words, phones and, when the recognizer ran, recognizer_rtf (its CPU seconds
// per second of audio) (the CLI's verification interface); the frames are
// formatted on `threads` threads (0 = one per core).
std::string ToJson(const PipelineResult& result, int threads = 0);
// CSV: one row per frame (time_s,f0_hz,voiced,voicing_probability,intensity_db,
// syllable,accent_strength).
std::string ToCsv(const PipelineResult& result);
// Praat TextGrid (long text format): interval tiers syllables, pauses,
// words, phones and a point tier accents.
std::string ToTextGrid(const PipelineResult& result);

}  // namespace kinemo::prosody

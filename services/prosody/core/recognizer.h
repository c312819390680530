// Speech recognition with CMU PocketSphinx (Debian's 5prealpha): words
// (N-gram language model), keyword spotting, and timed phones (-allphone).
// Built only with KINEMO_WITH_SPHINX. Input: mono float samples in [-1, 1]
// at 16 kHz (the en-us acoustic model's rate); callers resample.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "common/status/status.h"

struct ps_decoder_s;

namespace kinemo::prosody {

struct RecognizerConfig {
  // Acoustic model directory (-hmm). Empty = the Debian package's.
  std::string model_dir;
  // Empty = cmudict-en-us.dict / en-us.lm.bin / en-us-phone.lm.bin beside
  // model_dir.
  std::string dictionary_file;
  std::string language_model_file;
  std::string phone_model_file;
  // Default keyword-spotting threshold (-kws_threshold).
  double keyword_threshold = 1e-10;  // bench/tools/keyword_eval.py
};

// Fills the empty paths of `config` with the Debian defaults.
RecognizerConfig WithDefaultPaths(RecognizerConfig config);

struct RecognizedWord {
  std::string word;  // lower case, without the dictionary's "(2)" variant mark
  double start_s = 0;
  double end_s = 0;
  double confidence = 0;  // posterior in [0, 1] when the decoder gives one, else 0
  bool keyword = false;
};

struct RecognizedPhone {
  std::string phone;  // ARPAbet, upper case; "SIL" for silence and noise
  double start_s = 0;
  double end_s = 0;
};

// Live keyword spotting: audio in pieces of any size, each keyword reported
// once, as soon as the spotter fires (typically 0.1-0.3 s after the word
// ends). One decoder per stream; not thread-safe (one stream, one caller).
class KeywordStream {
 public:
  ~KeywordStream();
  KeywordStream(const KeywordStream&) = delete;
  KeywordStream& operator=(const KeywordStream&) = delete;

  // Feeds 16 kHz mono samples; appends new detections to `out`, with times
  // from the start of the stream.
  Status Process(std::span<const float> samples, std::vector<RecognizedWord>* out);
  // Ends the stream: detections in the last piece of audio.
  Status Finish(std::vector<RecognizedWord>* out);
  // Seconds of audio processed.
  double processed_s() const { return static_cast<double>(samples_) / 16000.0; }

 private:
  friend class SphinxRecognizer;
  explicit KeywordStream(ps_decoder_s* ps) : ps_(ps) {}
  void Collect(const char* hyp, std::vector<RecognizedWord>* out);
  ps_decoder_s* ps_;
  bool in_utterance_ = true;
  std::int64_t samples_ = 0;           // processed so far
  std::vector<std::int16_t> pcm_;      // conversion buffer, reused
};

// Thread-safe; calls are serialised (one decoder per mode).
class SphinxRecognizer {
 public:
  static constexpr int kSampleRateHz = 16000;
  // FAILED_PRECONDITION naming the path when a model file is missing.
  static StatusOr<std::unique_ptr<SphinxRecognizer>> Create(const RecognizerConfig& config);
  ~SphinxRecognizer();
  SphinxRecognizer(const SphinxRecognizer&) = delete;
  SphinxRecognizer& operator=(const SphinxRecognizer&) = delete;

  StatusOr<std::vector<RecognizedWord>> Words(std::span<const float> samples);
  // Spots `keywords` (lower case, in the dictionary; INVALID_ARGUMENT names
  // the first unknown one). threshold 0 = the configured default.
  StatusOr<std::vector<RecognizedWord>> Keywords(std::span<const float> samples,
                                                 const std::vector<std::string>& keywords,
                                                 double threshold);
  StatusOr<std::vector<RecognizedPhone>> Phones(std::span<const float> samples);
  // OK if every keyword is in the dictionary.
  Status CheckKeywords(const std::vector<std::string>& keywords);
  // A live spotter for `keywords` (checked as in Keywords()); loading the
  // acoustic model and dictionary takes about 0.2-0.5 s.
  StatusOr<std::unique_ptr<KeywordStream>> OpenKeywordStream(const std::vector<std::string>& keywords,
                                                             double threshold);

 private:
  explicit SphinxRecognizer(const RecognizerConfig& config) : config_(config) {}
  Status EnsureWordDecoder();
  Status EnsurePhoneDecoder();
  std::mutex mu_;
  RecognizerConfig config_;
  ps_decoder_s* words_ = nullptr;
  std::string lm_search_;  // name of the language-model search
  ps_decoder_s* phones_ = nullptr;
};

}  // namespace kinemo::prosody

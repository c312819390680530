// Speech recognition with CMU PocketSphinx (Debian's 5prealpha): words
// (N-gram language model), keyword spotting, timed phones (the phone loop,
// -allphone, offline and live) and forced alignment of a known transcript.
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

// How timed phones are found (speed against accuracy; measured against a
// forced alignment of the transcript with bench/tools/phone_eval.cc, see
// docs/prosody_phones.md):
//  - kAlignedWords (default): the word search (WordSearchConfig), then a
//    forced alignment of the words it found (AlignPhones): the phones of real
//    words in the order the language model finds likely, timed by Viterbi;
//  - kPhoneGrammar: a grammar whose words are the phones, each allowed after
//    the others with the phone language model's trigram probability
//    (phone_model_file), searched by Sphinx's grammar (FSG) search, which only
//    visits hypotheses inside the beams; a phone's right context is taken as
//    silence (Sphinx models one-phone words so). Live streams use it;
//  - kPhoneLoop: -allphone, the phone loop with the phone trigram (the method
//    used before): every triphone of the model in every frame, 7x slower.
enum class PhoneMethod { kAlignedWords, kPhoneGrammar, kPhoneLoop };

struct PhoneSearchConfig {
  PhoneMethod method = PhoneMethod::kAlignedWords;
  // Phone grammar and phone loop:
  int grammar_order = 3;           // phone grammar: 2 = bigram, 3 = trigram
  double beam = 1e-20;             // -beam: HMM state pruning (smaller = wider)
  double phone_beam = 1e-20;       // -pbeam: phone transitions
  double word_beam = 1e-15;        // -wbeam: phone exits (phone grammar only)
  double language_weight = 2.0;    // -lw: weight of the phone language model
  int frame_downsampling = 1;      // -ds: Gaussians scored every n-th frame
  int top_gaussians = 4;           // -topn: Gaussians per mixture scored
  bool context_independent = false;  // -allphone_ci (phone loop only)
};

// The phone search used before (the phone loop), for comparison.
PhoneSearchConfig LegacyPhoneSearch();

// The word search (n-gram language model). The defaults keep the first,
// lexicon-tree pass only, with a cap on the hypotheses per frame (6x faster
// than Sphinx's defaults; bench/tools/phone_eval.cc reports word accuracy).
struct WordSearchConfig {
  bool second_passes = false;   // -fwdflat and -bestpath
  int max_hmms_per_frame = 2000;  // -maxhmmpf (-1 = no cap)
  int max_words_per_frame = 10;   // -maxwpf (-1 = no cap)
  int top_gaussians = 2;          // -topn
};

// Sphinx's defaults, used before.
WordSearchConfig LegacyWordSearch();

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
  PhoneSearchConfig phone_search;
  WordSearchConfig word_search;
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

class DecoderPool;

// Live timed phones from the phone loop: audio in pieces of any size; each
// phone reported once, when the best path has kept it for `lag_s` of audio
// after its end (the path seldom changes that far back), with times from the
// start of the stream. Long streams are cut into utterances at silences, so
// that memory stays bounded. One stream, one caller (not thread-safe).
class PhoneStream {
 public:
  ~PhoneStream();
  PhoneStream(const PhoneStream&) = delete;
  PhoneStream& operator=(const PhoneStream&) = delete;

  // Feeds 16 kHz mono samples; appends the phones that became final.
  Status Process(std::span<const float> samples, std::vector<RecognizedPhone>* out);
  // Ends the stream: every phone not reported yet.
  Status Finish(std::vector<RecognizedPhone>* out);
  double processed_s() const { return static_cast<double>(samples_) / 16000.0; }
  // Most audio after a phone's end before it is reported (plus one chunk):
  // the lag, the path being looked at every 5 frames, and the 4 frames of
  // context Sphinx's features (deltas) need.
  double latency_s() const { return (lag_frames_ + 5 + 4) * 0.01; }

 private:
  friend class SphinxRecognizer;
  PhoneStream(std::shared_ptr<DecoderPool> pool, ps_decoder_s* ps, int lag_frames);
  // Reports the best path's phones that end before `until_frame` (of the
  // utterance) and after the last one reported; returns the length of the
  // silence the path ends in, in frames (0 if it ends in a phone).
  int Emit(int until_frame, std::vector<RecognizedPhone>* out);
  std::shared_ptr<DecoderPool> pool_;
  ps_decoder_s* ps_;
  int lag_frames_;
  bool in_utterance_ = false;
  bool finished_ = false;
  std::int64_t samples_ = 0;            // fed so far
  double utterance_start_s_ = 0;        // audio time the utterance starts at
  int emitted_frames_ = 0;              // utterance frames reported so far
  int checked_frames_ = 0;              // utterance frames at the last look at the path
  double last_end_s_ = 0;               // end of the last phone reported
  std::vector<std::int16_t> pcm_;       // conversion buffer, reused
};

// Thread-safe. Words and keywords share one decoder (calls serialised);
// phone decoders come from a pool, so phone calls and streams run at once.
class SphinxRecognizer {
 public:
  static constexpr int kSampleRateHz = 16000;
  // FAILED_PRECONDITION naming the path when a model file is missing.
  static StatusOr<std::unique_ptr<SphinxRecognizer>> Create(const RecognizerConfig& config);
  ~SphinxRecognizer();
  SphinxRecognizer(const SphinxRecognizer&) = delete;
  SphinxRecognizer& operator=(const SphinxRecognizer&) = delete;

  // Loads the models the word search and the alignment need (done by the
  // first call otherwise; about 0.3-0.6 s), e.g. to time recognition alone.
  Status LoadModels();
  StatusOr<std::vector<RecognizedWord>> Words(std::span<const float> samples);
  // Words and timed phones of one recording (with kAlignedWords, the phones
  // of the words found, so the word search runs once).
  struct WordsAndPhones {
    std::vector<RecognizedWord> words;
    std::vector<RecognizedPhone> phones;
  };
  StatusOr<WordsAndPhones> Recognize(std::span<const float> samples);
  // Spots `keywords` (lower case, in the dictionary; INVALID_ARGUMENT names
  // the first unknown one). threshold 0 = the configured default.
  StatusOr<std::vector<RecognizedWord>> Keywords(std::span<const float> samples,
                                                 const std::vector<std::string>& keywords,
                                                 double threshold);
  // Timed phones (PhoneSearchConfig.method; consecutive silences merged).
  StatusOr<std::vector<RecognizedPhone>> Phones(std::span<const float> samples);
  // Forced alignment of `words` (the transcript, lower case, each in the
  // dictionary; INVALID_ARGUMENT "words[i]: ..." otherwise): the phones of
  // their pronunciations (any variant) in order, silence allowed between
  // them. FAILED_PRECONDITION when the audio cannot be aligned with them.
  StatusOr<std::vector<RecognizedPhone>> AlignPhones(std::span<const float> samples,
                                                     const std::vector<std::string>& words);
  // A live phone stream (the phone grammar, or the phone loop when that is
  // the method) whose phones are final `lag_s` after their end (0 < lag_s
  // <= 2). The first stream loads the models (about 0.2-0.5 s); later ones
  // reuse idle decoders.
  StatusOr<std::unique_ptr<PhoneStream>> OpenPhoneStream(double lag_s);
  // OK if every keyword is in the dictionary.
  Status CheckKeywords(const std::vector<std::string>& keywords);
  // A live spotter for `keywords` (checked as in Keywords()); loading the
  // acoustic model and dictionary takes about 0.2-0.5 s.
  StatusOr<std::unique_ptr<KeywordStream>> OpenKeywordStream(const std::vector<std::string>& keywords,
                                                             double threshold);

 private:
  explicit SphinxRecognizer(const RecognizerConfig& config);
  Status EnsureWordDecoder();
  // Words() and AlignPhones() with mu_ held.
  StatusOr<std::vector<RecognizedWord>> WordsLocked(std::span<const float> samples);
  StatusOr<std::vector<RecognizedPhone>> AlignLocked(std::span<const float> samples,
                                                     const std::vector<std::string>& words);
  // Phones of the phone grammar or loop (a pooled decoder).
  StatusOr<std::vector<RecognizedPhone>> SearchPhones(std::span<const float> samples);
  Status EnsureAlignDecoder();
  std::mutex mu_;
  RecognizerConfig config_;
  ps_decoder_s* words_ = nullptr;
  std::string lm_search_;  // name of the language-model search
  ps_decoder_s* align_ = nullptr;  // phones as words, for forced alignment
  // Their cepstral means when new (each recording starts from it).
  std::vector<float> words_cmn_, align_cmn_;
  // Phone decoders for whole recordings and for live streams (kept apart:
  // a decoder that ran live normalises every later recording live too).
  std::shared_ptr<DecoderPool> phone_decoders_;
  std::shared_ptr<DecoderPool> live_phone_decoders_;
};

}  // namespace kinemo::prosody

// SphinxRecognizer and its live streams (recognizer.h): words, keywords,
// timed phones (phone grammar, phone loop, or the forced alignment of the
// words found) and forced alignment of a transcript for whole recordings;
// live keyword spotting and live timed phones. How PocketSphinx is driven
// (decoding, reading segments, the phone decoders' pool) is in
// sphinx_decoder.cc.
#include "services/prosody/core/recognizer.h"

#include <pocketsphinx.h>
#include <err.h>
#include <ckd_alloc.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <sstream>

#include "services/prosody/core/sphinx_decoder.h"

namespace kinemo::prosody {
namespace {

Status CheckFile(const std::string& field, const std::string& path) {
  if (!std::filesystem::exists(path)) {
    return absl::FailedPreconditionError(
        kinemo::StrCat("recognizer.", field, ": ", path, " does not exist"));
  }
  return absl::OkStatus();
}

}  // namespace

RecognizerConfig WithDefaultPaths(RecognizerConfig c) {
  if (c.model_dir.empty()) c.model_dir = "/usr/share/pocketsphinx/model/en-us/en-us";
  const std::string parent = std::filesystem::path(c.model_dir).parent_path().string();
  if (c.dictionary_file.empty()) c.dictionary_file = parent + "/cmudict-en-us.dict";
  if (c.language_model_file.empty()) c.language_model_file = parent + "/en-us.lm.bin";
  if (c.phone_model_file.empty()) c.phone_model_file = parent + "/en-us-phone.lm.bin";
  if (!(c.keyword_threshold > 0)) c.keyword_threshold = 1e-10;
  return c;
}

WordSearchConfig LegacyWordSearch() {
  WordSearchConfig c;
  c.second_passes = true;
  c.max_hmms_per_frame = 30000;
  c.max_words_per_frame = -1;
  c.top_gaussians = 4;
  return c;
}

PhoneSearchConfig LegacyPhoneSearch() {
  PhoneSearchConfig c;
  c.method = PhoneMethod::kPhoneLoop;
  c.beam = 1e-15;
  c.phone_beam = 1e-15;
  c.language_weight = 2.0;
  c.frame_downsampling = 1;
  c.top_gaussians = 4;
  c.context_independent = false;
  return c;
}

StatusOr<std::unique_ptr<SphinxRecognizer>> SphinxRecognizer::Create(
    const RecognizerConfig& config) {
  const RecognizerConfig c = WithDefaultPaths(config);
  KINEMO_RETURN_IF_ERROR(CheckFile("model_dir", c.model_dir + "/mdef"));
  KINEMO_RETURN_IF_ERROR(CheckFile("dictionary_file", c.dictionary_file));
  KINEMO_RETURN_IF_ERROR(CheckFile("language_model_file", c.language_model_file));
  KINEMO_RETURN_IF_ERROR(CheckFile("phone_model_file", c.phone_model_file));
  // Sphinx logs to stderr by default; keep our logs clean.
  err_set_logfp(nullptr);
  return std::unique_ptr<SphinxRecognizer>(new SphinxRecognizer(c));
}

SphinxRecognizer::SphinxRecognizer(const RecognizerConfig& config)
    : config_(config),
      phone_decoders_(std::make_shared<DecoderPool>(config)),
      live_phone_decoders_(std::make_shared<DecoderPool>(config)) {}

SphinxRecognizer::~SphinxRecognizer() {
  if (words_) ps_free(words_);
  if (align_) ps_free(align_);
}

Status SphinxRecognizer::EnsureWordDecoder() {
  if (words_) return absl::OkStatus();
  const WordSearchConfig& w = config_.word_search;
  const char* passes = w.second_passes ? "yes" : "no";
  const std::string maxhmmpf = std::to_string(w.max_hmms_per_frame),
                    maxwpf = std::to_string(w.max_words_per_frame),
                    topn = std::to_string(w.top_gaussians);
  cmd_ln_t* cfg = cmd_ln_init(nullptr, ps_args(), TRUE, "-hmm", config_.model_dir.c_str(), "-dict",
                              config_.dictionary_file.c_str(), "-lm",
                              config_.language_model_file.c_str(), "-fwdflat", passes, "-bestpath",
                              passes, "-maxhmmpf", maxhmmpf.c_str(), "-maxwpf", maxwpf.c_str(),
                              "-topn", topn.c_str(), "-logfn", "/dev/null", nullptr);
  if (!cfg) return absl::InternalError("recognizer: bad Sphinx configuration");
  words_ = ps_init(cfg);
  cmd_ln_free_r(cfg);
  if (!words_) return absl::InternalError("recognizer: could not load the Sphinx word models");
  words_cmn_ = sphinx::CepstralMean(words_);
  const char* search = ps_get_search(words_);
  lm_search_ = search ? search : "_default";
  return absl::OkStatus();
}

Status SphinxRecognizer::EnsureAlignDecoder() {
  if (align_) return absl::OkStatus();
  // A dictionary whose words are the phones: a grammar of the transcript's
  // phones then aligns each phone as a word (with cross-word triphones).
  KINEMO_ASSIGN_OR_RETURN(sphinx::TempTextFile file,
                          sphinx::WritePhoneDictionary(/*with_silence=*/false));
  cmd_ln_t* cfg = cmd_ln_init(nullptr, ps_args(), TRUE, "-hmm", config_.model_dir.c_str(), "-dict",
                              file.path, "-backtrace", "yes", "-logfn", "/dev/null", nullptr);
  if (!cfg) return absl::InternalError("recognizer: bad Sphinx alignment configuration");
  align_ = ps_init(cfg);
  cmd_ln_free_r(cfg);
  if (!align_) return absl::InternalError("recognizer: could not load the Sphinx alignment models");
  align_cmn_ = sphinx::CepstralMean(align_);
  return absl::OkStatus();
}

Status SphinxRecognizer::CheckKeywords(const std::vector<std::string>& keywords) {
  std::lock_guard<std::mutex> lock(mu_);
  KINEMO_RETURN_IF_ERROR(EnsureWordDecoder());
  for (std::size_t i = 0; i < keywords.size(); ++i) {
    const std::string& k = keywords[i];
    if (k.empty() || k.find_first_of("\n/") != std::string::npos) {
      return InvalidField(kinemo::StrCat("keywords[", i, "]"), "'", k, "' is not a word");
    }
    // Every word of a key phrase must be in the dictionary.
    std::size_t pos = 0;
    while (pos < k.size()) {
      std::size_t end = k.find(' ', pos);
      if (end == std::string::npos) end = k.size();
      const std::string w = k.substr(pos, end - pos);
      if (!w.empty()) {
        char* phones = ps_lookup_word(words_, w.c_str());
        if (!phones) {
          return InvalidField(kinemo::StrCat("keywords[", i, "]"), "'", w,
                              "' is not in the recognizer's dictionary");
        }
        ckd_free(phones);
      }
      pos = end + 1;
    }
  }
  return absl::OkStatus();
}

Status SphinxRecognizer::LoadModels() {
  std::lock_guard<std::mutex> lock(mu_);
  KINEMO_RETURN_IF_ERROR(EnsureWordDecoder());
  if (config_.phone_search.method == PhoneMethod::kAlignedWords) {
    KINEMO_RETURN_IF_ERROR(EnsureAlignDecoder());
  }
  return absl::OkStatus();
}

StatusOr<std::vector<RecognizedWord>> SphinxRecognizer::Words(std::span<const float> samples) {
  std::lock_guard<std::mutex> lock(mu_);
  return WordsLocked(samples);
}

StatusOr<std::vector<RecognizedWord>> SphinxRecognizer::WordsLocked(std::span<const float> samples) {
  KINEMO_RETURN_IF_ERROR(EnsureWordDecoder());
  if (ps_set_search(words_, lm_search_.c_str()) < 0) {
    return absl::InternalError("recognizer: cannot select the language-model search");
  }
  KINEMO_RETURN_IF_ERROR(sphinx::Decode(words_, samples, words_cmn_));
  std::vector<RecognizedWord> words;
  logmath_t* lmath = ps_get_logmath(words_);
  for (ps_seg_t* seg = ps_seg_iter(words_); seg; seg = ps_seg_next(seg)) {
    const char* w = ps_seg_word(seg);
    if (!w || sphinx::IsFiller(w)) continue;
    int sf = 0, ef = 0;
    ps_seg_frames(seg, &sf, &ef);
    int32 ascr = 0, lscr = 0, lback = 0;
    const int32 prob = ps_seg_prob(seg, &ascr, &lscr, &lback);
    RecognizedWord rw;
    rw.word = sphinx::CleanWord(w);
    rw.start_s = sf * sphinx::kFrameS;
    rw.end_s = (ef + 1) * sphinx::kFrameS;
    const double p = logmath_exp(lmath, prob);
    rw.confidence = (prob != 0 && p >= 0 && p <= 1) ? p : 0.0;
    words.push_back(rw);
  }
  return words;
}

StatusOr<std::vector<RecognizedWord>> SphinxRecognizer::Keywords(
    std::span<const float> samples, const std::vector<std::string>& keywords, double threshold) {
  KINEMO_RETURN_IF_ERROR(CheckKeywords(keywords));
  std::vector<RecognizedWord> found;
  if (keywords.empty()) return found;
  std::lock_guard<std::mutex> lock(mu_);
  if (!(threshold > 0)) threshold = config_.keyword_threshold;
  KINEMO_ASSIGN_OR_RETURN(sphinx::TempTextFile file, sphinx::WriteKeywordFile(keywords, threshold));
  const int set = ps_set_kws(words_, "kinemo_kws", file.path);
  if (set < 0 || ps_set_search(words_, "kinemo_kws") < 0) {
    return absl::InternalError("recognizer: cannot set up keyword spotting");
  }
  const Status decoded = sphinx::Decode(words_, samples, words_cmn_);
  if (decoded.ok()) sphinx::AppendKeywordSegments(words_, &found);
  ps_set_search(words_, lm_search_.c_str());
  if (!decoded.ok()) return decoded;
  std::sort(found.begin(), found.end(),
            [](const RecognizedWord& a, const RecognizedWord& b) { return a.start_s < b.start_s; });
  return found;
}

StatusOr<std::vector<RecognizedPhone>> SphinxRecognizer::Phones(std::span<const float> samples) {
  if (config_.phone_search.method != PhoneMethod::kAlignedWords) return SearchPhones(samples);
  KINEMO_ASSIGN_OR_RETURN(WordsAndPhones r, Recognize(samples));
  return std::move(r.phones);
}

StatusOr<SphinxRecognizer::WordsAndPhones> SphinxRecognizer::Recognize(
    std::span<const float> samples) {
  WordsAndPhones out;
  if (config_.phone_search.method != PhoneMethod::kAlignedWords) {
    KINEMO_ASSIGN_OR_RETURN(out.words, Words(samples));
    KINEMO_ASSIGN_OR_RETURN(out.phones, SearchPhones(samples));
    return out;
  }
  std::vector<std::string> spoken;
  {
    std::lock_guard<std::mutex> lock(mu_);
    KINEMO_ASSIGN_OR_RETURN(out.words, WordsLocked(samples));
    for (const RecognizedWord& w : out.words) spoken.push_back(w.word);
    if (!spoken.empty()) {
      auto aligned = AlignLocked(samples, spoken);
      if (aligned.ok()) {
        out.phones = *std::move(aligned);
        return out;
      }
      if (aligned.status().code() != absl::StatusCode::kFailedPrecondition) return aligned.status();
    }
  }
  // No words (silence, noise), or words the audio cannot be aligned with:
  // the phone grammar says what was there.
  KINEMO_ASSIGN_OR_RETURN(out.phones, SearchPhones(samples));
  return out;
}

StatusOr<std::vector<RecognizedPhone>> SphinxRecognizer::SearchPhones(
    std::span<const float> samples) {
  KINEMO_ASSIGN_OR_RETURN(ps_decoder_t * ps, phone_decoders_->Take());
  const Status decoded = sphinx::Decode(ps, samples, phone_decoders_->initial_cmn());
  std::vector<RecognizedPhone> phones;
  if (decoded.ok()) phones = sphinx::SegmentPhones(ps);
  phone_decoders_->Give(ps);
  if (!decoded.ok()) return decoded;
  return phones;
}

StatusOr<std::vector<RecognizedPhone>> SphinxRecognizer::AlignPhones(
    std::span<const float> samples, const std::vector<std::string>& words) {
  if (words.empty()) return InvalidField("words", "no words to align");
  std::lock_guard<std::mutex> lock(mu_);
  return AlignLocked(samples, words);
}

StatusOr<std::vector<RecognizedPhone>> SphinxRecognizer::AlignLocked(
    std::span<const float> samples, const std::vector<std::string>& words) {
  KINEMO_RETURN_IF_ERROR(EnsureWordDecoder());
  KINEMO_RETURN_IF_ERROR(EnsureAlignDecoder());
  // JSGF: one group of alternative pronunciations per word.
  std::string grammar = "#JSGF V1.0;\ngrammar kinemo_align;\npublic <utterance> =";
  std::size_t expected_min = 0;
  for (std::size_t i = 0; i < words.size(); ++i) {
    std::vector<std::string> variants;
    for (int v = 1; v < 10; ++v) {
      const std::string key = v == 1 ? words[i] : kinemo::StrCat(words[i], "(", v, ")");
      char* pron = ps_lookup_word(words_, key.c_str());
      if (!pron) break;
      variants.push_back(pron);
      ckd_free(pron);
    }
    if (variants.empty()) {
      return InvalidField(kinemo::StrCat("words[", i, "]"), "'", words[i],
                          "' is not in the recognizer's dictionary");
    }
    std::size_t shortest = SIZE_MAX;
    grammar += " (";
    for (std::size_t v = 0; v < variants.size(); ++v) {
      if (v > 0) grammar += " |";
      std::istringstream in(variants[v]);
      std::size_t n = 0;
      for (std::string phone; in >> phone; ++n) {
        if (std::find_if(std::begin(sphinx::kPhones), std::end(sphinx::kPhones),
                         [&](const char* p) { return phone == p; }) == std::end(sphinx::kPhones)) {
          return InvalidField(kinemo::StrCat("words[", i, "]"), "'", words[i], "' has phone '",
                              phone, "' that the acoustic model lacks");
        }
        grammar.push_back(' ');
        grammar += sphinx::Lower(phone);
      }
      shortest = std::min(shortest, n);
    }
    grammar += " )";
    expected_min += shortest;
  }
  grammar += ";\n";
  if (ps_set_jsgf_string(align_, "kinemo_align", grammar.c_str()) < 0 ||
      ps_set_search(align_, "kinemo_align") < 0) {
    return absl::InternalError("recognizer: cannot set up the alignment grammar");
  }
  KINEMO_RETURN_IF_ERROR(sphinx::Decode(align_, samples, align_cmn_));
  std::vector<RecognizedPhone> phones = sphinx::SegmentPhones(align_);
  std::size_t spoken = 0;
  for (const RecognizedPhone& p : phones) spoken += p.phone != "SIL";
  // A search that did not reach the grammar's end returns a partial path.
  if (spoken < expected_min) {
    return absl::FailedPreconditionError(kinemo::StrCat(
        "words: the audio could not be aligned with the transcript (", spoken, " of at least ",
        expected_min, " phones)"));
  }
  return phones;
}

StatusOr<std::unique_ptr<PhoneStream>> SphinxRecognizer::OpenPhoneStream(double lag_s) {
  if (!(lag_s > 0 && lag_s <= 2)) return InvalidField("lag_s", lag_s, " is outside (0, 2]");
  KINEMO_ASSIGN_OR_RETURN(ps_decoder_t * ps, live_phone_decoders_->Take());
  sphinx::SetCepstralMean(ps, live_phone_decoders_->initial_cmn());
  // Frame times restart with every utterance; the stream keeps its own clock.
  if (ps_start_stream(ps) < 0 || ps_start_utt(ps) < 0) {
    live_phone_decoders_->Give(ps);
    return absl::InternalError("recognizer: ps_start_utt failed");
  }
  auto stream = std::unique_ptr<PhoneStream>(new PhoneStream(
      live_phone_decoders_, ps, static_cast<int>(std::lround(lag_s / sphinx::kFrameS))));
  stream->in_utterance_ = true;
  return stream;
}

}  // namespace kinemo::prosody

namespace kinemo::prosody {

StatusOr<std::unique_ptr<KeywordStream>> SphinxRecognizer::OpenKeywordStream(
    const std::vector<std::string>& keywords, double threshold) {
  if (keywords.empty()) return InvalidField("keywords", "no keywords to spot");
  KINEMO_RETURN_IF_ERROR(CheckKeywords(keywords));
  if (!(threshold > 0)) threshold = config_.keyword_threshold;
  KINEMO_ASSIGN_OR_RETURN(sphinx::TempTextFile file, sphinx::WriteKeywordFile(keywords, threshold));
  cmd_ln_t* cfg = cmd_ln_init(nullptr, ps_args(), TRUE, "-hmm", config_.model_dir.c_str(), "-dict",
                              config_.dictionary_file.c_str(), "-kws", file.path, "-logfn", "/dev/null",
                              nullptr);
  if (!cfg) return absl::InternalError("recognizer: bad Sphinx keyword configuration");
  ps_decoder_t* ps = ps_init(cfg);
  cmd_ln_free_r(cfg);
  if (!ps) return absl::InternalError("recognizer: could not load the Sphinx keyword spotter");
  // Segment times are stream-wide from here on, across utterances.
  if (ps_start_stream(ps) < 0 || ps_start_utt(ps) < 0) {
    ps_free(ps);
    return absl::InternalError("recognizer: ps_start_utt failed");
  }
  return std::unique_ptr<KeywordStream>(new KeywordStream(ps));
}

KeywordStream::~KeywordStream() {
  if (in_utterance_) ps_end_utt(ps_);
  ps_free(ps_);
}

void KeywordStream::Collect(const char* hyp, std::vector<RecognizedWord>* out) {
  // Times are stream-wide frames (ps_start_stream).
  if (sphinx::AppendKeywordSegments(ps_, out) == 0) {
    // No segmentation available: the detection ends now.
    RecognizedWord rw;
    rw.word = sphinx::CleanWord(hyp);
    rw.start_s = rw.end_s = static_cast<double>(samples_) / 16000.0;
    rw.keyword = true;
    out->push_back(rw);
  }
}

Status KeywordStream::Process(std::span<const float> samples, std::vector<RecognizedWord>* out) {
  if (!in_utterance_) return absl::FailedPreconditionError("keywords: the stream has finished");
  sphinx::ToPcm16(samples, &pcm_);
  if (!pcm_.empty() && ps_process_raw(ps_, pcm_.data(), pcm_.size(), FALSE, FALSE) < 0) {
    return absl::InternalError("recognizer: ps_process_raw failed");
  }
  samples_ += static_cast<std::int64_t>(samples.size());
  int32 score = 0;
  const char* hyp = ps_get_hyp(ps_, &score);
  if (hyp == nullptr || hyp[0] == 0) return absl::OkStatus();
  Collect(hyp, out);
  // A detection ends the utterance, so that each is reported once.
  in_utterance_ = false;
  if (ps_end_utt(ps_) < 0) return absl::InternalError("recognizer: ps_end_utt failed");
  if (ps_start_utt(ps_) < 0) return absl::InternalError("recognizer: ps_start_utt failed");
  in_utterance_ = true;
  return absl::OkStatus();
}

Status KeywordStream::Finish(std::vector<RecognizedWord>* out) {
  if (!in_utterance_) return absl::OkStatus();
  in_utterance_ = false;
  if (ps_end_utt(ps_) < 0) return absl::InternalError("recognizer: ps_end_utt failed");
  int32 score = 0;
  const char* hyp = ps_get_hyp(ps_, &score);
  if (hyp != nullptr && hyp[0] != 0) Collect(hyp, out);
  return absl::OkStatus();
}

}  // namespace kinemo::prosody

namespace kinemo::prosody {
namespace {

// A long utterance is cut at the next silence (bounded search history).
constexpr double kMaxUtteranceS = 30.0;
// ... after this much silence at the end of the path.
constexpr int kCutSilenceFrames = 20;
// How often the live path is looked at, in frames (PhoneStream::latency_s).
constexpr int kCheckEveryFrames = 5;

}  // namespace

PhoneStream::PhoneStream(std::shared_ptr<DecoderPool> pool, ps_decoder_s* ps, int lag_frames)
    : pool_(std::move(pool)), ps_(ps), lag_frames_(std::max(1, lag_frames)) {}

PhoneStream::~PhoneStream() {
  if (in_utterance_) ps_end_utt(ps_);
  pool_->Give(ps_);
}

int PhoneStream::Emit(int until_frame, std::vector<RecognizedPhone>* out) {
  int tail_silence = 0;
  int first_frame = -1;  // Sphinx's number of the utterance's first frame
  for (ps_seg_t* seg = ps_seg_iter(ps_); seg; seg = ps_seg_next(seg)) {
    const char* w = ps_seg_word(seg);
    if (!w || sphinx::IsNull(w)) continue;
    int sf = 0, ef = 0;
    ps_seg_frames(seg, &sf, &ef);
    // Segments count frames from the start of the stream by Sphinx's clock
    // (which can run behind the audio after a cut): make them utterance
    // frames; the path starts with the utterance.
    if (first_frame < 0) first_frame = sf;
    sf -= first_frame;
    ef -= first_frame;
    tail_silence = sphinx::IsSilence(w) ? ef + 1 - sf : 0;
    if (ef < emitted_frames_ || ef >= until_frame || ef < sf) continue;  // reported, or not final yet
    RecognizedPhone p;
    p.phone = sphinx::IsSilence(w) ? "SIL" : sphinx::Upper(w);
    // The path may have moved a boundary already reported: start after it.
    p.start_s = utterance_start_s_ + std::max(sf, emitted_frames_) * sphinx::kFrameS;
    p.end_s = utterance_start_s_ + (ef + 1) * sphinx::kFrameS;
    // Tile: rounding, and the first phone of an utterance after a cut (made
    // in a silence; Sphinx's frames can fall short of the audio there).
    if (p.start_s < last_end_s_ + 0.03 || emitted_frames_ == 0) p.start_s = last_end_s_;
    if (!out->empty() && p.phone == "SIL" && out->back().phone == "SIL" &&
        out->back().end_s == p.start_s) {
      out->back().end_s = p.end_s;
    } else {
      out->push_back(p);
    }
    last_end_s_ = p.end_s;
    emitted_frames_ = ef + 1;
  }
  return tail_silence;
}

Status PhoneStream::Process(std::span<const float> samples, std::vector<RecognizedPhone>* out) {
  if (finished_) return absl::FailedPreconditionError("phones: the stream has finished");
  sphinx::ToPcm16(samples, &pcm_);
  if (!pcm_.empty() && ps_process_raw(ps_, pcm_.data(), pcm_.size(), FALSE, FALSE) < 0) {
    return absl::InternalError("recognizer: ps_process_raw failed");
  }
  samples_ += static_cast<std::int64_t>(samples.size());
  const int frames = ps_get_n_frames(ps_);  // of this utterance
  if (frames - checked_frames_ < kCheckEveryFrames) return absl::OkStatus();
  checked_frames_ = frames;
  const int tail_silence = Emit(frames - lag_frames_, out);
  // A long utterance ends inside a silence (no phone crosses the cut: every
  // phone of the path is final there) and the search restarts.
  if (frames * sphinx::kFrameS > kMaxUtteranceS && tail_silence >= kCutSilenceFrames) {
    if (ps_end_utt(ps_) < 0) return absl::InternalError("recognizer: ps_end_utt failed");
    in_utterance_ = false;
    Emit(std::numeric_limits<int>::max(), out);
    // The new utterance's times count from the audio received.
    utterance_start_s_ = processed_s();
    emitted_frames_ = 0;
    checked_frames_ = 0;
    if (ps_start_utt(ps_) < 0) return absl::InternalError("recognizer: ps_start_utt failed");
    in_utterance_ = true;
  }
  return absl::OkStatus();
}

Status PhoneStream::Finish(std::vector<RecognizedPhone>* out) {
  if (finished_) return absl::OkStatus();
  finished_ = true;
  if (!in_utterance_) return absl::OkStatus();
  in_utterance_ = false;
  if (ps_end_utt(ps_) < 0) return absl::InternalError("recognizer: ps_end_utt failed");
  Emit(std::numeric_limits<int>::max(), out);
  return absl::OkStatus();
}

}  // namespace kinemo::prosody

#include "services/prosody/core/recognizer.h"

#include <pocketsphinx.h>
#include <err.h>
#include <ckd_alloc.h>

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace kinemo::prosody {
namespace {

constexpr double kFrameS = 0.01;  // Sphinx's default 100 frames per second

Status CheckFile(const std::string& field, const std::string& path) {
  if (!std::filesystem::exists(path)) {
    return absl::FailedPreconditionError(
        kinemo::StrCat("recognizer.", field, ": ", path, " does not exist"));
  }
  return absl::OkStatus();
}

std::vector<int16> ToPcm16(std::span<const float> samples) {
  std::vector<int16> pcm(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const float v = std::clamp(samples[i], -1.0f, 1.0f) * 32767.0f;
    pcm[i] = static_cast<int16>(std::lrint(v));
  }
  return pcm;
}

bool IsFiller(const char* w) { return w[0] == '<' || w[0] == '[' || w[0] == '+'; }

std::string CleanWord(const char* w) {
  std::string s(w);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
  const auto paren = s.find('(');
  if (paren != std::string::npos) s.resize(paren);
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Runs one utterance through the active search of `ps`.
Status Decode(ps_decoder_t* ps, std::span<const float> samples) {
  const std::vector<int16> pcm = ToPcm16(samples);
  // Each call is a recording of its own: times restart at 0.
  if (ps_start_stream(ps) < 0) return absl::InternalError("recognizer: ps_start_stream failed");
  if (ps_start_utt(ps) < 0) return absl::InternalError("recognizer: ps_start_utt failed");
  if (ps_process_raw(ps, pcm.data(), pcm.size(), FALSE, TRUE) < 0) {
    ps_end_utt(ps);
    return absl::InternalError("recognizer: ps_process_raw failed");
  }
  if (ps_end_utt(ps) < 0) return absl::InternalError("recognizer: ps_end_utt failed");
  return absl::OkStatus();
}

// Sphinx reads key phrases from a file: "phrase /threshold/" per line. The
// file is removed when this goes out of scope.
struct KeywordFile {
  char path[32] = "/tmp/kinemo_kws_XXXXXX";
  KeywordFile() = default;
  KeywordFile(KeywordFile&& other) noexcept { std::copy(std::begin(other.path), std::end(other.path), path); other.path[0] = 0; }
  KeywordFile(const KeywordFile&) = delete;
  ~KeywordFile() {
    if (path[0] != 0) unlink(path);
  }
  static StatusOr<KeywordFile> Write(const std::vector<std::string>& keywords, double threshold) {
    KeywordFile f;
    const int fd = mkstemp(f.path);
    if (fd < 0) {
      f.path[0] = 0;
      return absl::InternalError("recognizer: cannot create the keyword list");
    }
    std::string text;
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", threshold);
    for (const std::string& k : keywords) text += k + " /" + buf + "/\n";
    const bool ok = write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
    close(fd);
    if (!ok) return absl::InternalError("recognizer: cannot write the keyword list");
    return f;
  }
};

// Appends the decoder's keyword segments (fillers skipped); returns how many.
int AppendKeywordSegments(ps_decoder_t* ps, std::vector<RecognizedWord>* out) {
  int n = 0;
  for (ps_seg_t* seg = ps_seg_iter(ps); seg; seg = ps_seg_next(seg)) {
    const char* w = ps_seg_word(seg);
    if (!w || IsFiller(w)) continue;
    int sf = 0, ef = 0;
    ps_seg_frames(seg, &sf, &ef);
    RecognizedWord rw;
    rw.word = CleanWord(w);
    rw.start_s = sf * kFrameS;
    rw.end_s = (ef + 1) * kFrameS;
    rw.keyword = true;
    out->push_back(rw);
    ++n;
  }
  return n;
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

SphinxRecognizer::~SphinxRecognizer() {
  if (words_) ps_free(words_);
  if (phones_) ps_free(phones_);
}

Status SphinxRecognizer::EnsureWordDecoder() {
  if (words_) return absl::OkStatus();
  cmd_ln_t* cfg = cmd_ln_init(nullptr, ps_args(), TRUE, "-hmm", config_.model_dir.c_str(), "-dict",
                              config_.dictionary_file.c_str(), "-lm",
                              config_.language_model_file.c_str(), "-logfn", "/dev/null", nullptr);
  if (!cfg) return absl::InternalError("recognizer: bad Sphinx configuration");
  words_ = ps_init(cfg);
  cmd_ln_free_r(cfg);
  if (!words_) return absl::InternalError("recognizer: could not load the Sphinx word models");
  const char* search = ps_get_search(words_);
  lm_search_ = search ? search : "_default";
  return absl::OkStatus();
}

Status SphinxRecognizer::EnsurePhoneDecoder() {
  if (phones_) return absl::OkStatus();
  cmd_ln_t* cfg = cmd_ln_init(nullptr, ps_args(), TRUE, "-hmm", config_.model_dir.c_str(),
                              "-allphone", config_.phone_model_file.c_str(), "-backtrace", "yes",
                              "-beam", "1e-15", "-pbeam", "1e-15", "-lw", "2.0", "-logfn",
                              "/dev/null", nullptr);
  if (!cfg) return absl::InternalError("recognizer: bad Sphinx phone configuration");
  phones_ = ps_init(cfg);
  cmd_ln_free_r(cfg);
  if (!phones_) return absl::InternalError("recognizer: could not load the Sphinx phone models");
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

StatusOr<std::vector<RecognizedWord>> SphinxRecognizer::Words(std::span<const float> samples) {
  std::lock_guard<std::mutex> lock(mu_);
  KINEMO_RETURN_IF_ERROR(EnsureWordDecoder());
  if (ps_set_search(words_, lm_search_.c_str()) < 0) {
    return absl::InternalError("recognizer: cannot select the language-model search");
  }
  KINEMO_RETURN_IF_ERROR(Decode(words_, samples));
  std::vector<RecognizedWord> words;
  logmath_t* lmath = ps_get_logmath(words_);
  for (ps_seg_t* seg = ps_seg_iter(words_); seg; seg = ps_seg_next(seg)) {
    const char* w = ps_seg_word(seg);
    if (!w || IsFiller(w)) continue;
    int sf = 0, ef = 0;
    ps_seg_frames(seg, &sf, &ef);
    int32 ascr = 0, lscr = 0, lback = 0;
    const int32 prob = ps_seg_prob(seg, &ascr, &lscr, &lback);
    RecognizedWord rw;
    rw.word = CleanWord(w);
    rw.start_s = sf * kFrameS;
    rw.end_s = (ef + 1) * kFrameS;
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
  KINEMO_ASSIGN_OR_RETURN(KeywordFile file, KeywordFile::Write(keywords, threshold));
  const int set = ps_set_kws(words_, "kinemo_kws", file.path);
  if (set < 0 || ps_set_search(words_, "kinemo_kws") < 0) {
    return absl::InternalError("recognizer: cannot set up keyword spotting");
  }
  const Status decoded = Decode(words_, samples);
  if (decoded.ok()) AppendKeywordSegments(words_, &found);
  ps_set_search(words_, lm_search_.c_str());
  if (!decoded.ok()) return decoded;
  std::sort(found.begin(), found.end(),
            [](const RecognizedWord& a, const RecognizedWord& b) { return a.start_s < b.start_s; });
  return found;
}

StatusOr<std::vector<RecognizedPhone>> SphinxRecognizer::Phones(std::span<const float> samples) {
  std::lock_guard<std::mutex> lock(mu_);
  KINEMO_RETURN_IF_ERROR(EnsurePhoneDecoder());
  KINEMO_RETURN_IF_ERROR(Decode(phones_, samples));
  std::vector<RecognizedPhone> phones;
  for (ps_seg_t* seg = ps_seg_iter(phones_); seg; seg = ps_seg_next(seg)) {
    const char* w = ps_seg_word(seg);
    if (!w) continue;
    int sf = 0, ef = 0;
    ps_seg_frames(seg, &sf, &ef);
    RecognizedPhone p;
    p.phone = IsFiller(w) ? "SIL" : std::string(w);
    for (char& ch : p.phone) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    p.start_s = sf * kFrameS;
    p.end_s = (ef + 1) * kFrameS;
    // Merge consecutive silences.
    if (!phones.empty() && p.phone == "SIL" && phones.back().phone == "SIL") {
      phones.back().end_s = p.end_s;
    } else {
      phones.push_back(p);
    }
  }
  return phones;
}

}  // namespace kinemo::prosody

namespace kinemo::prosody {

StatusOr<std::unique_ptr<KeywordStream>> SphinxRecognizer::OpenKeywordStream(
    const std::vector<std::string>& keywords, double threshold) {
  if (keywords.empty()) return InvalidField("keywords", "no keywords to spot");
  KINEMO_RETURN_IF_ERROR(CheckKeywords(keywords));
  if (!(threshold > 0)) threshold = config_.keyword_threshold;
  KINEMO_ASSIGN_OR_RETURN(KeywordFile file, KeywordFile::Write(keywords, threshold));
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
  if (AppendKeywordSegments(ps_, out) == 0) {  // no segmentation available: the detection ends now
    RecognizedWord rw;
    rw.word = CleanWord(hyp);
    rw.start_s = rw.end_s = static_cast<double>(samples_) / 16000.0;
    rw.keyword = true;
    out->push_back(rw);
  }
}

Status KeywordStream::Process(std::span<const float> samples, std::vector<RecognizedWord>* out) {
  if (!in_utterance_) return absl::FailedPreconditionError("keywords: the stream has finished");
  pcm_.resize(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    pcm_[i] = static_cast<int16>(std::lrint(std::clamp(samples[i], -1.0f, 1.0f) * 32767.0f));
  }
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

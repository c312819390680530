// The PocketSphinx wiring (sphinx_decoder.h): helpers that drive a decoder and
// read its results, and the pool of phone decoders with the phone loop and
// the phone grammar they are built with. What the recognizer does with them
// (words, keywords, phones, alignment, live streams) is in recognizer.cc.
#include "services/prosody/core/sphinx_decoder.h"

#include <cmn.h>
#include <feat.h>
#include <fsg_model.h>
#include <ngram_model.h>

#include <strings.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>

namespace kinemo::prosody {
namespace {

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

}  // namespace

namespace sphinx {

void ToPcm16(std::span<const float> samples, std::vector<int16>* pcm) {
  pcm->resize(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const float v = std::clamp(samples[i], -1.0f, 1.0f) * 32767.0f;
    (*pcm)[i] = static_cast<int16>(std::lrint(v));
  }
}

bool IsFiller(const char* w) { return w[0] == '<' || w[0] == '[' || w[0] == '+'; }

bool IsNull(const char* w) { return w[0] == '('; }

bool IsSilence(const char* w) { return IsFiller(w) || strcasecmp(w, "sil") == 0; }

std::string CleanWord(const char* w) {
  std::string s(w);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
  const auto paren = s.find('(');
  if (paren != std::string::npos) s.resize(paren);
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::vector<mfcc_t> CepstralMean(ps_decoder_t* ps) {
  cmn_t* cmn = ps_get_feat(ps)->cmn_struct;
  std::vector<mfcc_t> mean(static_cast<std::size_t>(cmn->veclen));
  cmn_live_get(cmn, mean.data());
  return mean;
}

void SetCepstralMean(ps_decoder_t* ps, const std::vector<mfcc_t>& mean) {
  if (!mean.empty()) cmn_live_set(ps_get_feat(ps)->cmn_struct, mean.data());
}

Status Decode(ps_decoder_t* ps, std::span<const float> samples, const std::vector<mfcc_t>& start) {
  std::vector<int16> pcm;
  ToPcm16(samples, &pcm);
  SetCepstralMean(ps, start);
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

StatusOr<TempTextFile> WriteKeywordFile(const std::vector<std::string>& keywords,
                                        double threshold) {
  std::string text;
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", threshold);
  for (const std::string& k : keywords) text += k + " /" + buf + "/\n";
  return TempTextFile::Write(text);
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

StatusOr<TempTextFile> WritePhoneDictionary(bool with_silence) {
  std::string dict;
  for (const char* p : kPhones) dict += Lower(p) + " " + p + "\n";
  if (with_silence) dict += "sil SIL\n";
  return TempTextFile::Write(dict);
}

std::string Upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

std::vector<RecognizedPhone> SegmentPhones(ps_decoder_t* ps) {
  std::vector<RecognizedPhone> phones;
  for (ps_seg_t* seg = ps_seg_iter(ps); seg; seg = ps_seg_next(seg)) {
    const char* w = ps_seg_word(seg);
    if (!w || IsNull(w)) continue;
    int sf = 0, ef = 0;
    ps_seg_frames(seg, &sf, &ef);
    if (ef < sf) continue;
    RecognizedPhone p;
    p.phone = IsSilence(w) ? "SIL" : Upper(w);
    p.start_s = sf * kFrameS;
    p.end_s = (ef + 1) * kFrameS;
    if (!phones.empty() && p.phone == "SIL" && phones.back().phone == "SIL") {
      phones.back().end_s = p.end_s;
    } else {
      phones.push_back(p);
    }
  }
  return phones;
}

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

}  // namespace sphinx

DecoderPool::~DecoderPool() {
  for (ps_decoder_t* ps : idle_) ps_free(ps);
}

StatusOr<ps_decoder_t*> DecoderPool::Take() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!idle_.empty()) {
      ps_decoder_t* ps = idle_.back();
      idle_.pop_back();
      return ps;
    }
  }
  KINEMO_ASSIGN_OR_RETURN(ps_decoder_t * ps, config_.phone_search.method == PhoneMethod::kPhoneLoop
                                                 ? NewLoopDecoder()
                                                 : NewGrammarDecoder());
  std::lock_guard<std::mutex> lock(mu_);
  if (initial_cmn_.empty()) initial_cmn_ = sphinx::CepstralMean(ps);
  return ps;
}

const std::vector<mfcc_t>& DecoderPool::initial_cmn() {
  std::lock_guard<std::mutex> lock(mu_);
  return initial_cmn_;  // set once, before the first decoder is handed out
}

void DecoderPool::Give(ps_decoder_t* ps) {
  std::lock_guard<std::mutex> lock(mu_);
  if (idle_.size() < kMaxIdle) {
    idle_.push_back(ps);
  } else {
    ps_free(ps);
  }
}

StatusOr<ps_decoder_t*> DecoderPool::NewLoopDecoder() const {
  const PhoneSearchConfig& p = config_.phone_search;
  const std::string beam = Num(p.beam), pbeam = Num(p.phone_beam), lw = Num(p.language_weight),
                    ds = std::to_string(p.frame_downsampling),
                    topn = std::to_string(p.top_gaussians);
  cmd_ln_t* cfg = cmd_ln_init(nullptr, ps_args(), TRUE, "-hmm", config_.model_dir.c_str(),
                              "-allphone", config_.phone_model_file.c_str(), "-allphone_ci",
                              p.context_independent ? "yes" : "no", "-backtrace", "yes", "-beam",
                              beam.c_str(), "-pbeam", pbeam.c_str(), "-lw", lw.c_str(), "-ds",
                              ds.c_str(), "-topn", topn.c_str(), "-logfn", "/dev/null", nullptr);
  if (!cfg) return absl::InternalError("recognizer: bad Sphinx phone configuration");
  ps_decoder_t* ps = ps_init(cfg);
  cmd_ln_free_r(cfg);
  if (!ps) return absl::InternalError("recognizer: could not load the Sphinx phone models");
  return ps;
}

StatusOr<ps_decoder_t*> DecoderPool::NewGrammarDecoder() const {
  const PhoneSearchConfig& p = config_.phone_search;
  KINEMO_ASSIGN_OR_RETURN(sphinx::TempTextFile dict,
                          sphinx::WritePhoneDictionary(/*with_silence=*/true));
  const std::string beam = Num(p.beam), pbeam = Num(p.phone_beam), wbeam = Num(p.word_beam),
                    ds = std::to_string(p.frame_downsampling),
                    topn = std::to_string(p.top_gaussians);
  cmd_ln_t* cfg = cmd_ln_init(nullptr, ps_args(), TRUE, "-hmm", config_.model_dir.c_str(), "-dict",
                              dict.path, "-fsgusefiller", "no", "-bestpath", "no", "-remove_silence", "no",
                              "-lw", Num(p.language_weight).c_str(), "-beam",
                              beam.c_str(), "-pbeam", pbeam.c_str(), "-wbeam", wbeam.c_str(), "-ds",
                              ds.c_str(), "-topn", topn.c_str(), "-logfn", "/dev/null", nullptr);
  if (!cfg) return absl::InternalError("recognizer: bad Sphinx phone configuration");
  ps_decoder_t* ps = ps_init(cfg);
  if (!ps) {
    cmd_ln_free_r(cfg);
    return absl::InternalError("recognizer: could not load the Sphinx phone models");
  }
  logmath_t* lmath = ps_get_logmath(ps);
  ngram_model_t* lm = ngram_model_read(cfg, config_.phone_model_file.c_str(), NGRAM_AUTO, lmath);
  cmd_ln_free_r(cfg);
  if (!lm) {
    ps_free(ps);
    return absl::FailedPreconditionError(kinemo::StrCat(
        "recognizer.phone_model_file: ", config_.phone_model_file, " is not a language model"));
  }
  ngram_model_apply_weights(lm, 1.0f, 1.0f);  // plain log probabilities (read with -lw, -wip)
  std::vector<std::string> units(std::begin(sphinx::kPhones), std::end(sphinx::kPhones));
  units.push_back("SIL");
  const int n = static_cast<int>(units.size());
  const bool trigram = p.grammar_order >= 3;
  // States: 0 = start; bigram: 1 + a after unit a; trigram: 1 + a after
  // <s> a, 1 + n + a * n + b after a b; the last state is final.
  const int states = 1 + n + (trigram ? n * n : 0) + 1;
  const int final_state = states - 1;
  fsg_model_t* fsg = fsg_model_init("kinemo_phones", lmath, static_cast<float32>(p.language_weight),
                                    states);
  fsg->start_state = 0;
  fsg->final_state = final_state;
  std::vector<int32> wid(static_cast<std::size_t>(n)), lmwid(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    wid[static_cast<std::size_t>(i)] =
        fsg_model_word_add(fsg, sphinx::Lower(units[static_cast<std::size_t>(i)]).c_str());
    lmwid[static_cast<std::size_t>(i)] = ngram_wid(lm, units[static_cast<std::size_t>(i)].c_str());
  }
  const int32 sentence_start = ngram_wid(lm, "<s>"), sentence_end = ngram_wid(lm, "</s>");
  const double lw = p.language_weight;
  // log P(w | h2 h1) (h2 < 0: bigram), weighted.
  auto logp = [&](int32 w, int32 h1, int32 h2) {
    int32 used = 0;
    const int32 score = h2 < 0 ? ngram_bg_score(lm, w, h1, &used) : ngram_tg_score(lm, w, h1, h2, &used);
    return static_cast<int32>(lw * score);
  };
  auto add_state = [&](int state, int32 h1, int32 h2, auto next_state) {
    for (int j = 0; j < n; ++j) {
      fsg_model_trans_add(fsg, state, next_state(j), logp(lmwid[static_cast<std::size_t>(j)], h1, h2),
                          wid[static_cast<std::size_t>(j)]);
    }
    if (state != 0) fsg_model_null_trans_add(fsg, state, final_state, logp(sentence_end, h1, h2));
  };
  if (!trigram) {
    for (int a = -1; a < n; ++a) {
      add_state(1 + a, a < 0 ? sentence_start : lmwid[static_cast<std::size_t>(a)], -1,
                [&](int j) { return 1 + j; });
    }
  } else {
    add_state(0, sentence_start, -1, [&](int j) { return 1 + j; });
    for (int a = -1; a < n; ++a) {
      const int32 ha = a < 0 ? sentence_start : lmwid[static_cast<std::size_t>(a)];
      for (int b = 0; b < n; ++b) {
        const int state = a < 0 ? 1 + b : 1 + n + a * n + b;
        add_state(state, lmwid[static_cast<std::size_t>(b)], ha,
                  [&](int j) { return 1 + n + b * n + j; });
      }
    }
  }
  ngram_model_free(lm);
  glist_free(fsg_model_null_trans_closure(fsg, nullptr));
  const bool set = ps_set_fsg(ps, "kinemo_phones", fsg) >= 0 &&
                   ps_set_search(ps, "kinemo_phones") >= 0;
  fsg_model_free(fsg);  // the search holds its own reference
  if (!set) {
    ps_free(ps);
    return absl::InternalError("recognizer: cannot set up the phone grammar");
  }
  return ps;
}

}  // namespace kinemo::prosody

// How good and how fast are the timed phones? On real speech with a
// transcript (the LibriVox clips: tests/data/speech/transcription, or
// ../shared/data/speech/librivox when present) each setting's phones are
// compared with a forced alignment of the transcript (SphinxRecognizer::
// AlignPhones, the reference):
//   - boundary error: for every boundary of the reference, the distance to the
//     nearest phone boundary of the setting; median and 90th percentile, ms;
//   - matched: share of the reference's phones (silence excluded) whose
//     midpoint falls in a phone of the setting with the same label;
//   - seq_matched: share of the reference's phones matched by the minimum
//     edit-distance alignment of the two phone sequences (silence excluded);
//   - frames: share of 10 ms frames with the same label;
//   - word_acc: 1 - word error rate of the recognised words;
//   - rtf: this thread's CPU seconds per second of audio (one core; models
//     loaded beforehand) of what `--recognize` runs (words and phones), of
//     the phones alone, and of the live phone stream (20 ms chunks, whose
//     phones are scored too: live_matched, live_bound_p50).
//
//   phone_eval [--data DIR] [--audio FILE]... [--json] [--dump]
//              [--setting NAME:METHOD:BEAM:PBEAM:WBEAM:LW:DS:TOPN:CI]...
//
// METHOD is words | grammar | grammar2 | loop (PhoneMethod). --audio adds
// recordings without a transcript to the speed measurement (e.g. the 69 s
// ZEGGS monologue). Rows: the previous setting ("legacy": phone loop, Sphinx's
// default word search), the current default, and variations; or only the
// settings given. --dump prints each clip's phones on stderr.
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "services/prosody/core/recognizer.h"

namespace {

namespace pr = kinemo::prosody;

double ThreadCpuS() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) * 1e-9;
}

struct Clip {
  std::string name;
  std::vector<float> samples;  // 16 kHz
  double seconds = 0;
  std::vector<std::string> words;          // empty: speed only
  std::vector<pr::RecognizedPhone> truth;  // forced alignment
};

struct Setting {
  std::string name;
  pr::PhoneSearchConfig phones;
  pr::WordSearchConfig words;
};

std::string MethodName(const pr::PhoneSearchConfig& c) {
  switch (c.method) {
    case pr::PhoneMethod::kAlignedWords:
      return "words";
    case pr::PhoneMethod::kPhoneGrammar:
      return c.grammar_order == 2 ? "grammar2" : "grammar";
    case pr::PhoneMethod::kPhoneLoop:
      return "loop";
  }
  return "?";
}

// Label at time t (SIL outside every phone).
const std::string& LabelAt(const std::vector<pr::RecognizedPhone>& phones, double t) {
  static const std::string kSil = "SIL";
  auto it = std::upper_bound(phones.begin(), phones.end(), t,
                             [](double x, const pr::RecognizedPhone& p) { return x < p.end_s; });
  if (it == phones.end() || t < it->start_s) return kSil;
  return it->phone;
}

// Matches of the minimum edit-distance alignment of a and b.
template <typename T>
int AlignedMatches(const std::vector<T>& a, const std::vector<T>& b) {
  const std::size_t n = a.size(), m = b.size();
  // cost, then -matches, to prefer matches among equal-cost alignments.
  std::vector<std::pair<int, int>> d((n + 1) * (m + 1));
  auto at = [&](std::size_t i, std::size_t j) -> std::pair<int, int>& { return d[i * (m + 1) + j]; };
  for (std::size_t i = 0; i <= n; ++i) at(i, 0) = {static_cast<int>(i), 0};
  for (std::size_t j = 0; j <= m; ++j) at(0, j) = {static_cast<int>(j), 0};
  for (std::size_t i = 1; i <= n; ++i) {
    for (std::size_t j = 1; j <= m; ++j) {
      const bool same = a[i - 1] == b[j - 1];
      std::pair<int, int> best = {at(i - 1, j - 1).first + (same ? 0 : 1), at(i - 1, j - 1).second - same};
      best = std::min(best, {at(i - 1, j).first + 1, at(i - 1, j).second});
      best = std::min(best, {at(i, j - 1).first + 1, at(i, j - 1).second});
      at(i, j) = best;
    }
  }
  return -at(n, m).second;
}

std::vector<std::string> Labels(const std::vector<pr::RecognizedPhone>& phones) {
  std::vector<std::string> out;
  for (const auto& p : phones) {
    if (p.phone != "SIL") out.push_back(p.phone);
  }
  return out;
}

struct Scores {
  std::vector<double> boundary_errors_s;
  int phones = 0, matched = 0, seq_matched = 0;
  int frames = 0, frames_agreeing = 0;
  void Add(const std::vector<pr::RecognizedPhone>& truth, const std::vector<pr::RecognizedPhone>& hyp,
           double seconds) {
    std::vector<double> hb;
    for (std::size_t i = 1; i < hyp.size(); ++i) hb.push_back(hyp[i].start_s);
    for (std::size_t i = 1; i < truth.size(); ++i) {
      const double t = truth[i].start_s;
      double best = seconds;
      auto it = std::lower_bound(hb.begin(), hb.end(), t);
      if (it != hb.end()) best = std::min(best, *it - t);
      if (it != hb.begin()) best = std::min(best, t - *(it - 1));
      boundary_errors_s.push_back(best);
    }
    for (const auto& p : truth) {
      if (p.phone == "SIL") continue;
      ++phones;
      matched += LabelAt(hyp, 0.5 * (p.start_s + p.end_s)) == p.phone;
    }
    seq_matched += AlignedMatches(Labels(truth), Labels(hyp));
    for (double t = 0.005; t < seconds; t += 0.01) {
      ++frames;
      frames_agreeing += LabelAt(hyp, t) == LabelAt(truth, t);
    }
  }
  double Share(int k) const { return phones > 0 ? static_cast<double>(k) / phones : 0.0; }
};

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

std::map<std::string, std::vector<std::string>> ReadTranscription(const std::string& path) {
  std::map<std::string, std::vector<std::string>> out;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    const auto open = line.rfind('('), close = line.rfind(')');
    if (open == std::string::npos || close == std::string::npos || close < open) continue;
    const std::string stem = line.substr(open + 1, close - open - 1);
    std::istringstream words(line.substr(0, open));
    for (std::string w; words >> w;) {
      if (w != "<s>" && w != "</s>") out[stem].push_back(w);
    }
  }
  return out;
}

bool LoadAudio(const std::string& path, Clip* clip) {
  auto decoded = kinemo::audio::DecodeAudioFile(path);
  if (!decoded.ok()) {
    std::fprintf(stderr, "%s: %s\n", path.c_str(), std::string(decoded.status().message()).c_str());
    return false;
  }
  auto at16k = kinemo::audio::ToAnalysisRate(*std::move(decoded), pr::SphinxRecognizer::kSampleRateHz);
  if (!at16k.ok()) return false;
  clip->samples = std::move(at16k->samples);
  clip->seconds = at16k->duration_s;
  clip->name = std::filesystem::path(path).stem().string();
  return true;
}

bool ParseSetting(std::string spec, Setting* s) {
  std::replace(spec.begin(), spec.end(), ':', ' ');
  std::istringstream in(spec);
  std::string method;
  int ci = 0;
  pr::PhoneSearchConfig& p = s->phones;
  if (!(in >> s->name >> method >> p.beam >> p.phone_beam >> p.word_beam >> p.language_weight >>
        p.frame_downsampling >> p.top_gaussians >> ci)) {
    return false;
  }
  if (method == "words") {
    p.method = pr::PhoneMethod::kAlignedWords;
  } else if (method == "grammar" || method == "grammar2") {
    p.method = pr::PhoneMethod::kPhoneGrammar;
    p.grammar_order = method == "grammar2" ? 2 : 3;
  } else if (method == "loop") {
    p.method = pr::PhoneMethod::kPhoneLoop;
  } else {
    return false;
  }
  p.context_independent = ci != 0;
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::string data;
  std::vector<std::string> extra;
  std::vector<Setting> custom;
  bool json = false, dump = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--data" && i + 1 < argc) {
      data = argv[++i];
    } else if (a == "--audio" && i + 1 < argc) {
      extra.push_back(argv[++i]);
    } else if (a == "--setting" && i + 1 < argc) {
      Setting s;
      if (!ParseSetting(argv[++i], &s)) {
        std::fprintf(stderr, "--setting NAME:words|grammar|grammar2|loop:BEAM:PBEAM:WBEAM:LW:DS:TOPN:CI\n");
        return 2;
      }
      custom.push_back(s);
    } else if (a == "--dump") {
      dump = true;
    } else if (a == "--json") {
      json = true;
    } else {
      std::fprintf(stderr, "usage: phone_eval [--data DIR] [--audio FILE]... [--json] [--dump] "
                           "[--setting NAME:METHOD:BEAM:PBEAM:WBEAM:LW:DS:TOPN:CI]...\n");
      return 2;
    }
  }
  if (data.empty()) {
    const std::string shared = std::string(KINEMO_SHARED_DATA_DIR) + "/speech/librivox";
    data = std::filesystem::exists(shared) ? shared : std::string(KINEMO_TEST_DATA_DIR) + "/speech";
  }
  std::fprintf(stderr, "phone_eval: clips with transcripts from %s\n", data.c_str());
  auto reference = pr::SphinxRecognizer::Create({});
  if (!reference.ok()) {
    std::fprintf(stderr, "%s\n", std::string(reference.status().message()).c_str());
    return 1;
  }
  std::vector<Clip> clips;
  for (const auto& [stem, words] : ReadTranscription(data + "/transcription")) {
    Clip c;
    if (!LoadAudio(data + "/" + stem + ".wav", &c)) continue;
    c.words = words;
    auto truth = (*reference)->AlignPhones(c.samples, c.words);
    if (!truth.ok()) {
      std::fprintf(stderr, "%s: %s\n", stem.c_str(), std::string(truth.status().message()).c_str());
      continue;
    }
    c.truth = *std::move(truth);
    clips.push_back(std::move(c));
  }
  for (const auto& path : extra) {
    Clip c;
    if (LoadAudio(path, &c)) clips.push_back(std::move(c));
  }
  if (clips.empty()) {
    std::fprintf(stderr, "phone_eval: no clips\n");
    return 1;
  }

  std::vector<Setting> settings;
  settings.push_back({"legacy", pr::LegacyPhoneSearch(), pr::LegacyWordSearch()});
  settings.push_back({"default", {}, {}});
  auto vary = [&](const std::string& name, auto change) {
    Setting s{name, {}, {}};
    change(s);
    settings.push_back(s);
  };
  vary("grammar", [](Setting& s) { s.phones.method = pr::PhoneMethod::kPhoneGrammar; });
  vary("grammar_bigram", [](Setting& s) {
    s.phones.method = pr::PhoneMethod::kPhoneGrammar;
    s.phones.grammar_order = 2;
  });
  vary("words_sphinx_default", [](Setting& s) { s.words = pr::LegacyWordSearch(); });
  vary("words_maxhmmpf1000", [](Setting& s) { s.words.max_hmms_per_frame = 1000; });
  vary("words_topn4", [](Setting& s) { s.words.top_gaussians = 4; });
  vary("words_maxhmmpf1500", [](Setting& s) { s.words.max_hmms_per_frame = 1500; });
  vary("words_maxhmmpf3000", [](Setting& s) { s.words.max_hmms_per_frame = 3000; });
  if (!custom.empty()) settings = custom;

  nlohmann::json rows = nlohmann::json::array();
  if (!json) {
    std::printf("%-22s %7s %7s %7s %6s %6s %7s %7s %6s %7s %7s %8s\n", "setting", "rec_rtf", "ph_rtf",
                "liv_rtf", "b_p50", "b_p90", "matched", "seq_mat", "frames", "liv_mat", "liv_b50",
                "word_acc");
  }
  for (const Setting& s : settings) {
    pr::RecognizerConfig config;
    config.phone_search = s.phones;
    config.word_search = s.words;
    auto recognizer = pr::SphinxRecognizer::Create(config);
    if (!recognizer.ok()) return 1;
    (void)(*recognizer)->Recognize(clips.front().samples);  // loads the models
    Scores scores, live_scores;
    double rec_cpu = 0, phone_cpu = 0, live_cpu = 0, seconds = 0;
    int ref_words = 0, word_hits = 0, hyp_words = 0;
    for (const Clip& c : clips) {
      seconds += c.seconds;
      double t0 = ThreadCpuS();
      auto rec = (*recognizer)->Recognize(c.samples);
      rec_cpu += ThreadCpuS() - t0;
      if (!rec.ok()) {
        std::fprintf(stderr, "%s: %s\n", c.name.c_str(), std::string(rec.status().message()).c_str());
        return 1;
      }
      t0 = ThreadCpuS();
      auto phones = (*recognizer)->Phones(c.samples);
      phone_cpu += ThreadCpuS() - t0;
      if (!phones.ok()) return 1;
      auto stream = (*recognizer)->OpenPhoneStream(0.3);
      if (!stream.ok()) return 1;
      std::vector<pr::RecognizedPhone> live;
      t0 = ThreadCpuS();
      for (std::size_t i = 0; i < c.samples.size(); i += 320) {
        const std::size_t n = std::min<std::size_t>(320, c.samples.size() - i);
        if (!(*stream)->Process(std::span<const float>(c.samples).subspan(i, n), &live).ok()) return 1;
      }
      if (!(*stream)->Finish(&live).ok()) return 1;
      live_cpu += ThreadCpuS() - t0;
      if (c.truth.empty()) continue;
      scores.Add(c.truth, *phones, c.seconds);
      live_scores.Add(c.truth, live, c.seconds);
      std::vector<std::string> said;
      for (const auto& w : rec->words) said.push_back(w.word);
      ref_words += static_cast<int>(c.words.size());
      hyp_words += static_cast<int>(said.size());
      word_hits += AlignedMatches(c.words, said);
      if (dump) {
        std::string ref, hyp, lv;
        for (const auto& p : c.truth) ref += " " + p.phone;
        for (const auto& p : *phones) hyp += " " + p.phone;
        for (const auto& p : live) lv += " " + p.phone;
        std::fprintf(stderr, "%s\n  reference:%s\n  %s:%s\n  live:%s\n", c.name.c_str(), ref.c_str(),
                     s.name.c_str(), hyp.c_str(), lv.c_str());
      }
    }
    // Word accuracy 1 - (S + D + I) / N from the alignment's matches (an
    // upper bound of the exact WER's complement when sequences differ much).
    const int errors = std::max(ref_words, hyp_words) - word_hits;
    nlohmann::json row = {
        {"setting", s.name},
        {"method", MethodName(s.phones)},
        {"beam", s.phones.beam},
        {"phone_beam", s.phones.phone_beam},
        {"word_beam", s.phones.word_beam},
        {"language_weight", s.phones.language_weight},
        {"frame_downsampling", s.phones.frame_downsampling},
        {"top_gaussians", s.phones.top_gaussians},
        {"word_search_second_passes", s.words.second_passes},
        {"word_search_max_hmms_per_frame", s.words.max_hmms_per_frame},
        {"audio_s", seconds},
        {"recognize_rtf", rec_cpu / seconds},
        {"phones_rtf", phone_cpu / seconds},
        {"live_rtf", live_cpu / seconds},
        {"boundary_error_p50_ms", 1000 * Quantile(scores.boundary_errors_s, 0.5)},
        {"boundary_error_p90_ms", 1000 * Quantile(scores.boundary_errors_s, 0.9)},
        {"phones_matched", scores.Share(scores.matched)},
        {"phones_seq_matched", scores.Share(scores.seq_matched)},
        {"frames_agreeing", scores.frames ? double(scores.frames_agreeing) / scores.frames : 0.0},
        {"live_phones_matched", live_scores.Share(live_scores.matched)},
        {"live_boundary_error_p50_ms", 1000 * Quantile(live_scores.boundary_errors_s, 0.5)},
        {"word_accuracy", ref_words > 0 ? 1.0 - double(errors) / ref_words : 0.0},
        {"reference_phones", scores.phones}};
    if (json) {
      rows.push_back(row);
    } else {
      std::printf("%-22s %7.3f %7.3f %7.3f %4.0fms %4.0fms %7.3f %7.3f %6.3f %7.3f %5.0fms %8.3f\n",
                  s.name.c_str(), rec_cpu / seconds, phone_cpu / seconds, live_cpu / seconds,
                  row["boundary_error_p50_ms"].get<double>(), row["boundary_error_p90_ms"].get<double>(),
                  row["phones_matched"].get<double>(), row["phones_seq_matched"].get<double>(),
                  row["frames_agreeing"].get<double>(), row["live_phones_matched"].get<double>(),
                  row["live_boundary_error_p50_ms"].get<double>(), row["word_accuracy"].get<double>());
      std::fflush(stdout);
    }
  }
  if (json) std::printf("%s\n", rows.dump(1).c_str());
  return 0;
}

#include "services/prosody/core/pipeline.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>

#include <nlohmann/json.hpp>

#include "common/audio/resample.h"
#include "common/parallel/parallel.h"
#include "services/prosody/core/analyzer.h"
#ifdef KINEMO_WITH_SPHINX
#include "services/prosody/core/recognizer.h"
#endif

namespace kinemo::prosody {

#ifdef KINEMO_WITH_SPHINX
namespace {

// CPU seconds this thread has run (the recognizer runs on the caller's thread).
double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

}  // namespace
#endif

bool RecognizerBuiltIn() {
#ifdef KINEMO_WITH_SPHINX
  return true;
#else
  return false;
#endif
}

StatusOr<PipelineResult> RunPipeline(std::span<const float> mono, int sample_rate_hz,
                                     const PipelineRequest& request,
                                     SphinxRecognizer* recognizer) {
  PipelineResult out;
  const bool want_recognizer = request.recognize || !request.keywords.empty();
  if (want_recognizer && !RecognizerBuiltIn()) {
    return absl::FailedPreconditionError(
        "recognizer: not built in (configure with -DKINEMO_WITH_SPHINX=ON)");
  }
  if (want_recognizer && recognizer == nullptr) {
    return absl::FailedPreconditionError("recognizer: not configured or disabled");
  }
  KINEMO_RETURN_IF_ERROR(CheckCancel(request.cancel, "analysis"));
  std::vector<float> resampled;
  std::span<const float> samples = mono;
  int rate = sample_rate_hz;
  if (request.analysis_rate_hz > 0 && request.analysis_rate_hz != sample_rate_hz) {
    KINEMO_ASSIGN_OR_RETURN(resampled,
                            audio::Resample(mono, sample_rate_hz, request.analysis_rate_hz));
    samples = resampled;
    rate = request.analysis_rate_hz;
  }
  KINEMO_RETURN_IF_ERROR(CheckCancel(request.cancel, "analysis"));
  KINEMO_ASSIGN_OR_RETURN(out.prosody, AnalyzeSamples(samples, rate, request.options));
#ifdef KINEMO_WITH_SPHINX
  if (want_recognizer) {
    std::vector<float> at16k;
    std::span<const float> speech = samples;
    if (rate != SphinxRecognizer::kSampleRateHz) {
      KINEMO_ASSIGN_OR_RETURN(at16k, audio::Resample(mono, sample_rate_hz,
                                                     SphinxRecognizer::kSampleRateHz));
      speech = at16k;
    }
    KINEMO_RETURN_IF_ERROR(CheckCancel(request.cancel, "analysis"));
    KINEMO_RETURN_IF_ERROR(recognizer->LoadModels());  // not counted as recognition
    KINEMO_RETURN_IF_ERROR(CheckCancel(request.cancel, "analysis"));
    const double cpu0 = ThreadCpuSeconds();
    std::vector<RecognizedWord> words;
    std::vector<RecognizedPhone> phones;
    if (!request.keywords.empty()) {
      KINEMO_ASSIGN_OR_RETURN(
          words, recognizer->Keywords(speech, request.keywords, request.keyword_threshold));
      if (request.recognize) {
        KINEMO_ASSIGN_OR_RETURN(phones, recognizer->Phones(speech));
      }
    } else {
      // Words and phones in one pass (the phones are the words' by default).
      KINEMO_ASSIGN_OR_RETURN(SphinxRecognizer::WordsAndPhones both, recognizer->Recognize(speech));
      words = std::move(both.words);
      phones = std::move(both.phones);
    }
    out.recognizer_compute_s = ThreadCpuSeconds() - cpu0;
    for (const RecognizedWord& w : words) {
      out.words.push_back({w.word, w.start_s, w.end_s, w.confidence, w.keyword});
    }
    for (const RecognizedPhone& p : phones) out.phones.push_back({p.phone, p.start_s, p.end_s});
    out.recognizer_ran = true;
  }
#endif
  return out;
}

namespace {

// Appends `v` as nlohmann::json's dump() writes a double, so that the frames
// (written here directly, being most of a long recording's output) read back
// the same: the shortest digits that round-trip; integers end in ".0"; plain
// notation for decimal exponents -4 < n <= 15, else d.ddde+XX; null for
// non-finite values.
void AppendNumber(double v, std::string* out) {
  if (!std::isfinite(v)) {
    *out += "null";
    return;
  }
  char sci[40];
  const char* end = std::to_chars(sci, sci + sizeof sci, v, std::chars_format::scientific).ptr;
  // sci = [-]d[.ddd]e(+|-)XX
  const char* p = sci;
  if (*p == '-') out->push_back(*p++);
  char digits[24];
  int k = 0;
  for (; *p != 'e'; ++p) {
    if (*p != '.') digits[k++] = *p;
  }
  int exponent = 0;
  std::from_chars(p + (p[1] == '+' ? 2 : 1), end, exponent);
  const int n = exponent + 1;  // the decimal point sits after n digits
  if (k <= n && n <= 15) {
    out->append(digits, static_cast<std::size_t>(k));
    out->append(static_cast<std::size_t>(n - k), '0');
    *out += ".0";
  } else if (0 < n && n <= 15) {
    out->append(digits, static_cast<std::size_t>(n));
    out->push_back('.');
    out->append(digits + n, static_cast<std::size_t>(k - n));
  } else if (-4 < n && n <= 0) {
    *out += "0.";
    out->append(static_cast<std::size_t>(-n), '0');
    out->append(digits, static_cast<std::size_t>(k));
  } else {
    out->push_back(digits[0]);
    if (k > 1) {
      out->push_back('.');
      out->append(digits + 1, static_cast<std::size_t>(k - 1));
    }
    char exp[16];
    const int e = n - 1;
    std::snprintf(exp, sizeof exp, "e%c%02d", e < 0 ? '-' : '+', std::abs(e));
    *out += exp;
  }
}

// Frames [first, last) as JSON objects separated by commas (keys in
// nlohmann's order: sorted).
void AppendFrames(const std::vector<Frame>& frames, std::size_t first, std::size_t last,
                  std::string* out) {
  for (std::size_t i = first; i < last; ++i) {
    const Frame& f = frames[i];
    if (i > first) out->push_back(',');
    *out += "{\"f0_hz\":";
    AppendNumber(f.f0_hz, out);
    *out += ",\"intensity_db\":";
    AppendNumber(f.intensity_db, out);
    *out += ",\"time_s\":";
    AppendNumber(f.time_s, out);
    *out += f.voiced ? ",\"voiced\":true" : ",\"voiced\":false";
    *out += ",\"voicing_probability\":";
    AppendNumber(f.voicing_probability, out);
    out->push_back('}');
  }
}

// The frames array, formatted in blocks on `threads` threads.
void AppendFramesArray(const std::vector<Frame>& frames, int threads, std::string* out) {
  constexpr std::size_t kBlock = 4096;
  const int blocks = static_cast<int>((frames.size() + kBlock - 1) / kBlock);
  std::vector<std::string> text(static_cast<std::size_t>(blocks));
  parallel::ParallelFor(blocks, parallel::ResolveThreads(threads), [&](int b, int) {
    const std::size_t first = static_cast<std::size_t>(b) * kBlock;
    std::string& t = text[static_cast<std::size_t>(b)];
    t.reserve(kBlock * 128);
    AppendFrames(frames, first, std::min(frames.size(), first + kBlock), &t);
  });
  out->push_back('[');
  for (int b = 0; b < blocks; ++b) {
    if (b > 0) out->push_back(',');
    *out += text[static_cast<std::size_t>(b)];
  }
  out->push_back(']');
}

}  // namespace

std::string ToJson(const PipelineResult& result, int threads) {
  using nlohmann::json;
  const ProsodyResult& r = result.prosody;
  json j;
  j["duration_s"] = r.duration_s;
  j["analysis_rate_hz"] = r.sample_rate_hz;
  j["frame_step_s"] = r.frame_step_s;
  j["frames"] = nullptr;  // written below, in its place among the sorted keys
  json syllables = json::array();
  for (const Syllable& s : r.syllables) {
    syllables.push_back({{"start_s", s.start_s},
                         {"end_s", s.end_s},
                         {"f0_mean_hz", s.f0_mean_hz},
                         {"intensity_mean_db", s.intensity_mean_db},
                         {"length_s", s.length_s},
                         {"voiced", s.voiced},
                         {"nucleus_time_s", s.nucleus_time_s},
                         {"accent_index", s.accent_index}});
  }
  j["syllables"] = std::move(syllables);
  json accents = json::array();
  for (const Accent& a : r.accents) {
    accents.push_back({{"time_s", a.time_s},
                       {"strength", a.strength},
                       {"psi", a.psi},
                       {"syllable_index", a.syllable_index},
                       {"syllable_start_s", a.syllable_start_s},
                       {"syllable_end_s", a.syllable_end_s},
                       {"before_pause", a.before_pause}});
  }
  j["accents"] = std::move(accents);
  json pauses = json::array();
  for (const Pause& p : r.pauses) pauses.push_back({{"start_s", p.start_s}, {"end_s", p.end_s}});
  j["pauses"] = std::move(pauses);
  json words = json::array();
  for (const Word& w : result.words) {
    words.push_back({{"word", w.word},
                     {"start_s", w.start_s},
                     {"end_s", w.end_s},
                     {"confidence", w.confidence},
                     {"keyword", w.keyword}});
  }
  j["words"] = std::move(words);
  json phones = json::array();
  for (const Phone& p : result.phones) {
    phones.push_back({{"phone", p.phone}, {"start_s", p.start_s}, {"end_s", p.end_s}});
  }
  j["phones"] = std::move(phones);
  j["recognizer_ran"] = result.recognizer_ran;
  if (result.recognizer_ran && r.duration_s > 0) {
    j["recognizer_rtf"] = result.recognizer_compute_s / r.duration_s;
  }
  std::string out = "{";
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (it != j.begin()) out.push_back(',');
    out += json(it.key()).dump();
    out.push_back(':');
    if (it.key() == "frames") {
      AppendFramesArray(r.frames, threads, &out);
    } else {
      out += it.value().dump();
    }
  }
  out.push_back('}');
  return out;
}

std::string ToCsv(const PipelineResult& result) {
  const ProsodyResult& r = result.prosody;
  std::string out =
      "time_s,f0_hz,voiced,voicing_probability,intensity_db,syllable,accent_strength\n";
  std::size_t s = 0;
  char line[160];
  for (std::size_t i = 0; i < r.frames.size(); ++i) {
    const Frame& f = r.frames[i];
    while (s < r.syllables.size() && r.syllables[s].end_frame <= static_cast<int>(i)) ++s;
    int syl = -1;
    double strength = 0;
    if (s < r.syllables.size() && r.syllables[s].first_frame <= static_cast<int>(i)) {
      syl = static_cast<int>(s);
      if (r.syllables[s].accent_index >= 0) strength = r.accents[r.syllables[s].accent_index].strength;
    }
    std::snprintf(line, sizeof line, "%.3f,%.3f,%d,%.4f,%.3f,%d,%.4f\n", f.time_s, f.f0_hz,
                  f.voiced ? 1 : 0, f.voicing_probability, f.intensity_db, syl, strength);
    out += line;
  }
  return out;
}

namespace {

std::string Quote(const std::string& s) {
  std::string q = "\"";
  for (char c : s) {
    if (c == '"') q += '"';
    q += c;
  }
  return q + "\"";
}

struct Interval {
  double xmin, xmax;
  std::string text;
};

// Fills the gaps between `marks` with empty intervals over [0, duration].
std::string IntervalTier(const std::string& name, std::vector<Interval> marks, double duration,
                         int index) {
  std::sort(marks.begin(), marks.end(),
            [](const Interval& a, const Interval& b) { return a.xmin < b.xmin; });
  std::vector<Interval> all;
  double t = 0;
  for (Interval m : marks) {
    m.xmin = std::clamp(m.xmin, t, duration);
    m.xmax = std::clamp(m.xmax, m.xmin, duration);
    if (m.xmax <= m.xmin) continue;
    if (m.xmin > t) all.push_back({t, m.xmin, ""});
    all.push_back(m);
    t = m.xmax;
  }
  if (t < duration || all.empty()) all.push_back({t, duration, ""});
  char buf[256];
  std::string out;
  std::snprintf(buf, sizeof buf,
                "    item [%d]:\n        class = \"IntervalTier\"\n        name = %s\n"
                "        xmin = 0\n        xmax = %.6f\n        intervals: size = %zu\n",
                index, Quote(name).c_str(), duration, all.size());
  out += buf;
  for (std::size_t i = 0; i < all.size(); ++i) {
    std::snprintf(buf, sizeof buf,
                  "        intervals [%zu]:\n            xmin = %.6f\n            xmax = %.6f\n",
                  i + 1, all[i].xmin, all[i].xmax);
    out += buf;
    out += "            text = " + Quote(all[i].text) + "\n";
  }
  return out;
}

}  // namespace

std::string ToTextGrid(const PipelineResult& result) {
  const ProsodyResult& r = result.prosody;
  const double duration = std::max(r.duration_s, 1e-3);
  std::vector<Interval> syl, pau, wrd, phn;
  char label[64];
  for (const Syllable& s : r.syllables) {
    if (s.voiced) {
      std::snprintf(label, sizeof label, "%.0f Hz %.1f dB", s.f0_mean_hz, s.intensity_mean_db);
    } else {
      std::snprintf(label, sizeof label, "unvoiced %.1f dB", s.intensity_mean_db);
    }
    syl.push_back({s.start_s, s.end_s, label});
  }
  for (const Pause& p : r.pauses) pau.push_back({p.start_s, p.end_s, "pause"});
  for (const Word& w : result.words) wrd.push_back({w.start_s, w.end_s, w.word});
  for (const Phone& p : result.phones) phn.push_back({p.start_s, p.end_s, p.phone});
  const int tiers = 3 + (result.recognizer_ran ? 2 : 0);
  char buf[256];
  std::string out = "File type = \"ooTextFile\"\nObject class = \"TextGrid\"\n\n";
  std::snprintf(buf, sizeof buf, "xmin = 0\nxmax = %.6f\ntiers? <exists>\nsize = %d\nitem []:\n",
                duration, tiers);
  out += buf;
  out += IntervalTier("syllables", syl, duration, 1);
  std::snprintf(buf, sizeof buf,
                "    item [2]:\n        class = \"TextTier\"\n        name = \"accents\"\n"
                "        xmin = 0\n        xmax = %.6f\n        points: size = %zu\n",
                duration, r.accents.size());
  out += buf;
  for (std::size_t i = 0; i < r.accents.size(); ++i) {
    std::snprintf(buf, sizeof buf,
                  "        points [%zu]:\n            number = %.6f\n"
                  "            mark = \"%.2f psi=%.3f\"\n",
                  i + 1, r.accents[i].time_s, r.accents[i].strength, r.accents[i].psi);
    out += buf;
  }
  out += IntervalTier("pauses", pau, duration, 3);
  if (result.recognizer_ran) {
    out += IntervalTier("words", wrd, duration, 4);
    out += IntervalTier("phones", phn, duration, 5);
  }
  return out;
}

}  // namespace kinemo::prosody

#include "services/planner/gesture/visemes.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

namespace kinemo::planner::gesture {

constexpr double kMaxVisemeTrackS = 7200;  // longest track one Visemes(Chunked) call makes (2 h)
namespace {

struct Entry {
  const char* phone;
  Viseme viseme;
};

// Table 4.5 (ARPAbet spelling).
constexpr Entry kTable[] = {
    {"SIL", Viseme::kPau}, {"PAU", Viseme::kPau},
    {"R", Viseme::kR},
    {"K", Viseme::kKGNg}, {"G", Viseme::kKGNg}, {"NG", Viseme::kKGNg},
    {"AE", Viseme::kAa}, {"AX", Viseme::kAa}, {"AH", Viseme::kAa}, {"AA", Viseme::kAa},
    {"F", Viseme::kFV}, {"V", Viseme::kFV},
    {"CH", Viseme::kChShJh}, {"SH", Viseme::kChShJh}, {"JH", Viseme::kChShJh},
    {"AO", Viseme::kAo}, {"Y", Viseme::kAo}, {"IY", Viseme::kAo}, {"IH", Viseme::kAo}, {"AY", Viseme::kAo},
    {"AW", Viseme::kAo}, {"IX", Viseme::kAo},
    {"OW", Viseme::kOw}, {"OY", Viseme::kOw},
    {"N", Viseme::kNDTL}, {"D", Viseme::kNDTL}, {"T", Viseme::kNDTL}, {"L", Viseme::kNDTL},
    {"DX", Viseme::kNDTL}, {"NX", Viseme::kNDTL},
    {"EY", Viseme::kEy}, {"EH", Viseme::kEy}, {"EL", Viseme::kEy}, {"EM", Viseme::kEy}, {"EN", Viseme::kEy},
    {"ER", Viseme::kEy}, {"AXR", Viseme::kEy},
    {"TH", Viseme::kThDh}, {"DH", Viseme::kThDh},
    {"S", Viseme::kSZZh}, {"Z", Viseme::kSZZh}, {"ZH", Viseme::kSZZh},
    {"B", Viseme::kBPM}, {"P", Viseme::kBPM}, {"M", Viseme::kBPM},
    {"HH", Viseme::kHh},
    {"W", Viseme::kWUw}, {"UW", Viseme::kWUw}, {"UH", Viseme::kWUw}, {"UX", Viseme::kWUw},
};

constexpr const char* kNames[kNumVisemes] = {"PAU", "R",   "K_G_NG", "AA",    "F_V",   "CH_SH_JH", "AO",  "OW",
                                             "N_D_T_L", "EY", "TH_DH", "S_Z_ZH", "B_P_M", "HH",       "W_UW"};

}  // namespace

std::string_view VisemeName(Viseme v) { return kNames[static_cast<int>(v)]; }

bool IsVowelViseme(Viseme v) {
  return v == Viseme::kAa || v == Viseme::kAo || v == Viseme::kOw || v == Viseme::kEy || v == Viseme::kWUw;
}

bool PhoneToViseme(std::string_view phone, Viseme* out) {
  std::string p;
  for (char c : phone) {
    if (std::isdigit(static_cast<unsigned char>(c))) continue;  // stress marks
    p.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  }
  *out = Viseme::kPau;
  if (p.empty()) return false;
  // Sphinx fillers and noise: "+NSN+", "+SPN+", "<sil>", "[NOISE]".
  if (p.front() == '+' || p.front() == '<' || p.front() == '[') return true;
  for (const Entry& e : kTable) {
    if (p == e.phone) {
      *out = e.viseme;
      return true;
    }
  }
  return false;
}

StatusOr<VisemeTrack> ComputeVisemes(std::span<const TimedPhone> phones, std::span<const VisemeAccent> accents,
                                     const VisemeParams& params) {
  if (!(params.frame_time_s > 0.001 && params.frame_time_s <= 1)) {
    return InvalidField("params.frame_time_s", "must be in (0.001, 1] s");
  }
  if (!(params.coarticulation_s >= 0 && params.coarticulation_s <= 1)) {
    return InvalidField("params.coarticulation_s", "must be in [0, 1] s");
  }
  if (!(params.face_emphasis >= -1 && params.face_emphasis <= 1)) {
    return InvalidField("params.face_emphasis", "must be in [-1, 1]");
  }
  // One request's track covers at most two hours (its frames are allocated up front).
  if (!(params.duration_s >= 0 && params.duration_s <= kMaxVisemeTrackS)) {
    return InvalidField("duration_s", params.duration_s, " is not in [0, ", kMaxVisemeTrackS, "] s");
  }
  double prev_end = 0;
  std::vector<Viseme> cat(phones.size());
  VisemeTrack track;
  track.frame_time_s = params.frame_time_s;
  for (size_t i = 0; i < phones.size(); ++i) {
    const auto& p = phones[i];
    const std::string f = kinemo::StrCat("phones[", i, "]");
    if (!std::isfinite(p.start_s) || !std::isfinite(p.end_s) || p.start_s < 0 || p.end_s <= p.start_s) {
      return InvalidField(f, "needs 0 <= start_s < end_s");
    }
    if (p.end_s > kMaxVisemeTrackS) return InvalidField(f + ".end_s", p.end_s, " is past ", kMaxVisemeTrackS, " s");
    if (p.start_s < prev_end - 1e-6) return InvalidField(f + ".start_s", "phones out of order or overlapping");
    prev_end = p.end_s;
    if (!PhoneToViseme(p.phone, &cat[i]) &&
        std::find(track.unknown_phones.begin(), track.unknown_phones.end(), p.phone) == track.unknown_phones.end()) {
      track.unknown_phones.push_back(p.phone);
    }
  }
  for (size_t i = 0; i < accents.size(); ++i) {
    const auto& a = accents[i];
    if (!std::isfinite(a.papt_s) || !(a.strength >= 0 && a.strength <= 1)) {
      return InvalidField(kinemo::StrCat("accents[", i, "]"), "needs a finite time and strength in [0, 1]");
    }
  }
  const double duration = params.duration_s > 0 ? params.duration_s : prev_end;
  if (duration > params.max_duration_s) {
    return absl::ResourceExhaustedError(kinemo::StrCat("duration_s: longer than ", params.max_duration_s, " s"));
  }
  // Emphasis per phone: vowels overlapping an accented syllable.
  std::vector<double> emph(phones.size(), 0.0);
  for (const auto& a : accents) {
    const double s = std::clamp(a.strength + params.face_emphasis, 0.0, 1.0);
    const bool span = a.syllable_end_s > a.syllable_start_s;
    for (size_t i = 0; i < phones.size(); ++i) {
      if (!IsVowelViseme(cat[i])) continue;
      const bool hit = span ? (phones[i].start_s < a.syllable_end_s && phones[i].end_s > a.syllable_start_s)
                            : (phones[i].start_s <= a.papt_s && a.papt_s < phones[i].end_s);
      if (hit) emph[i] = 2 * s - 1;
    }
  }
  const int n = static_cast<int>(std::floor(duration / params.frame_time_s + 1e-9)) + 1;
  track.frames.resize(static_cast<size_t>(n));
  const double c2 = params.coarticulation_s / 2;
  size_t pi = 0;
  for (int k = 0; k < n; ++k) {
    VisemeFrame& fr = track.frames[static_cast<size_t>(k)];
    const double t = k * params.frame_time_s;
    fr.time_s = t;
    while (pi < phones.size() && phones[pi].end_s <= t) ++pi;
    const bool inside = pi < phones.size() && phones[pi].start_s <= t;
    if (!inside) {
      // Between phones (or outside them): silence, with the ramps of the
      // neighbours if they are adjacent to this gap.
      fr.weights[static_cast<int>(Viseme::kPau)] = 1;
      continue;
    }
    const TimedPhone& p = phones[pi];
    const Viseme v = cat[pi];
    const double len = p.end_s - p.start_s;
    double w_self = 1;
    Viseme other = v;
    // Boundary with the previous phone (adjacent, else silence).
    {
      const bool adj = pi > 0 && phones[pi - 1].end_s >= p.start_s - 1e-6;
      const double plen = adj ? phones[pi - 1].end_s - phones[pi - 1].start_s : len;
      const double h = std::min({c2, len / 2, plen / 2});
      if (h > 0 && t < p.start_s + h) {
        w_self = 0.5 + 0.5 * (t - p.start_s) / h;
        other = adj ? cat[pi - 1] : Viseme::kPau;
      }
    }
    // Boundary with the next phone.
    {
      const bool adj = pi + 1 < phones.size() && phones[pi + 1].start_s <= p.end_s + 1e-6;
      const double nlen = adj ? phones[pi + 1].end_s - phones[pi + 1].start_s : len;
      const double h = std::min({c2, len / 2, nlen / 2});
      if (h > 0 && t > p.end_s - h) {
        w_self = 0.5 + 0.5 * (p.end_s - t) / h;
        other = adj ? cat[pi + 1] : Viseme::kPau;
      }
    }
    fr.weights[static_cast<int>(v)] += w_self;
    fr.weights[static_cast<int>(other)] += 1 - w_self;
    fr.emphasis = IsVowelViseme(v) ? emph[pi] * w_self : 0.0;
  }
  return track;
}

std::string VisemesToJson(const VisemeTrack& track) {
  nlohmann::json j;
  j["frame_time_s"] = track.frame_time_s;
  nlohmann::json cats = nlohmann::json::array();
  for (int c = 0; c < kNumVisemes; ++c) cats.push_back(std::string(VisemeName(static_cast<Viseme>(c))));
  j["categories"] = cats;
  nlohmann::json frames = nlohmann::json::array();
  auto r = [](double v) { return std::round(v * 1e4) / 1e4; };
  for (const auto& f : track.frames) {
    nlohmann::json w = nlohmann::json::array();
    for (double x : f.weights) w.push_back(r(x));
    frames.push_back({{"time_s", r(f.time_s)}, {"weights", std::move(w)}, {"emphasis", r(f.emphasis)}});
  }
  j["frames"] = std::move(frames);
  j["unknown_phones"] = track.unknown_phones;
  return j.dump();
}

std::string VisemesToCsv(const VisemeTrack& track) {
  std::string out = "time_s,emphasis";
  for (int c = 0; c < kNumVisemes; ++c) out += kinemo::StrCat(",", VisemeName(static_cast<Viseme>(c)));
  out += "\n";
  char buf[64];
  for (const auto& f : track.frames) {
    std::snprintf(buf, sizeof buf, "%.4f,%.4f", f.time_s, f.emphasis);
    out += buf;
    for (double w : f.weights) {
      std::snprintf(buf, sizeof buf, ",%.4f", w);
      out += buf;
    }
    out += "\n";
  }
  return out;
}

}  // namespace kinemo::planner::gesture

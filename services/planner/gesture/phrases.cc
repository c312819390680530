#include "services/planner/gesture/phrases.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>

#include "common/motion/kinematics.h"

namespace kinemo::planner::gesture {
namespace {

using Json = nlohmann::json;

// Joints the segmentation and the GSI use.
struct ArmJoints {
  int left_hand = -1, right_hand = -1;
  int chest = -1;                        // parent of the left arm chain
  std::vector<std::pair<int, double>> fm;  // FMDistance joints and moments
};

StatusOr<ArmJoints> FindArmJoints(const Library& library) {
  ArmJoints a;
  const auto& sk = library.skeleton;
  KINEMO_ASSIGN_OR_RETURN(motion::KeyJoints keys, motion::FindKeyJoints(sk, library.regions));
  a.left_hand = keys.left_hand;
  a.right_hand = keys.right_hand;
  for (auto region : {motion::BodyRegion::kLeftArm, motion::BodyRegion::kRightArm}) {
    std::vector<int> js = library.regions.JointsIn(region);
    std::sort(js.begin(), js.end(), [&](int x, int y) { return sk.depth(x) < sk.depth(y); });
    if (js.size() < 2) {
      return absl::FailedPreconditionError("library: the skeleton has no arm chains (upper arm, forearm)");
    }
    // Shoulder (clavicle) 3, arm 3, forearm 2 (thesis §4.4.2).
    const size_t n = js.size();
    if (n >= 3) a.fm.push_back({js[n - 3], 3.0});
    a.fm.push_back({js[n - 2], 3.0});
    a.fm.push_back({js[n - 1], 2.0});
    if (region == motion::BodyRegion::kLeftArm) a.chest = sk.joint(js[0]).parent;
  }
  if (a.chest < 0) a.chest = 0;
  return a;
}

// Hand positions in the chest's frame (metres) for every frame of a clip.
struct HandTrack {
  std::vector<Eigen::Vector3d> left, right;
};

HandTrack ComputeHandTrack(const Library& library, const motion::Clip& clip, const ArmJoints& a) {
  const int n = clip.num_frames();
  const int nj = clip.skeleton.num_joints();
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(nj));
  std::vector<Eigen::Matrix3d> rot(static_cast<size_t>(nj));
  HandTrack t;
  t.left.resize(static_cast<size_t>(n));
  t.right.resize(static_cast<size_t>(n));
  const double mpu = library.meters_per_unit > 0 ? library.meters_per_unit : 0.01;
  for (int f = 0; f < n; ++f) {
    (void)motion::ComputeWorldPose(clip.skeleton, clip.frame(f), pos, rot);
    const Eigen::Matrix3d rt = rot[static_cast<size_t>(a.chest)].transpose();
    const Eigen::Vector3d c = pos[static_cast<size_t>(a.chest)];
    t.left[static_cast<size_t>(f)] = mpu * (rt * (pos[static_cast<size_t>(a.left_hand)] - c));
    t.right[static_cast<size_t>(f)] = mpu * (rt * (pos[static_cast<size_t>(a.right_hand)] - c));
  }
  return t;
}

double Clamp(double v, double lo, double hi) { return std::max(lo, std::min(hi, v)); }

// Automatic phrases of one clip.
std::vector<Phrase> SegmentClip(const Library& library, int clip_index, const ArmJoints& a,
                                const PhraseParams& p) {
  const motion::Clip& clip = library.clips[static_cast<size_t>(clip_index)].clip;
  const int n = clip.num_frames();
  std::vector<Phrase> out;
  if (n < 4) return out;
  const double dt = clip.frame_time_s;
  const HandTrack t = ComputeHandTrack(library, clip, a);
  std::vector<double> speed(static_cast<size_t>(n), 0.0), ext(static_cast<size_t>(n), 0.0);
  for (int f = 0; f < n; ++f) {
    const size_t u = static_cast<size_t>(f);
    ext[u] = std::max((t.left[u] - t.left[0]).norm(), (t.right[u] - t.right[0]).norm());
    const size_t f0 = static_cast<size_t>(std::max(0, f - 1)), f1 = static_cast<size_t>(std::min(n - 1, f + 1));
    const double span = static_cast<double>(f1 - f0) * dt;
    speed[u] = std::max((t.left[f1] - t.left[f0]).norm(), (t.right[f1] - t.right[f0]).norm()) / span;
  }
  // Smooth the speed over 3 frames.
  std::vector<double> s(speed);
  for (int f = 1; f + 1 < n; ++f) {
    const size_t u = static_cast<size_t>(f);
    s[u] = (speed[u - 1] + speed[u] + speed[u + 1]) / 3.0;
  }
  // 1. Activity runs.
  std::vector<std::pair<int, int>> runs;
  for (int f = 0; f < n;) {
    const size_t u = static_cast<size_t>(f);
    if (ext[u] > p.rest_distance_m || s[u] > p.rest_speed_mps) {
      int g = f;
      while (g < n && (ext[static_cast<size_t>(g)] > p.rest_distance_m || s[static_cast<size_t>(g)] > p.rest_speed_mps)) ++g;
      if (!runs.empty() && (f - runs.back().second) * dt < p.min_gap_s) {
        runs.back().second = g;
      } else {
        runs.push_back({f, g});
      }
      f = g;
    } else {
      ++f;
    }
  }
  for (auto [r0, r1] : runs) {
    if ((r1 - r0) * dt < p.min_phrase_s) continue;
    double max_ext = 0, max_speed = 0;
    for (int f = r0; f < r1; ++f) {
      max_ext = std::max(max_ext, ext[static_cast<size_t>(f)]);
      max_speed = std::max(max_speed, s[static_cast<size_t>(f)]);
    }
    const double peak_min = std::max(p.min_stroke_speed_mps, p.stroke_peak_fraction * max_speed);
    // 2. Strokes: local speed maxima in the gesture space.
    struct Stroke {
      int start, peak, apex;
    };
    std::vector<Stroke> strokes;
    int f = std::max(r0, 1);
    while (f < r1 - 1) {
      const size_t u = static_cast<size_t>(f);
      const bool is_peak = s[u] >= peak_min && s[u] >= s[u - 1] && s[u] > s[u + 1];
      if (!is_peak) {
        ++f;
        continue;
      }
      // Apex: tangential acceleration crosses zero upward (speed minimum),
      // searched from the peak; the run's end bounds it.
      int apex = f + 1;
      while (apex + 1 < r1 && s[static_cast<size_t>(apex + 1)] - s[static_cast<size_t>(apex)] < 0) ++apex;
      // Start: speed minimum before the peak (or the previous stroke's apex).
      int start = f;
      const int lo = strokes.empty() ? r0 : strokes.back().apex;
      while (start - 1 > lo && s[static_cast<size_t>(start - 1)] < s[static_cast<size_t>(start)]) --start;
      // Only peaks whose apex is in the gesture space count as strokes;
      // others belong to the preparation or retraction.
      double seg_ext = 0;
      for (int g = start; g <= apex; ++g) seg_ext = std::max(seg_ext, ext[static_cast<size_t>(g)]);
      if (seg_ext >= p.space_fraction * max_ext && apex - start >= 2) {
        strokes.push_back({start, f, apex});
      } else if (!strokes.empty() && ext[static_cast<size_t>(apex)] >= p.space_fraction * max_ext) {
        // A small peak inside the space extends the previous stroke.
        strokes.back().apex = apex;
      }
      f = apex + 1;
    }
    if (strokes.empty()) continue;
    // Drop trailing strokes that are really the retraction: the hands end
    // near rest, so a stroke whose apex is back at rest is retraction.
    while (strokes.size() > 1 && ext[static_cast<size_t>(strokes.back().apex)] < p.rest_distance_m) strokes.pop_back();
    // 3. Phrases and phases.
    for (size_t k = 0; k < strokes.size(); ++k) {
      Phrase ph;
      ph.clip = clip_index;
      const Stroke& st = strokes[k];
      const int stroke_end = std::min(st.apex + 1, r1);
      const bool last = k + 1 == strokes.size();
      // At most max_preparation_s before the stroke and max_after_stroke_s
      // after it: a unit whose hands never came back to rest made phrases of
      // 10-23 s (BEAT2 takes), played whole as one "gesture".
      const int max_pre = p.max_preparation_s > 0 ? static_cast<int>(std::lround(p.max_preparation_s / dt)) : n;
      const int max_after = p.max_after_stroke_s > 0 ? static_cast<int>(std::lround(p.max_after_stroke_s / dt)) : n;
      const int begin = std::max(k == 0 ? r0 : st.start, st.start - max_pre);
      const int end = std::min(last ? r1 : strokes[k + 1].start, stroke_end + max_after);
      ph.first_frame = begin;
      ph.end_frame = std::max(end, stroke_end);
      if (st.start > begin) ph.phases.push_back({Phase::kPreparation, begin, st.start});
      ph.phases.push_back({Phase::kStroke, st.start, stroke_end});
      int hold_end = stroke_end;
      while (hold_end < ph.end_frame && s[static_cast<size_t>(hold_end)] < p.hold_speed_mps) ++hold_end;
      if (hold_end > stroke_end) ph.phases.push_back({Phase::kHold, stroke_end, hold_end});
      if (ph.end_frame > hold_end) {
        ph.phases.push_back({last ? Phase::kRetraction : Phase::kHold, hold_end, ph.end_frame});
      }
      // Merge consecutive holds.
      std::vector<PhaseSpan> merged;
      for (const auto& sp : ph.phases) {
        if (!merged.empty() && merged.back().phase == sp.phase) {
          merged.back().end_frame = sp.end_frame;
        } else {
          merged.push_back(sp);
        }
      }
      ph.phases = std::move(merged);
      ph.apex_frame = st.apex;
      if (ph.frames() >= 3) out.push_back(std::move(ph));
    }
  }
  return out;
}

StatusOr<Phase> ParsePhase(std::string_view name) {
  if (name == "preparation") return Phase::kPreparation;
  if (name == "stroke") return Phase::kStroke;
  if (name == "hold") return Phase::kHold;
  if (name == "retraction") return Phase::kRetraction;
  return absl::InvalidArgumentError("unknown phase (preparation, stroke, hold, retraction)");
}

// Parses a manifest annotation (see phrases.h).
StatusOr<std::vector<Phrase>> ParseAnnotation(const Library& library, int clip_index) {
  const LibraryClip& lc = library.clips[static_cast<size_t>(clip_index)];
  const std::string field = kinemo::StrCat("clips[", lc.name, "].phrases");
  Json j = Json::parse(lc.annotation_json, nullptr, false);
  if (j.is_discarded() || !j.is_array()) return InvalidField(field, "must be a JSON array");
  const double dt = lc.clip.frame_time_s;
  const double len = lc.clip.duration_s();
  auto frame_of = [&](double t) { return static_cast<int>(std::lround(t / dt)); };
  auto num = [](const Json& o, const char* key, double* v) {
    auto it = o.find(key);
    if (it == o.end() || !it->is_number()) return false;
    *v = it->get<double>();
    return std::isfinite(*v);
  };
  std::vector<Phrase> out;
  double prev_end = -1;
  for (size_t i = 0; i < j.size(); ++i) {
    const std::string f = kinemo::StrCat(field, "[", i, "]");
    const Json& o = j[i];
    if (!o.is_object()) return InvalidField(f, "must be an object");
    double start = 0, end = 0;
    if (!num(o, "start_s", &start) || !num(o, "end_s", &end)) return InvalidField(f, "needs numbers start_s and end_s");
    if (!(start >= 0 && start < end && end <= len + dt)) {
      return InvalidField(f, "needs 0 <= start_s < end_s <= clip length ", len, " s");
    }
    if (start < prev_end - 1e-9) return InvalidField(f, "overlaps the previous phrase");
    prev_end = end;
    Phrase ph;
    ph.clip = clip_index;
    ph.annotated = true;
    ph.first_frame = frame_of(start);
    ph.end_frame = std::min(lc.clip.num_frames(), std::max(ph.first_frame + 1, frame_of(end)));
    auto it = o.find("phases");
    if (it == o.end() || !it->is_array() || it->empty()) return InvalidField(f + ".phases", "must be a non-empty array");
    int strokes = 0;
    double t_prev = start;
    for (size_t k = 0; k < it->size(); ++k) {
      const std::string pf = kinemo::StrCat(f, ".phases[", k, "]");
      const Json& po = (*it)[k];
      if (!po.is_object() || !po.contains("phase") || !po["phase"].is_string()) {
        return InvalidField(pf, "needs a string `phase`");
      }
      auto phase = ParsePhase(po["phase"].get<std::string>());
      if (!phase.ok()) return InvalidField(pf, phase.status().message());
      double ps = 0, pe = 0;
      if (!num(po, "start_s", &ps) || !num(po, "end_s", &pe)) return InvalidField(pf, "needs numbers start_s and end_s");
      if (ps < t_prev - 1e-6 || pe <= ps || pe > end + 1e-6) {
        return InvalidField(pf, "phases must be in order, non-empty and inside the phrase");
      }
      t_prev = pe;
      strokes += *phase == Phase::kStroke;
      const int a = std::max(ph.first_frame, frame_of(ps));
      const int b = std::min(ph.end_frame, std::max(a + 1, frame_of(pe)));
      ph.phases.push_back({*phase, a, b});
    }
    if (strokes != 1) return InvalidField(f + ".phases", "needs exactly one stroke");
    const PhaseSpan& st = ph.stroke();
    double apex = 0;
    if (num(o, "apex_s", &apex)) {
      if (apex / dt < st.first_frame - 0.5 || apex / dt > st.end_frame + 0.5) {
        return InvalidField(f + ".apex_s", "must lie in the stroke");
      }
      ph.apex_frame = apex / dt;
    } else {
      ph.apex_frame = st.end_frame - 1;
    }
    out.push_back(std::move(ph));
  }
  return out;
}

}  // namespace

std::string_view PhaseName(Phase phase) {
  switch (phase) {
    case Phase::kPreparation: return "preparation";
    case Phase::kStroke: return "stroke";
    case Phase::kHold: return "hold";
    case Phase::kRetraction: return "retraction";
  }
  return "stroke";
}

const PhaseSpan& Phrase::stroke() const {
  for (const auto& p : phases) {
    if (p.phase == Phase::kStroke) return p;
  }
  return phases.front();
}

double FmDistance(const Library& library, const LibraryClip& lc, int first, int end, double time_scale) {
  auto arms = FindArmJoints(library);
  if (!arms.ok()) return 0;
  const motion::Clip& clip = lc.clip;
  first = std::max(0, first);
  end = std::min(clip.num_frames(), end);
  if (end - first < 2) return 0;
  const double dt = clip.frame_time_s * time_scale;
  double energy = 0;
  for (auto [j, m] : arms->fm) {
    const motion::Joint& joint = clip.skeleton.joint(j);
    double sum = 0;
    Eigen::Matrix3d prev = motion::LocalRotation(joint, clip.frame(first));
    for (int f = first + 1; f < end; ++f) {
      const Eigen::Matrix3d cur = motion::LocalRotation(joint, clip.frame(f));
      const double angle_deg = Eigen::AngleAxisd(prev.transpose() * cur).angle() * 180.0 / M_PI;
      const double w = angle_deg / dt;
      sum += w * w;
      prev = cur;
    }
    energy += 0.5 * m * sum / (end - first - 1);
  }
  return std::log1p(energy);
}

StatusOr<PhraseSet> ExtractPhrases(const Library& library, const PhraseParams& params) {
  KINEMO_ASSIGN_OR_RETURN(ArmJoints arms, FindArmJoints(library));
  PhraseSet set;
  set.clip_counts.assign(library.clips.size(), 0);
  for (size_t c = 0; c < library.clips.size(); ++c) {
    std::vector<Phrase> ph;
    if (!library.clips[c].annotation_json.empty()) {
      KINEMO_ASSIGN_OR_RETURN(ph, ParseAnnotation(library, static_cast<int>(c)));
    } else {
      ph = SegmentClip(library, static_cast<int>(c), arms, params);
    }
    set.clip_counts[c] = static_cast<int>(ph.size());
    for (auto& p : ph) {
      if (static_cast<int>(set.phrases.size()) >= params.max_phrases) {
        return absl::ResourceExhaustedError(kinemo::StrCat("library: more than ", params.max_phrases, " phrases"));
      }
      const PhaseSpan& st = p.stroke();
      p.gsi_raw = FmDistance(library, library.clips[c], st.first_frame, st.end_frame);
      set.phrases.push_back(std::move(p));
    }
  }
  if (!set.phrases.empty()) {
    set.gsi_raw_min = std::numeric_limits<double>::infinity();
    set.gsi_raw_max = -std::numeric_limits<double>::infinity();
    for (const auto& p : set.phrases) {
      set.gsi_raw_min = std::min(set.gsi_raw_min, p.gsi_raw);
      set.gsi_raw_max = std::max(set.gsi_raw_max, p.gsi_raw);
    }
    const double range = set.gsi_raw_max - set.gsi_raw_min;
    for (auto& p : set.phrases) p.gsi = range > 0 ? Clamp((p.gsi_raw - set.gsi_raw_min) / range, 0, 1) : 0.5;
  }
  return set;
}

std::string PhrasesToAnnotationJson(const Library& library, const PhraseSet& set, int clip) {
  const double dt = library.clips[static_cast<size_t>(clip)].clip.frame_time_s;
  auto r = [](double v) { return std::round(v * 1000.0) / 1000.0; };
  Json arr = Json::array();
  for (const auto& p : set.phrases) {
    if (p.clip != clip) continue;
    Json o;
    o["start_s"] = r(p.first_frame * dt);
    o["end_s"] = r(p.end_frame * dt);
    o["apex_s"] = r(p.apex_frame * dt);
    Json phases = Json::array();
    for (const auto& s : p.phases) {
      phases.push_back({{"phase", std::string(PhaseName(s.phase))},
                        {"start_s", r(s.first_frame * dt)},
                        {"end_s", r(s.end_frame * dt)}});
    }
    o["phases"] = std::move(phases);
    o["gsi"] = r(p.gsi);
    arr.push_back(std::move(o));
  }
  return arr.dump();
}

}  // namespace kinemo::planner::gesture

#include "services/planner/gesture/synthesis.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>

#include "common/motion/inertialize.h"
#include "common/motion/kinematics.h"
#include "common/motion/speed_limit.h"
#include "services/planner/library/feet.h"

namespace kinemo::planner::gesture {

constexpr double kMaxSynthesisS = 7200;  // longest motion one SynthesizeGestures(Chunked) call makes (2 h)
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// How fast the incoming phrase of a blend slows into its start (s).
constexpr double kCoastS = 0.1;
// The shortest decay of a join (s). The edges' own blend lengths (0.15-0.5 s
// on BEAT2) as the decay's length gave wrist jerk GMG 94 / 78, BodySpeech
// 105 / 144 m/s³ on held-out speech (the two folds); 0.8 s gives 73 / 58 and
// 73 / 67 (the cross-fade before: 86 / 70, 91 / 112; the real takes 43 / 57).
constexpr double kMinJoinS = 0.8;
// Half the window over which a phrase's play rate changes at a knot (s).
constexpr double kRateRoundS = 0.2;

// A pose of the library: clip, fractional frame, and a horizontal root shift.
struct PoseRef {
  int clip = 0;
  double frame = 0;
  double shift_x = 0, shift_z = 0;
};

struct Piece {
  enum Kind { kPlay, kBlend, kHold } kind = kHold;
  double t0 = 0, t1 = 0;
  PoseRef a, b;  // kPlay: a (frame from the knots); kBlend: a -> b; kHold: a
  std::array<double, 5> kt{}, kf{};  // kPlay knots: output time -> source frame
  int nk = 0;
};

// A phrase's time map with its corners rounded: output time -> source frame
// through knots, piecewise linear between them, except within h of a knot,
// where the play rate moves from one segment's to the next along a
// smootherstep (so the map's first three derivatives stay continuous) and
// rejoins the straight map at the window's end. h is kRateRoundS, at most
// half of either segment. A knot where the rate jumps (a stroke played at
// its own speed between warped phases, one phrase continuing the recording
// at another rate) makes the hands jump in velocity; on held-out BEAT2
// speech the rounding takes 0.1-0.3 m/s³ off the wrists' mean jerk (the
// frame skipped at E1 joins, see Commit, was the large part: 6-8).
class TimeWarp {
 public:
  void Clear() { t_.clear(), f_.clear(); }
  // Appends a knot; one at the time of the last replaces it.
  void Add(double t, double f) {
    if (!t_.empty() && t - t_.back() < 1e-9) {
      f_.back() = f;
      return;
    }
    t_.push_back(t);
    f_.push_back(f);
  }
  double Map(double t) const {
    const size_t n = t_.size();
    if (n == 0) return 0;
    if (t <= t_[0]) return f_[0];
    if (t >= t_[n - 1]) return f_[n - 1];
    size_t i = 0;
    while (i + 2 < n && t >= t_[i + 1]) ++i;
    double f = f_[i] + Slope(i) * (t - t_[i]);
    if (i > 0) f += Corner(i, t);
    if (i + 2 < n) f += Corner(i + 1, t);
    return f;
  }

 private:
  double Slope(size_t i) const { return (f_[i + 1] - f_[i]) / (t_[i + 1] - t_[i]); }
  // The rounding at interior knot k, at time t (0 outside its window).
  double Corner(size_t k, double t) const {
    const double h = std::min({kRateRoundS, 0.5 * (t_[k] - t_[k - 1]), 0.5 * (t_[k + 1] - t_[k])});
    if (!(h > 0) || std::abs(t - t_[k]) >= h) return 0;
    const double x = (t - t_[k] + h) / (2 * h);
    // ∫ smootherstep = x⁶ − 3x⁵ + 2.5x⁴ (1/2 at x = 1: the windows' areas agree).
    const double g = x * x * x * x * (x * x - 3 * x + 2.5);
    return (Slope(k) - Slope(k - 1)) * (2 * h * g - std::max(0.0, t - t_[k]));
  }
  std::vector<double> t_, f_;
};

double Wrap180(double d) {
  while (d > 180) d -= 360;
  while (d < -180) d += 360;
  return d;
}

// Root (joint 0) horizontal position of a clip frame, in file units.
Eigen::Vector2d RootXZ(const motion::Clip& clip, int f) {
  const motion::Joint& r = clip.skeleton.joint(0);
  const auto frame = clip.frame(std::clamp(f, 0, clip.num_frames() - 1));
  const double x = r.position_column[0] >= 0 ? frame[static_cast<size_t>(r.position_column[0])] : 0.0;
  const double z = r.position_column[2] >= 0 ? frame[static_cast<size_t>(r.position_column[2])] : 0.0;
  return {x, z};
}

// Writes the channels of a PoseRef into `out` (allocation-free).
void SamplePose(const Library& lib, const PoseRef& p, std::span<double> out) {
  const motion::Clip& clip = lib.clips[static_cast<size_t>(p.clip)].clip;
  const int n = clip.num_frames();
  const double x = std::clamp(p.frame, 0.0, static_cast<double>(n - 1));
  const int f0 = static_cast<int>(std::floor(x));
  const int f1 = std::min(n - 1, f0 + 1);
  const double a = x - f0;
  const auto v0 = clip.frame(f0), v1 = clip.frame(f1);
  const auto& sk = clip.skeleton;
  for (int j = 0; j < sk.num_joints(); ++j) {
    const motion::Joint& joint = sk.joint(j);
    for (int c = 0; c < joint.num_channels(); ++c) {
      const size_t col = static_cast<size_t>(joint.first_channel + c);
      const double d = v1[col] - v0[col];
      out[col] = v0[col] + a * (motion::IsRotation(joint.channels[static_cast<size_t>(c)]) ? Wrap180(d) : d);
    }
  }
  const motion::Joint& r = sk.joint(0);
  if (r.position_column[0] >= 0) out[static_cast<size_t>(r.position_column[0])] += p.shift_x;
  if (r.position_column[2] >= 0) out[static_cast<size_t>(r.position_column[2])] += p.shift_z;
}

// Timing of one candidate phrase.
struct Timing {
  bool feasible = false;
  double warp = 1;
  double time_cost = 0;
  double gsi = 0;       // the GSI used (may be recomputed for 'only stroke')
  double gsi_raw = 0;
  std::array<double, 5> kt{}, kf{};
  int nk = 0;
};

struct Candidate {
  int node = -1;
  bool via_rest = false;
  bool early_exit = false;           // leaves the current phrase where its stroke ends
  double exit_t = 0;                 // output time of that exit
  Edge exit_edge;                    // the E2 edge from the exit pose
  const Edge* edge = nullptr;       // direct edge, or rest -> node when via rest
  const Edge* to_rest = nullptr;    // cur -> rest when via rest (null when cur is rest)
  double start_t = 0;               // output time the phrase starts
  double hold_s = 0;                // rest hold (via rest)
  Timing timing;
  double smooth = 0, intensity = 0, total = kInf;
  bool intensity_ok = false;
  bool memory_waived = false;
};

class Planner {
 public:
  Planner(const GestureGraph& g, Algorithm alg, const SynthesisParams& p)
      : g_(g), lib_(g.library()), alg_(alg), p_(p), dt_(1.0 / lib_.frame_rate_hz), stance_(lib_) {
    const int n = g.num_phrases();
    rest_in_.assign(static_cast<size_t>(n), nullptr);
    rest_out_.assign(static_cast<size_t>(n), nullptr);
    shown_until_.assign(static_cast<size_t>(n), -kInf);
    for (const Edge& e : g.out(g.rest_node())) rest_out_[static_cast<size_t>(e.to)] = &e;
    for (int m = 0; m < n; ++m) {
      if (!g.kept(m)) continue;
      for (const Edge& e : g.out(m)) {
        if (e.to == g.rest_node()) rest_in_[static_cast<size_t>(m)] = &e;
      }
    }
  }

  double BlendOf(const Edge& e) const {
    if (e.kind == EdgeKind::kConsecutive) return 0;
    return alg_ == Algorithm::kGmg ? p_.blend_s : e.blend_s;
  }

  double SmoothOf(const Edge& e) const {
    if (alg_ == Algorithm::kBodySpeech) return e.weight;
    return std::min(1.0, e.weight / g_.params().similarity_threshold);
  }

  // Fits phrase n so that its apex falls at `anchor`, starting at `start`.
  // natural = play at the original speed (via rest; `start` is then derived).
  Timing Fit(int n, double start, double anchor, bool natural) const {
    const Phrase& ph = g_.phrases()[static_cast<size_t>(n)];
    const double first = ph.first_frame, last = ph.end_frame - 1, apex = ph.apex_frame;
    const PhaseSpan& st = ph.stroke();
    Timing t;
    t.gsi_raw = ph.gsi_raw;
    t.gsi = alg_ == Algorithm::kGmg ? ph.gsi_raw : ph.gsi;
    const double lead = std::max(apex - first, 1.0) * dt_;
    const double tap = std::max(last - apex, 0.0) * dt_;
    const double tt = anchor - start;
    if (alg_ == Algorithm::kGmg) {
      if (tt < dt_) return t;
      const double w = natural ? 1.0 : tt / lead;  // (4.4)
      if (!SpeedOk(1 / w)) return t;
      const double mw = p_.max_warp;
      t.warp = w;
      if (w >= 1 && w <= mw) {
        t.time_cost = mw > 1 ? (w - 1) / (mw - 1) : 0;
      } else if (w >= 1 / mw && w < 1) {
        t.time_cost = (1 - w) / (1 - 1 / mw);
      } else {
        t.time_cost = p_.penalty;
      }
      t.kt = {start, anchor, anchor + w * tap};
      t.kf = {first, apex, last};
      t.nk = 3;
      t.feasible = true;
      return t;
    }
    // BodySpeech.
    const double pre = (st.first_frame - first) * dt_;
    if (pre >= 2 * dt_) {
      // 'Gestural phrase': the stroke keeps its speed; the other phases warp.
      const double stroke_lead = (apex - st.first_frame) * dt_;
      const double target_pre = tt - stroke_lead;
      if (target_pre < dt_) return t;
      const double w = natural ? 1.0 : pre / target_pre;  // original / target
      if (!SpeedOk(w)) return t;
      const double s_last = std::max(static_cast<double>(st.end_frame - 1), apex);
      const double post = (last - s_last) * dt_;
      t.warp = w;
      t.time_cost = (w > p_.phrase_warp_min && w < p_.phrase_warp_max)
                        ? (w - p_.phrase_warp_min) / (p_.phrase_warp_max - p_.phrase_warp_min)
                        : p_.penalty;
      if (natural) t.time_cost = (1 - p_.phrase_warp_min) / (p_.phrase_warp_max - p_.phrase_warp_min);
      const double t_stroke = start + pre / w;
      const double t_send = anchor + (s_last - apex) * dt_;
      t.kt = {start, t_stroke, anchor, t_send, t_send + post / w};
      t.kf = {first, static_cast<double>(st.first_frame), apex, s_last, last};
      t.nk = 5;
    } else {
      // 'Only stroke': the stroke itself warps, and its GSI changes.
      if (tt < dt_) return t;
      const double w = natural ? 1.0 : lead / tt;  // original / target
      if (!SpeedOk(w)) return t;
      t.warp = w;
      t.time_cost = (w > p_.stroke_warp_min && w < p_.stroke_warp_max)
                        ? (w - p_.stroke_warp_min) / (p_.stroke_warp_max - p_.stroke_warp_min)
                        : p_.penalty;
      if (natural) t.time_cost = (1 - p_.stroke_warp_min) / (p_.stroke_warp_max - p_.stroke_warp_min);
      const auto& set = g_.phrase_set();
      t.gsi_raw = std::log1p(std::expm1(ph.gsi_raw) * w * w);
      const double range = set.gsi_raw_max - set.gsi_raw_min;
      t.gsi = range > 0 ? std::clamp((t.gsi_raw - set.gsi_raw_min) / range, 0.0, 1.0) : 0.5;
      t.kt = {start, anchor, anchor + tap / w};
      t.kf = {first, apex, last};
      t.nk = 3;
    }
    t.feasible = true;
    return t;
  }

  // The hard limit on speed changes (beyond it a candidate is not played).
  bool SpeedOk(double speed) const { return speed <= p_.max_speed_change && speed >= 1 / p_.max_speed_change; }

  void Score(Candidate& c, const AccentInput& acc) {
    const Timing& t = c.timing;
    if (alg_ == Algorithm::kGmg) {
      c.intensity_ok = IntensityRuleHolds(t.gsi_raw, acc.psi);
      c.intensity = c.intensity_ok ? 0 : p_.penalty;
    } else {
      const double s = std::clamp(acc.strength + p_.gesture_emphasis, 0.0, 1.0);
      c.intensity = std::abs(s - t.gsi);
      c.intensity_ok = c.intensity <= p_.emphasis_tolerance;
    }
    c.total = c.smooth + c.intensity + t.time_cost;
    any_intensity_ok_ = any_intensity_ok_ || c.intensity_ok;
  }

  // Whether any feasible candidate of the last Best() met the intensity rule.
  bool any_intensity_ok() const { return any_intensity_ok_; }

  // Best candidate for an accent at `anchor`, from the current state: with
  // the memory and the run cap (SynthesisParams::recent_s, max_run_s), and
  // only if nothing fits so, without them.
  Candidate Best(const AccentInput& acc, double anchor) {
    remember_ = p_.recent_s > 0 || p_.max_run_s > 0;
    Candidate c = BestOf(acc, anchor);
    if (c.node < 0 && remember_) {
      remember_ = false;
      c = BestOf(acc, anchor);
      c.memory_waived = c.node >= 0;
    }
    return c;
  }

  // Ruled out by the memory: phrase n ended a play less than recent_s ago.
  bool Recent(int n, double start_t) const {
    return remember_ && p_.recent_s > 0 && start_t - shown_until_[static_cast<size_t>(n)] < p_.recent_s;
  }

  // Whether the candidate's apex leaves its blend back to rest before the
  // end of the output (Start): Finish() cuts the last phrase no earlier than
  // its apex, and a later apex ran the motion past the speech.
  bool EndsInTime(const Candidate& c) const {
    const Edge* back = rest_in_[static_cast<size_t>(c.node)];
    const double blend = back ? BlendOf(*back) : p_.blend_s;
    return MapKnotsInverse(c.timing, g_.phrases()[static_cast<size_t>(c.node)].apex_frame) + blend <= end_s_ + 1e-9;
  }

  // Whether phrase n starts where the recording left at `end_frame` goes on
  // (its E1 successor, or a stroke phrase cut from it: any edge kind).
  bool ContinuesRecording(int n, double end_frame) const {
    const Phrase& ph = g_.phrases()[static_cast<size_t>(n)];
    return cur_node_ != g_.rest_node() && ph.clip == cur_end_pose_.clip && std::abs(ph.first_frame - end_frame) <= 2.5;
  }

  // The run cap: a candidate that continues the recording may not make the
  // run of unbroken library material longer than max_run_s.
  bool OverRun(const Candidate& c, double end_frame) const {
    if (!remember_ || p_.max_run_s <= 0 || !ContinuesRecording(c.node, end_frame)) return false;
    return run_s_ + (c.timing.kt[static_cast<size_t>(c.timing.nk - 1)] - c.start_t) > p_.max_run_s;
  }

  Candidate BestOf(const AccentInput& acc, double anchor) {
    Candidate best;
    any_intensity_ok_ = false;
    const double avail = anchor - cur_end_t_;
    const int rest = g_.rest_node();
    for (const Edge& e : g_.out(cur_node_)) {
      if (e.to == rest) continue;
      Candidate c;
      c.node = e.to;
      c.edge = &e;
      c.start_t = cur_end_t_ + BlendOf(e);
      if (Recent(e.to, c.start_t)) continue;
      c.timing = Fit(e.to, c.start_t, anchor, false);
      if (!c.timing.feasible || !EndsInTime(c)) continue;
      if (OverRun(c, cur_end_pose_.frame)) continue;
      c.smooth = SmoothOf(e);
      Score(c, acc);
      if (c.total < best.total) best = c;
    }
    // Early exit: leave the current phrase where its stroke ends, toward
    // a phrase whose start pose is within the similarity threshold.
    if (cur_node_ != rest && g_.exit_frame(cur_node_) >= 0 && !pieces_.empty() &&
        pieces_.back().kind == Piece::kPlay) {
      const double exit_t = InverseKnots(pieces_.back(), g_.exit_frame(cur_node_));
      const auto& exit_pose = g_.exit_pose(cur_node_);
      for (int n = 0; n < g_.num_phrases(); ++n) {
        if (!g_.kept(n) || rest_out_[static_cast<size_t>(n)] == nullptr) continue;
        Candidate c;
        c.early_exit = true;
        c.exit_t = exit_t;
        c.node = n;
        c.exit_edge.to = n;
        c.exit_edge.kind = EdgeKind::kSimilarity;
        c.exit_edge.weight = g_.metric().Distance(exit_pose, g_.start_pose(n));
        if (c.exit_edge.weight >= g_.params().similarity_threshold) continue;
        c.exit_edge.blend_s = g_.metric().BlendLength(exit_pose, g_.start_pose(n), g_.params());
        c.start_t = exit_t + BlendOf(c.exit_edge);
        if (Recent(n, c.start_t)) continue;
        c.timing = Fit(n, c.start_t, anchor, false);
        if (!c.timing.feasible || !EndsInTime(c)) continue;
        if (OverRun(c, g_.exit_frame(cur_node_))) continue;
        c.smooth = SmoothOf(c.exit_edge);
        Score(c, acc);
        if (c.total < best.total) best = c;
      }
    }
    // Through the rest pose at natural speed.
    const Edge* to_rest = cur_node_ == rest ? nullptr : rest_in_[static_cast<size_t>(cur_node_)];
    if (cur_node_ != rest && to_rest == nullptr) return best;
    const double l1 = to_rest ? BlendOf(*to_rest) : 0;
    for (int n = 0; n < g_.num_phrases(); ++n) {
      const Edge* in = rest_out_[static_cast<size_t>(n)];
      if (in == nullptr) continue;
      const Phrase& ph = g_.phrases()[static_cast<size_t>(n)];
      const double natural_lead = (ph.apex_frame - ph.first_frame) * dt_;
      const double hold = avail - l1 - BlendOf(*in) - natural_lead;
      if (hold < 0) continue;
      Candidate c;
      c.node = n;
      c.via_rest = true;
      c.edge = in;
      c.to_rest = to_rest;
      c.hold_s = hold;
      c.start_t = cur_end_t_ + l1 + hold + BlendOf(*in);
      if (Recent(n, c.start_t)) continue;
      c.timing = Fit(n, c.start_t, anchor, true);
      if (!c.timing.feasible || !EndsInTime(c)) continue;
      if (alg_ == Algorithm::kGmg) {
        c.smooth = std::max(to_rest ? SmoothOf(*to_rest) : 0.0, SmoothOf(*in));
      } else {
        c.smooth = (to_rest ? to_rest->weight : 0.0) + in->weight;
      }
      Score(c, acc);
      if (c.total < best.total) best = c;
    }
    return best;
  }

  // The pose `node` starts with, shifted horizontally so that it stands where
  // `from_end` stands (see StanceLocator).
  PoseRef StartPose(int node, const PoseRef& from_end) {
    const Eigen::Vector2d end_stance =
        stance_.At(from_end.clip, from_end.frame) + Eigen::Vector2d(from_end.shift_x, from_end.shift_z);
    PoseRef r;
    if (node == g_.rest_node()) {
      r.clip = g_.rest_clip();
      r.frame = g_.rest_frame();
    } else {
      const Phrase& ph = g_.phrases()[static_cast<size_t>(node)];
      r.clip = ph.clip;
      r.frame = ph.first_frame;
    }
    const Eigen::Vector2d stance = stance_.At(r.clip, r.frame);
    r.shift_x = end_stance.x() - stance.x();
    r.shift_z = end_stance.y() - stance.y();
    return r;
  }

  void AddBlend(double len, const PoseRef& to) {
    if (len <= 0) return;
    Piece b;
    b.kind = Piece::kBlend;
    b.t0 = cur_end_t_;
    b.t1 = cur_end_t_ + len;
    b.a = cur_end_pose_;
    b.b = to;
    pieces_.push_back(b);
    cur_end_t_ = b.t1;
  }

  void AddHold(double len, const PoseRef& pose) {
    if (len <= 0) return;
    Piece h;
    h.kind = Piece::kHold;
    h.t0 = cur_end_t_;
    h.t1 = cur_end_t_ + len;
    h.a = pose;
    pieces_.push_back(h);
    cur_end_t_ = h.t1;
  }

  void Commit(Candidate& c) {
    const int rest = g_.rest_node();
    const bool continues =
        !c.via_rest && ContinuesRecording(c.node, c.early_exit ? g_.exit_frame(cur_node_) : cur_end_pose_.frame);
    if (c.early_exit) {
      Piece& last = pieces_.back();
      last.t1 = c.exit_t;
      cur_end_t_ = c.exit_t;
      cur_end_pose_.frame = g_.exit_frame(cur_node_);
      c.edge = &c.exit_edge;
    }
    if (c.via_rest) {
      if (c.to_rest) {
        const PoseRef rp = StartPose(rest, cur_end_pose_);
        AddBlend(BlendOf(*c.to_rest), rp);
        cur_end_pose_ = rp;
      }
      AddHold(c.hold_s, cur_end_pose_);
    }
    // E1: the recording continues; no blend, and the root keeps its course:
    // the same root shift, and the phrase's map starts at the frame shown
    // (its first frame is the next one: the map skipped a frame at once, and
    // re-anchoring the root at the first frame's stance moved it by a frame's
    // step at once, each a jerk spike at the wrists).
    const bool e1 = !c.via_rest && c.edge->kind == EdgeKind::kConsecutive;
    const PoseRef start = e1 ? cur_end_pose_ : StartPose(c.node, cur_end_pose_);
    AddBlend(BlendOf(*c.edge), start);
    Piece play;
    play.kind = Piece::kPlay;
    play.a = start;
    play.kt = c.timing.kt;
    play.kf = c.timing.kf;
    play.nk = c.timing.nk;
    if (e1 && start.frame < play.kf[0]) play.kf[0] = start.frame;
    play.t0 = play.kt[0];
    play.t1 = play.kt[static_cast<size_t>(play.nk - 1)];
    pieces_.push_back(play);
    run_s_ = (continues ? run_s_ : 0.0) + (play.t1 - play.t0);
    shown_until_[static_cast<size_t>(c.node)] = play.t1;
    cur_node_ = c.node;
    cur_end_t_ = play.t1;
    last_apex_t_ = MapKnotsInverse(c.timing, g_.phrases()[static_cast<size_t>(c.node)].apex_frame);
    cur_end_pose_ = start;
    cur_end_pose_.frame = play.kf[static_cast<size_t>(play.nk - 1)];
  }

  void Finish() {
    const double duration_s = end_s_;
    const int rest = g_.rest_node();
    if (cur_node_ != rest) {
      const Edge* e = rest_in_[static_cast<size_t>(cur_node_)];
      const double blend = e ? BlendOf(*e) : p_.blend_s;
      // Return to rest by the end of the speech: cut the last phrase's tail
      // (never before its apex) so that the blend ends at duration_s.
      if (!pieces_.empty() && pieces_.back().kind == Piece::kPlay && cur_end_t_ + blend > duration_s) {
        Piece& last = pieces_.back();
        const double cut = std::max({duration_s - blend, last_apex_t_, last.t0});
        if (cut < last.t1) {
          last.t1 = cut;
          cur_end_t_ = cut;
          cur_end_pose_.frame = MapKnots(last, cut);
        }
      }
      const PoseRef rp = StartPose(rest, cur_end_pose_);
      AddBlend(blend, rp);
      cur_end_pose_ = rp;
      cur_node_ = rest;
    }
    AddHold(std::max(duration_s - cur_end_t_, dt_), cur_end_pose_);
  }

  // Starts at rest; the output ends at end_s.
  void Start(double end_s) {
    end_s_ = end_s;
    cur_node_ = g_.rest_node();
    cur_end_t_ = 0;
    cur_end_pose_ = PoseRef{g_.rest_clip(), static_cast<double>(g_.rest_frame()), 0, 0};
    const motion::Clip& rest = lib_.clips[static_cast<size_t>(g_.rest_clip())].clip;
    cur_end_pose_.shift_x = -RootXZ(rest, g_.rest_frame()).x();
    cur_end_pose_.shift_z = -RootXZ(rest, g_.rest_frame()).y();
  }

  double cur_end_t() const { return cur_end_t_; }
  int cur_node() const { return cur_node_; }

  // The phrase coming in at blend piece i, at output time t: it comes in
  // along the frames before its start, slowing into them with a 0.1 s time
  // constant from its own rate (a frozen start pose made the hands jump to
  // speed when the phrase began).
  void Incoming(size_t i, double t, std::span<double> out) const {
    const Piece& pc = pieces_[i];
    PoseRef b = pc.b;
    b.frame -= NextPlayRate(i) * kCoastS * (1 - std::exp(-(pc.t1 - t) / kCoastS));
    SamplePose(lib_, b, out);
  }

  // Renders the pieces at the library's frame rate.
  StatusOr<motion::Clip> Render() const {
    motion::Clip out;
    out.skeleton = lib_.skeleton;
    out.frame_time_s = dt_;
    const double end = pieces_.empty() ? 0 : pieces_.back().t1;
    const int n = static_cast<int>(std::floor(end / dt_ + 1e-9)) + 1;
    const int nc = lib_.skeleton.num_channels();
    out.frames.resize(n, nc);
    std::vector<double> target(static_cast<size_t>(nc)), t1(target), t2(target), t3(target);
    // Joins are inertialized (common/motion/inertialize.h, as the Gesture
    // Controller's): at a blend piece the output switches to the incoming
    // phrase, and the difference between the motion shown and it, with its
    // velocity and acceleration, decays to zero over the blend, at least
    // kMinJoinS. The legs start their decay at rest and hang from the root
    // as if it had too (LegsAtRestInertializer): the foot planter holds the
    // feet, and a carried pelvis swing otherwise swung both legs, lifting
    // both feet 8 cm at once (BodySpeech, held-out BEAT2 speech: 63 frames
    // with the pelvis 5 cm or more under its height over the feet, none
    // before or with the legs at rest).
    std::vector<int> legs = lib_.regions.JointsIn(motion::BodyRegion::kLeftLeg);
    for (int j : lib_.regions.JointsIn(motion::BodyRegion::kRightLeg)) legs.push_back(j);
    motion::LegsAtRestInertializer join(lib_.skeleton, legs);
    const int min_join = static_cast<int>(std::lround(kMinJoinS / dt_));
    size_t pi = 0, joined = pieces_.size();
    // The time map of the run of play pieces being shown: a phrase that
    // continues the recording (E1) joins its predecessor's map, built when
    // the run's first piece comes.
    TimeWarp warp;
    size_t warp_piece = pieces_.size();
    for (int k = 0; k < n; ++k) {
      const double t = k * dt_;
      while (pi + 1 < pieces_.size() && t >= pieces_[pi].t1 - 1e-9) ++pi;
      const Piece& pc = pieces_[pi];
      std::span<double> row(out.frames.data() + static_cast<Eigen::Index>(k) * nc, static_cast<size_t>(nc));
      switch (pc.kind) {
        case Piece::kHold:
          SamplePose(lib_, pc.a, target);
          break;
        case Piece::kPlay: {
          if (pi != warp_piece && !(pi > 0 && Continues(pi - 1))) {
            warp.Clear();
            for (size_t i = pi;; ++i) {
              const Piece& q = pieces_[i];
              for (int u = 0; u < q.nk; ++u)
                if (q.kt[static_cast<size_t>(u)] < q.t1) warp.Add(q.kt[static_cast<size_t>(u)], q.kf[static_cast<size_t>(u)]);
              warp.Add(q.t1, MapKnots(q, q.t1));
              if (!Continues(i)) break;
            }
          }
          warp_piece = pi;
          PoseRef p = pc.a;
          p.frame = warp.Map(t);
          SamplePose(lib_, p, target);
          break;
        }
        case Piece::kBlend: {
          if (joined != pi) {
            joined = pi;
            Incoming(pi, t - dt_, t1);
            Incoming(pi, t - 2 * dt_, t2);
            Incoming(pi, t - 3 * dt_, t3);
            // Settled by the end of the output.
            const int blend = static_cast<int>(std::lround((pc.t1 - t) / dt_));
            const int frames = std::min(n - k, std::max(blend, min_join));
            // The last join (into the rest pose the output ends on) settles
            // from rest: carried velocity in a decay cut short by the end
            // swung the wrists at 3 m/s in the last frames.
            const bool last = pi + 2 >= pieces_.size();
            join.Start(t1, t2, t3, frames, !last);
          }
          Incoming(pi, t, target);
          break;
        }
      }
      join.Apply(target, row);
    }
    KINEMO_RETURN_IF_ERROR(out.Validate());
    return out;
  }

  // Whether play piece i+1 continues play piece i's recording (an E1 edge:
  // same clip, no blend, its first frame the one piece i ends on).
  bool Continues(size_t i) const {
    if (i + 1 >= pieces_.size()) return false;
    const Piece& a = pieces_[i];
    const Piece& b = pieces_[i + 1];
    return a.kind == Piece::kPlay && b.kind == Piece::kPlay && a.a.clip == b.a.clip &&
           std::abs(b.t0 - a.t1) < 1e-9 && std::abs(b.kf[0] - MapKnots(a, a.t1)) < 1e-6;
  }

  // Output time at which a play piece reaches source frame `f`.
  static double InverseKnots(const Piece& pc, double f) {
    Timing t;
    t.kt = pc.kt;
    t.kf = pc.kf;
    t.nk = pc.nk;
    return MapKnotsInverse(t, f);
  }

  // Output time at which the played phrase reaches source frame `f`.
  static double MapKnotsInverse(const Timing& t, double f) {
    for (int i = 1; i < t.nk; ++i) {
      const size_t u = static_cast<size_t>(i);
      if (f <= t.kf[u] + 1e-9) {
        const double span = t.kf[u] - t.kf[u - 1];
        const double a = span > 0 ? (f - t.kf[u - 1]) / span : 1.0;
        return t.kt[u - 1] + a * (t.kt[u] - t.kt[u - 1]);
      }
    }
    return t.kt[static_cast<size_t>(t.nk - 1)];
  }

  // Source frames per second of the play piece after piece i, at its start;
  // 0 when that piece holds a pose.
  double NextPlayRate(size_t i) const {
    if (i + 1 >= pieces_.size()) return 0;
    const Piece& p = pieces_[i + 1];
    if (p.kind != Piece::kPlay) return 0;
    const double h = std::min(dt_, p.t1 - p.t0);
    if (!(h > 0)) return 0;
    return (MapKnots(p, p.t0 + h) - MapKnots(p, p.t0)) / h;
  }

  static double MapKnots(const Piece& pc, double t) {
    if (t <= pc.kt[0]) return pc.kf[0];
    for (int i = 1; i < pc.nk; ++i) {
      const size_t u = static_cast<size_t>(i);
      if (t <= pc.kt[u]) {
        const double span = pc.kt[u] - pc.kt[u - 1];
        const double a = span > 0 ? (t - pc.kt[u - 1]) / span : 1.0;
        return pc.kf[u - 1] + a * (pc.kf[u] - pc.kf[u - 1]);
      }
    }
    return pc.kf[static_cast<size_t>(pc.nk - 1)];
  }

 private:
  const GestureGraph& g_;
  const Library& lib_;
  Algorithm alg_;
  SynthesisParams p_;
  double dt_;
  StanceLocator stance_;  // where poses stand (pieces are joined there)
  std::vector<const Edge*> rest_in_, rest_out_;
  int cur_node_ = -1;
  double cur_end_t_ = 0;
  double last_apex_t_ = 0;
  double end_s_ = kInf;               // the output's end (Start)
  double run_s_ = 0;                  // the current chain of consecutive phrases (output s)
  std::vector<double> shown_until_;   // per phrase: output time its last play ended
  bool remember_ = true;              // Best(): the memory and the run cap apply
  bool any_intensity_ok_ = false;
  PoseRef cur_end_pose_;
  std::vector<Piece> pieces_;
};

// The output's length: duration_s, or the last accent + 1 s.
double OutputDuration(std::span<const AccentInput> accents, const SynthesisParams& p) {
  return p.duration_s > 0 ? p.duration_s : (accents.empty() ? 1.0 : accents.back().papt_s + 1.0);
}

Status Validate(std::span<const AccentInput> accents, const SynthesisParams& p) {
  if (!(p.synchrony_min_s < p.synchrony_max_s) || !std::isfinite(p.synchrony_min_s) ||
      !std::isfinite(p.synchrony_max_s)) {
    return InvalidField("params.synchrony_min_s", "must be < synchrony_max_s");
  }
  if (!(p.max_warp >= 1) || !std::isfinite(p.max_warp)) return InvalidField("params.max_warp", "must be >= 1");
  if (!(p.penalty > 0) || !std::isfinite(p.penalty)) return InvalidField("params.penalty", "must be > 0");
  if (!(p.blend_s >= 0 && p.blend_s <= 5)) return InvalidField("params.blend_s", "must be in [0, 5] s");
  if (!(p.gesture_emphasis >= -1 && p.gesture_emphasis <= 1)) {
    return InvalidField("style.gesture_emphasis", "must be in [-1, 1]");
  }
  if (!(p.duration_s >= 0 && p.duration_s <= kMaxSynthesisS)) {
    return InvalidField("duration_s", p.duration_s, " is not in [0, ", kMaxSynthesisS, "] s");
  }
  if (!(p.max_run_s >= 0 && p.max_run_s <= 60)) return InvalidField("params.max_run_s", p.max_run_s, " is not in [0, 60] s");
  if (!(p.recent_s >= 0 && p.recent_s <= 60)) return InvalidField("params.recent_s", p.recent_s, " is not in [0, 60] s");
  if (p.feet.enabled) KINEMO_RETURN_IF_ERROR(motion::ValidateFootPlantParams(p.feet));
  if (!(p.max_speed_scale == 0 || (p.max_speed_scale >= 0.5 && p.max_speed_scale <= 10))) {
    return InvalidField("params.max_speed_scale", p.max_speed_scale, " is neither 0 nor in [0.5, 10]");
  }
  double prev = -kInf;
  for (size_t i = 0; i < accents.size(); ++i) {
    const AccentInput& a = accents[i];
    const std::string f = kinemo::StrCat("accents[", i, "]");
    if (!(a.papt_s >= 0 && a.papt_s <= kMaxSynthesisS)) return InvalidField(f + ".time_s", a.papt_s, " is not in [0, ", kMaxSynthesisS, "] s");
    if (a.papt_s < prev) return InvalidField(f + ".time_s", "accents out of time order");
    if (!(a.strength >= 0 && a.strength <= 1)) return InvalidField(f + ".strength", "must be in [0, 1]");
    if (!(a.psi >= 0) || !std::isfinite(a.psi)) return InvalidField(f + ".psi", "must be finite and >= 0");
    prev = a.papt_s;
  }
  const double duration = OutputDuration(accents, p);
  if (duration > p.max_output_s) {
    return absl::ResourceExhaustedError(
        kinemo::StrCat("duration_s: ", duration, " s is longer than the limit of ", p.max_output_s, " s"));
  }
  return absl::OkStatus();
}

}  // namespace

bool IntensityRuleHolds(double gsi_raw, double psi) {
  if (!(psi > 0)) return false;
  const double x = std::log(psi);
  return gsi_raw > 0.6633 * x + 10.24 && gsi_raw < 0.6633 * x + 12.24;
}

StatusOr<SynthesisResult> Synthesize(const GestureGraph& graph, std::span<const AccentInput> accents,
                                     Algorithm algorithm, const SynthesisParams& params) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_RETURN_IF_ERROR(Validate(accents, params));
  if (graph.rest_node() < 0) {
    return absl::FailedPreconditionError("graph_id: the graph was built without the rest-pose node");
  }
  Planner planner(graph, algorithm, params);
  planner.Start(OutputDuration(accents, params));
  std::mt19937_64 rng(params.seed == 0 ? 20141117ULL : params.seed);
  std::uniform_real_distribution<double> window(params.synchrony_min_s, params.synchrony_max_s);
  SynthesisResult result;
  int placed = 0, in_window = 0, intensity_ok = 0, possible = 0, possible_ok = 0;
  for (size_t i = 0; i < accents.size(); ++i) {
    if (i % 16 == 0) KINEMO_RETURN_IF_ERROR(CheckCancel(params.cancel, "synthesis"));
    const AccentInput& acc = accents[i];
    Placement pl;
    pl.accent_index = static_cast<int>(i);
    pl.papt_s = acc.papt_s;
    pl.psi = acc.psi;
    double ta = window(rng);
    Candidate c = planner.Best(acc, acc.papt_s - ta);
    if (c.node < 0 && ta > params.synchrony_min_s) {
      ta = params.synchrony_min_s;  // latest apex the window allows
      c = planner.Best(acc, acc.papt_s - ta);
    }
    if (c.node < 0) {
      const double avail = acc.papt_s - ta - planner.cur_end_t();
      pl.anticipation_s = ta;
      pl.skipped_reason =
          avail <= -1e-9 ? kinemo::StrCat("the previous phrase is still playing at the anchor (it ends ",
                                      std::round(-avail * 1000) / 1000, " s after it)")
                     : kinemo::StrCat("no phrase fits the ", std::round(avail * 1000) / 1000,
                                      " s before the anchor (accents closer than the shortest phrase lead)");
      result.report.push_back(std::move(pl));
      continue;
    }
    const int from = planner.cur_node();
    planner.Commit(c);
    const Phrase& ph = graph.phrases()[static_cast<size_t>(c.node)];
    pl.placed = true;
    pl.phrase = c.node;
    pl.apex_s = Planner::MapKnotsInverse(c.timing, ph.apex_frame);
    pl.anticipation_s = acc.papt_s - pl.apex_s;
    pl.gsi = c.timing.gsi;
    pl.warp = c.timing.warp;
    pl.edge_kind = c.via_rest ? EdgeKind::kRest : c.edge->kind;
    pl.early_exit = c.early_exit;
    pl.memory_waived = c.memory_waived;
    pl.from_node = c.via_rest ? graph.rest_node() : from;
    pl.to_node = c.node;
    pl.edge_weight = c.edge->weight;
    pl.edge_blend_s = planner.BlendOf(*c.edge);
    pl.smooth_cost = c.smooth;
    pl.intensity_cost = c.intensity;
    pl.time_cost = c.timing.time_cost;
    pl.intensity_ok = c.intensity_ok;
    pl.intensity_possible = planner.any_intensity_ok();
    possible += pl.intensity_possible;
    possible_ok += pl.intensity_possible && c.intensity_ok;
    ++placed;
    in_window += pl.anticipation_s >= params.synchrony_min_s - 1e-9 && pl.anticipation_s <= params.synchrony_max_s + 1e-9;
    intensity_ok += c.intensity_ok;
    result.report.push_back(std::move(pl));
  }
  KINEMO_RETURN_IF_ERROR(CheckCancel(params.cancel, "synthesis"));
  planner.Finish();
  KINEMO_ASSIGN_OR_RETURN(result.clip, planner.Render());
  result.clip.skeleton = graph.library().skeleton;
  if (params.feet.enabled) {
    // A skeleton without legs has no feet to plant; anything else is an error.
    StatusOr<motion::FootPlantParams> feet = LibraryFootPlantParams(graph.library(), params.feet);
    Status planted = feet.ok() ? motion::PlantFeet(&result.clip, graph.library().regions, *feet) : feet.status();
    if (!planted.ok() && !absl::IsFailedPrecondition(planted)) return Annotate(planted, "feet");
    result.feet_planted = planted.ok();
    result.feet_note = std::string(planted.message());
  }
  if (params.max_speed_scale > 0 && graph.upper_body() != nullptr && graph.fastest_upper_body_m_s() > 0) {
    // A skeleton without a head or hands has no upper body to limit.
    motion::SpeedLimitParams sl;
    sl.max_speed_m_s = params.max_speed_scale * graph.fastest_upper_body_m_s();
    sl.meters_per_unit = LibraryMetersPerUnit(graph.library());
    sl.cancel = params.cancel;
    KINEMO_ASSIGN_OR_RETURN(motion::SpeedLimitReport rep,
                            motion::LimitUpperBodySpeed(&result.clip, *graph.upper_body(), sl));
    result.speed_limit_m_s = sl.max_speed_m_s;
    result.speed_max_before_m_s = rep.max_before_m_s;
    result.speed_limited_frames = rep.frames_changed;
  }
  result.synchrony_rate = accents.empty() ? 1.0 : static_cast<double>(in_window) / static_cast<double>(accents.size());
  result.intensity_rule_rate = placed > 0 ? static_cast<double>(intensity_ok) / placed : 0.0;
  result.intensity_rule_rate_where_possible = possible > 0 ? static_cast<double>(possible_ok) / possible : 0.0;
  result.compute_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

}  // namespace kinemo::planner::gesture

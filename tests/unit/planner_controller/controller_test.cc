// The control layer on real Bandai motion capture with a state model fitted
// to the library's own segments: value iteration reaches the Bellman fixed
// point of Appendix A, culling never changes a decision, the policy allocates
// nothing, semantic keywords are served quickly, DP synthesis follows the
// beliefs, transitions are blended, files round-trip.
#include "services/planner/controller/controller.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <limits>
#include <map>
#include <cstdlib>
#include <new>
#include <random>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "common/gesture/kinematics.h"
#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/motion/motion_check.h"
#include "services/planner/library/feet.h"
#include "tests/unit/planner_controller/test_util.h"

// Counting replacement of the global allocator (GCC cannot see that the
// replaced new and delete match, hence the pragma).
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
}  // namespace

void* operator new(std::size_t size) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace kinemo::planner::controller {
namespace {

constexpr int kStates = 8;  // 5 gave beliefs too flat to follow once the tired takes stopped floating

struct Built {
  StateModel model;
  std::shared_ptr<const Controller> culled, full;
};

const Built& Get() {
  static const Built b = [] {
    Built x;
    x.model = testing::FitStateModel(*testing::TestLibrary(), kStates);
    ControllerParams p;
    p.tolerance = 1e-6;
    auto c = Controller::Build(testing::TestLibrary(), x.model, p, nullptr, nullptr);
    if (!c.ok()) throw std::runtime_error(std::string(c.status().message()));
    x.culled = *c;
    p.disable_culling = true;
    auto f = Controller::Build(testing::TestLibrary(), x.model, p, nullptr, nullptr);
    if (!f.ok()) throw std::runtime_error(std::string(f.status().message()));
    x.full = *f;
    return x;
  }();
  return b;
}

// Smoothed beliefs of the fitted HMM over a library clip's own segments:
// "the motion this clip shows", as spans of seconds.
// Forward-backward with the state Gaussians over segments `ys` spanning `spans` (s).
std::vector<BeliefSpan> SmoothedBeliefs(const StateModel& m, const std::vector<Vector6>& ys,
                                        const std::vector<std::pair<double, double>>& spans) {
  std::vector<BeliefSpan> out;
  const int n = static_cast<int>(ys.size()), S = m.num_states();
  Eigen::MatrixXd like(n, S), alpha(n, S), beta(n, S);
  // Likelihoods scaled per step (log-space, minus the row maximum), so that a
  // segment far from every state does not underflow to all zeros.
  for (int t = 0; t < n; ++t) {
    for (int i = 0; i < S; ++i) {
      const Vector6 d = ys[static_cast<size_t>(t)] - m.means[static_cast<size_t>(i)];
      const Matrix6& cv = m.covariances[static_cast<size_t>(i)];
      like(t, i) = -0.5 * d.dot(cv.ldlt().solve(d)) - 0.5 * std::log(cv.determinant());
    }
    like.row(t) = (like.row(t).array() - like.row(t).maxCoeff()).exp().matrix();
  }
  for (int t = 0; t < n; ++t) {
    Eigen::RowVectorXd a = t == 0 ? Eigen::RowVectorXd(m.initial.transpose()) : Eigen::RowVectorXd(alpha.row(t - 1) * m.transition);
    alpha.row(t) = a.cwiseProduct(like.row(t));
    alpha.row(t) /= alpha.row(t).sum();
  }
  beta.row(n - 1).setOnes();
  for (int t = n - 2; t >= 0; --t) {
    beta.row(t) = (m.transition * like.row(t + 1).cwiseProduct(beta.row(t + 1)).transpose()).transpose();
    beta.row(t) /= beta.row(t).sum();
  }
  for (int t = 0; t < n; ++t) {
    Eigen::RowVectorXd g = alpha.row(t).cwiseProduct(beta.row(t));
    g /= g.sum();
    BeliefSpan b;
    b.start_s = spans[static_cast<size_t>(t)].first;
    b.end_s = spans[static_cast<size_t>(t)].second;
    b.probabilities.assign(g.data(), g.data() + S);
    out.push_back(b);
  }
  return out;
}

std::vector<BeliefSpan> BeliefsOfClip(const Controller& c, const StateModel& m, int clip) {
  std::vector<Vector6> ys;
  std::vector<std::pair<double, double>> spans;
  for (const auto& s : c.segments().segments) {
    if (s.clip != clip) continue;
    ys.push_back(s.params);
    spans.emplace_back(s.first_frame * c.frame_time_s(), (s.first_frame + s.num_frames) * c.frame_time_s());
  }
  return SmoothedBeliefs(m, ys, spans);
}

// Beliefs of the motion of a clip the library does not have (held out).
std::vector<BeliefSpan> BeliefsOfHeldOutClip(const StateModel& m, const std::string& path) {
  auto clip = motion::ReadBvhFile(path);
  if (!clip.ok()) throw std::runtime_error(std::string(clip.status().message()));
  auto segs = gesture::ComputeKinematicSegments(*clip);
  if (!segs.ok()) throw std::runtime_error(std::string(segs.status().message()));
  std::vector<Vector6> ys;
  std::vector<std::pair<double, double>> spans;
  for (const auto& s : *segs) {
    ys.push_back(s.params);
    spans.emplace_back(s.start_s, s.end_s);
  }
  return SmoothedBeliefs(m, ys, spans);
}

// Mean speed of the two hands (body heights / s) and their mean distance from
// their own mean position (body heights: the gesture amplitude) in a clip.
std::pair<double, double> HandSpeedAndAmplitude(const motion::Clip& clip) {
  auto track = gesture::ComputeHandTrack(clip);
  if (!track.ok()) throw std::runtime_error(std::string(track.status().message()));
  const Eigen::VectorXd speed = gesture::MeanHandSpeed(gesture::TimeDerivative(track->p, track->dt));
  const Eigen::RowVectorXd mean = track->p.colwise().mean();
  double amplitude = 0;
  for (Eigen::Index f = 0; f < track->p.rows(); ++f) {
    const Eigen::RowVectorXd d = track->p.row(f) - mean;
    amplitude += 0.5 * (d.head(3).norm() + d.tail(3).norm());
  }
  return {speed.mean(), amplitude / static_cast<double>(track->p.rows())};
}

TEST(Controller, BuildReport) {
  const auto& c = *Get().culled;
  const BuildReport& r = c.report();
  EXPECT_NEAR(r.library_s, testing::TestLibrary()->duration_s(), 1e-9);
  EXPECT_EQ(r.segments, c.segments().num_segments());
  EXPECT_LT(r.final_change, 1e-6);
  EXPECT_GT(r.culled_fraction, 0.5);
  EXPECT_LT(r.culled_fraction, 1.0);
  EXPECT_EQ(Get().full->report().culled_fraction, 0.0);
  EXPECT_EQ(c.style_tones(), (std::vector<std::string>{"energetic", "neutral", "subdued"}));
  EXPECT_EQ(c.num_tones(), 9);  // + two gesture-emphasis tables per tone
  EXPECT_EQ(c.num_keyword_states(), 4);
}

// Appendix A: at the fixed point, U(a, i) = block cost of a's first block +
// η^L Σ_j P_L(i, j) min_actions V(·, e_0, j), and likewise for Vc.
TEST(Controller, BellmanFixedPoint) {
  const auto& c = *Get().full;
  const SegmentLibrary& L = c.segments();
  const int S = c.num_states();
  const double lambda = std::min(1.0, c.frame_time_s() / c.params().belief_step_s);
  const double eta = std::pow(c.params().discount, lambda);
  const RowMatrix& T = c.frame_transition();
  int lmax = 0;
  for (const auto& s : L.segments) lmax = std::max(lmax, s.num_frames + 1);
  std::vector<RowMatrix> pw{RowMatrix::Identity(S, S)}, cum{RowMatrix::Zero(S, S)};
  for (int l = 1; l <= lmax; ++l) {
    cum.push_back(cum.back() + std::pow(eta, l - 1) * pw.back());
    pw.push_back(pw.back() * T);
  }
  for (int m = 0; m < c.num_tones(); ++m) {
    const RowMatrix& U = c.U(m, 0);
    const RowMatrix& Vc = c.Vc(m, 0);
    double worst = 0;
    for (int e = 0; e < L.num_end_points(); ++e) {
      const auto& ep = L.end_points[static_cast<size_t>(e)];
      const int l = ep.block_in;
      Eigen::VectorXd f = Eigen::VectorXd::Constant(S, 1e300);
      if (!ep.last) f = pw[static_cast<size_t>(l)] * Vc.row(e).transpose();
      for (int b = 0; b < L.num_segments(); ++b)
        f = f.cwiseMin((L.S(e, b) + (pw[static_cast<size_t>(l)] * U.row(b).transpose()).array()).matrix());
      const auto& sa = L.segments[static_cast<size_t>(ep.segment)];
      const Eigen::VectorXd block = cum[static_cast<size_t>(l)] * c.delta(m).row(ep.segment).transpose();
      const Eigen::VectorXd want = block + std::pow(eta, l) * f;
      const Eigen::VectorXd have = ep.k == 0 ? Eigen::VectorXd(U.row(ep.segment).transpose())
                                             : Eigen::VectorXd(Vc.row(sa.first_end + ep.k - 1).transpose());
      worst = std::max(worst, (want - have).cwiseAbs().maxCoeff());
    }
    EXPECT_LT(worst, 1e-4) << "tone " << c.tones()[static_cast<size_t>(m)];
  }
}

TEST(Controller, CullingNeverChangesADecision) {
  const auto& b = Get();
  Policy culled(*b.culled), full(*b.full);
  std::mt19937_64 rng(11);
  std::gamma_distribution<double> g(0.3, 1.0);
  std::uniform_real_distribution<double> u(0, 1);
  const SegmentLibrary& L = b.culled->segments();
  int checked = 0;
  for (int trial = 0; trial < 300; ++trial) {
    // Random weights on every table (the emphasis tables too).
    std::vector<double> alpha(kStates), style(static_cast<size_t>(b.culled->num_tones()));
    for (double& a : alpha) a = g(rng) + 1e-9;
    for (double& s : style) s = u(rng) + 1e-3;
    const int kw = trial % 4 - 1;
    ASSERT_TRUE(culled.SetBelief(alpha).ok());
    ASSERT_TRUE(full.SetBelief(alpha).ok());
    ASSERT_TRUE(culled.SetStyle(style).ok());
    ASSERT_TRUE(full.SetStyle(style).ok());
    for (int e = trial % 7; e < L.num_end_points(); e += 37) {
      ASSERT_TRUE(culled.SetKeyword(kw).ok());
      ASSERT_TRUE(full.SetKeyword(kw).ok());
      const Decision a = culled.Decide(e), d = full.Decide(e);
      EXPECT_NEAR(a.expected_cost, d.expected_cost, 1e-9 * (1 + std::abs(d.expected_cost)));
      ++checked;
    }
  }
  EXPECT_GT(checked, 1000);
}

TEST(Controller, PolicyAllocatesNothing) {
  const auto& c = *Get().culled;
  Policy p(c);
  std::vector<double> alpha(kStates, 1.0 / kStates);
  auto style = StyleFromWeights(c, {{"energetic", 0.2}, {"neutral", 0.5}, {"subdued", 0.3}}, 0.4);
  ASSERT_TRUE(style.ok());
  ASSERT_TRUE(p.SetStyle(*style).ok());
  int e = 0;
  g_allocations = 0;
  g_counting = true;
  Decision d = p.Start();
  for (int step = 0; step < 2000; ++step) {
    alpha[static_cast<size_t>(step % kStates)] += 0.1;
    (void)p.SetBelief(alpha);
    p.Advance();
    if (step % 50 == 0) (void)p.SetKeyword(step % 3);
    d = p.Decide(e);
    e = d.end_point;
  }
  g_counting = false;
  EXPECT_EQ(g_allocations.load(), 0);
}

TEST(Controller, KeywordServedWithinHalfASecond) {
  const auto& b = Get();
  const auto& c = *b.culled;
  const auto beliefs = BeliefsOfClip(c, b.model, 4);  // guide_happy: no keyword of its own
  for (const std::string word : {"bye", "bow", "this"}) {
    SynthesisOptions o;
    o.keywords.push_back({word, 1.0, 1.3});
    for (bool online : {true, false}) {
      std::vector<double> us;
      auto r = online ? RunOnline(c, beliefs, o, &us) : Synthesize(c, beliefs, o);
      ASSERT_TRUE(r.ok()) << r.status();
      const SegmentPlayOut* served = nullptr;
      for (const auto& p : r->plays)
        if (p.keyword == word && p.end_s > 1.0) {
          served = &p;
          break;
        }
      ASSERT_NE(served, nullptr) << word << (online ? " online" : " offline");
      EXPECT_TRUE(c.Matches(served->segment, c.KeywordIndex(word) + 1));
      EXPECT_LE(served->start_s - 1.3, 0.5) << word << (online ? " online" : " offline");
      EXPECT_GE(served->end_s, 1.0);
    }
  }
}

TEST(Controller, SynthesisFollowsTheBeliefs) {
  // Beliefs inferred from a library clip's own motion: DP picks segments whose
  // parameters are close to that clip's, much closer than the library's
  // average segment.
  const auto& b = Get();
  const auto& c = *b.culled;
  const SegmentLibrary& L = c.segments();
  for (int clip : {0, 2, 6}) {
    const auto beliefs = BeliefsOfClip(c, b.model, clip);
    auto r = Synthesize(c, beliefs, {});
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->clip.num_frames(), static_cast<int>(std::ceil(beliefs.back().end_s / c.frame_time_s() * (1 - 1e-5))));
    double near = 0, avg = 0;
    int n = 0;
    for (const auto& p : r->plays) {
      const double mid = 0.5 * (p.start_s + p.end_s);
      const BeliefSpan* bs = &beliefs.back();
      for (const auto& x : beliefs)
        if (x.start_s <= mid && mid < x.end_s) bs = &x;
      const int src = static_cast<int>(bs - beliefs.data());
      int k = 0;
      Vector6 y = Vector6::Zero();
      for (const auto& s : L.segments)
        if (s.clip == clip && k++ == src) y = s.params;
      near += (L.segments[static_cast<size_t>(p.segment)].params - y).norm();
      for (const auto& s : L.segments) avg += (s.params - y).norm() / L.num_segments();
      ++n;
    }
    EXPECT_LT(near / n, 0.6 * avg / n) << "clip " << clip;
  }
}

// Choice, not playback, offline: the DP found one cheap segment and came
// back to it whenever it could (held-out BEAT2 speech: one segment 25 times
// in a minute, 58 % of the output). With the path's memory no segment is
// entered again within recent_s of its last frame shown; without it, on the
// five held-out Bandai clips back to back, segments come back sooner.
TEST(Controller, SynthesisDoesNotReturnToASegmentItShowedRecently) {
  const auto& b = Get();
  const auto& c = *b.culled;
  const std::string dir = std::string(KINEMO_TEST_DATA_DIR) + "/tones/";
  std::vector<BeliefSpan> beliefs;
  for (const char* f : {"dataset-1_byebye_normal_001.bvh", "dataset-1_bye_happy_001.bvh", "dataset-1_bow_angry_001.bvh",
                        "dataset-1_guide_sad_001.bvh", "dataset-1_bye_active_001.bvh"}) {
    const double t0 = beliefs.empty() ? 0.0 : beliefs.back().end_s;
    for (BeliefSpan s : BeliefsOfHeldOutClip(b.model, dir + f)) {
      s.start_s += t0;
      s.end_s += t0;
      beliefs.push_back(s);
    }
  }
  const double dt = c.frame_time_s();
  // Returns: a play entering a segment less than `memory_s` after an
  // earlier play of it ended (play times are whole frames, stored as floats).
  auto returns = [&](const SynthesisResult& r, double memory_s) {
    int n = 0;
    for (size_t j = 0; j < r.plays.size(); ++j)
      for (size_t i = 0; i < j; ++i)
        if (r.plays[i].segment == r.plays[j].segment && r.plays[j].start_s - r.plays[i].end_s < memory_s - dt - 1e-4) {
          ++n;
          break;
        }
    return n;
  };
  SynthesisOptions with, without;
  without.recent_s = 0;
  auto r = Synthesize(c, beliefs, with);
  auto free = Synthesize(c, beliefs, without);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_TRUE(free.ok()) << free.status();
  const double memory = with.recent_s;
  std::printf("%.1f s of held-out beliefs: %zu plays, %d returns within %.0f s; without the memory %zu plays, %d returns\n",
              beliefs.back().end_s, r->plays.size(), returns(*r, memory), memory, free->plays.size(),
              returns(*free, memory));
  EXPECT_EQ(returns(*r, memory), 0);
  EXPECT_GT(returns(*free, memory), 0);
  SynthesisOptions bad;
  bad.recent_s = 61;
  auto e = Synthesize(c, beliefs, bad);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.status().message().find("recent_s"), std::string::npos);
}

TEST(Controller, OnlinePlaysRunTheirMinimumBeforeAnInterruption) {
  // Greedy choices at every end point interrupted plays after a few frames,
  // and the overlapping blends damped the motion. With the minimum no run
  // (a chosen play and the true successors it continued into) without a
  // keyword is left before min_play_s; without it some are. The minimum is
  // the run's, not the segment's: a successor entered late in a run may be
  // left after a few of its own frames.
  const auto& b = Get();
  const auto& c = *b.culled;
  const SegmentLibrary& L = c.segments();
  const double dt = c.frame_time_s();
  const int min_frames = static_cast<int>(std::lround(Policy::kDefaultMinPlaySeconds / dt));
  // Frames of the run each play ends, keyed by the play's index.
  auto runs = [&](const std::vector<SegmentPlayOut>& plays) {
    std::vector<int> out(plays.size());
    for (size_t i = 0; i < plays.size(); ++i) {
      const auto& p = plays[i];
      const bool chained = i > 0 && plays[i - 1].keyword.empty() && !plays[i - 1].interrupted && p.first == 0 &&
                           L.segments[static_cast<size_t>(plays[i - 1].segment)].next == p.segment;
      out[i] = (chained ? out[i - 1] : 0) + p.last - p.first + 1;
    }
    return out;
  };
  int short_without = 0, checked = 0;
  for (int clip : {0, 2, 6}) {
    const auto beliefs = BeliefsOfClip(c, b.model, clip);
    std::vector<double> us;
    SynthesisOptions with, without;
    without.min_play_s = 0;
    auto r = RunOnline(c, beliefs, with, &us);
    auto free = RunOnline(c, beliefs, without, &us);
    ASSERT_TRUE(r.ok()) << r.status();
    ASSERT_TRUE(free.ok()) << free.status();
    const auto run = runs(r->plays);
    for (size_t i = 0; i < r->plays.size(); ++i) {
      const auto& p = r->plays[i];
      if (!p.interrupted || !p.keyword.empty()) continue;
      EXPECT_GE(run[i], min_frames) << "clip " << clip << " play at " << p.start_s << " s";
      ++checked;
    }
    const auto free_run = runs(free->plays);
    for (size_t i = 0; i < free->plays.size(); ++i)
      if (free->plays[i].interrupted && free_run[i] < min_frames) ++short_without;
  }
  EXPECT_GT(checked, 0);
  EXPECT_GT(short_without, 0);
  SynthesisOptions bad;
  bad.min_play_s = -1;
  std::vector<double> us;
  auto r = RunOnline(c, BeliefsOfClip(c, b.model, 0), bad, &us);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("min_play_s"), std::string::npos);
}

// Mean magnitude of the hands' third difference (body heights / frame³)
// over frames [first, last) of a clip (the third differences ending there).
double MeanHandJerk(const motion::Clip& clip, int first, int last) {
  auto track = gesture::ComputeHandTrack(clip);
  if (!track.ok()) throw std::runtime_error(std::string(track.status().message()));
  const Eigen::MatrixXd& p = track->p;
  double sum = 0;
  int n = 0;
  for (int f = std::max(first, 3); f < std::min<int>(last, static_cast<int>(p.rows())); ++f) {
    const Eigen::RowVectorXd j = p.row(f) - 3 * p.row(f - 1) + 3 * p.row(f - 2) - p.row(f - 3);
    sum += 0.5 * (j.head(3).norm() + j.tail(3).norm());
    ++n;
  }
  return n > 0 ? sum / n : 0.0;
}

// Mean distance the hands move from one frame to the next (body heights).
double MeanHandStep(const motion::Clip& clip) {
  auto track = gesture::ComputeHandTrack(clip);
  if (!track.ok()) throw std::runtime_error(std::string(track.status().message()));
  const Eigen::MatrixXd& p = track->p;
  double sum = 0;
  for (Eigen::Index f = 1; f < p.rows(); ++f) {
    sum += 0.5 * ((p.row(f) - p.row(f - 1)).head(3).norm() + (p.row(f) - p.row(f - 1)).tail(3).norm());
  }
  return p.rows() > 1 ? sum / static_cast<double>(p.rows() - 1) : 0.0;
}

// Clean starts: the motion leaves the rest pose as people do, the first
// segment easing in from standstill (for every clip's beliefs, offline and
// online: the first segment chosen may begin mid-stroke). Over the first
// start_s the hands jerk at most 1.5x as much as over the rest of the motion
// (before the ease: 2.0x over these runs; 0.5 s of GC on held-out BEAT2
// speech jerked 2.6x its clip), and their first step is under a fifth of the
// library's mean step (before: up to 0.9 of it).
TEST(Controller, TheMotionEasesOutOfRest) {
  const auto& b = Get();
  const auto& c = *b.culled;
  double library_step = 0;
  for (const auto& lc : c.library().clips) library_step += MeanHandStep(lc.clip);
  library_step /= static_cast<double>(c.library().clips.size());
  const int start = static_cast<int>(std::lround(SynthesisOptions{}.start_s / c.frame_time_s()));
  double start_jerk = 0, rest_jerk = 0;
  std::vector<double> us;
  for (int clip = 0; clip < static_cast<int>(c.library().clips.size()); ++clip) {
    const auto beliefs = BeliefsOfClip(c, b.model, clip);
    for (bool online : {false, true}) {
      auto r = online ? RunOnline(c, beliefs, {}, &us) : Synthesize(c, beliefs, {});
      ASSERT_TRUE(r.ok()) << r.status();
      ASSERT_GT(r->clip.num_frames(), 3 * start);
      start_jerk += MeanHandJerk(r->clip, 0, start);
      rest_jerk += MeanHandJerk(r->clip, start, r->clip.num_frames());
      auto track = gesture::ComputeHandTrack(r->clip);
      ASSERT_TRUE(track.ok());
      const Eigen::RowVectorXd first = track->p.row(1) - track->p.row(0);
      EXPECT_LT(0.5 * (first.head(3).norm() + first.tail(3).norm()), 0.2 * library_step)
          << "clip " << clip << (online ? " online" : " offline");
    }
  }
  EXPECT_LE(start_jerk, 1.5 * rest_jerk);
}

TEST(Controller, TransitionsAreBlended) {
  const auto& b = Get();
  const auto& c = *b.culled;
  for (int clip : {1, 3, 5}) {
    const auto beliefs = BeliefsOfClip(c, b.model, clip);
    std::vector<double> us;
    auto r = RunOnline(c, beliefs, {}, &us);
    ASSERT_TRUE(r.ok());
    EXPECT_LE(r->max_transition_dps, c.segments().angular_speed_max_dps) << "clip " << clip;
    // Without blending the same plays jump.
    SynthesisOptions hard;
    hard.blend_frames = 1;
    auto h = RunOnline(c, beliefs, hard, &us);
    ASSERT_TRUE(h.ok());
    EXPECT_LE(r->max_transition_dps, h->max_transition_dps);
  }
}

// The beliefs of every library clip one after the other (about 28 s).
std::vector<BeliefSpan> BeliefsOfLibrary(const Controller& c, const StateModel& m) {
  std::vector<BeliefSpan> out;
  double t0 = 0;
  for (int clip = 0; clip < static_cast<int>(c.library().clips.size()); ++clip) {
    for (BeliefSpan b : BeliefsOfClip(c, m, clip)) {
      b.start_s += t0;
      b.end_s += t0;
      out.push_back(std::move(b));
    }
    t0 = out.back().end_s;
  }
  return out;
}

// Offline DP and online runs plant the feet by default: measured with the
// code of `kinemo motion check`, the contact slide is under 3x the issue's
// target of 0.01 m/s and no contact floats more than 2 cm, where the same
// plays assembled without planting slide and float; the upper body is the
// same either way.
TEST(Controller, SynthesisPlantsTheFeet) {
  const auto& b = Get();
  const auto& c = *b.culled;
  const Library& lib = c.library();
  const auto beliefs = BeliefsOfLibrary(c, b.model);
  for (bool online : {false, true}) {
    SynthesisOptions off;
    off.feet.enabled = false;
    std::vector<double> us;
    auto planted = online ? RunOnline(c, beliefs, {}, &us) : Synthesize(c, beliefs, {});
    auto raw = online ? RunOnline(c, beliefs, off, &us) : Synthesize(c, beliefs, off);
    ASSERT_TRUE(planted.ok() && raw.ok());
    EXPECT_TRUE(planted->feet_planted);
    EXPECT_FALSE(raw->feet_planted);
    motion::MotionCheckParams mp;
    mp.contact.meters_per_unit = lib.meters_per_unit;
    auto after = motion::CheckMotion(planted->clip, lib.regions, mp, nullptr);
    auto before = motion::CheckMotion(raw->clip, lib.regions, mp, nullptr);
    ASSERT_TRUE(after.ok() && before.ok());
    EXPECT_GT(after->contact_fraction, 0.9) << "online " << online;
    EXPECT_LT(after->foot_slide_p95_m_s, 0.03) << "online " << online;
    EXPECT_LT(after->max_float_m, 0.02) << "online " << online;
    EXPECT_GT(after->min_foot_height_m, -0.005) << "online " << online;
    EXPECT_GT(before->foot_slide_p95_m_s, 3 * after->foot_slide_p95_m_s) << "online " << online;
    auto a = motion::ComputeWorldPositions(raw->clip), p = motion::ComputeWorldPositions(planted->clip);
    ASSERT_TRUE(a.ok() && p.ok());
    // Segments are joined where the body stands (StanceLocator), so even
    // unplanted the midpoint of the ankles stays near its first place,
    // although the tired takes stand 48 cm from the others (joined at joint
    // 0, it wandered 52 cm offline and 21 cm online).
    auto key = motion::FindKeyJoints(lib.skeleton, lib.regions);
    ASSERT_TRUE(key.ok());
    auto stance = [&](Eigen::Index f) {
      const Eigen::Vector3d m =
          0.5 * (a->block<1, 3>(f, 3 * key->left_foot) + a->block<1, 3>(f, 3 * key->right_foot)).transpose();
      return Eigen::Vector2d(m.x(), m.z());
    };
    double wander_m = 0;
    for (Eigen::Index f = 0; f < a->rows(); ++f) {
      wander_m = std::max(wander_m, (stance(f) - stance(0)).norm() * lib.meters_per_unit);
    }
    EXPECT_LT(wander_m, 0.1) << "online " << online;
    for (int j = 1; j < lib.skeleton.num_joints(); ++j) {
      const motion::BodyRegion r = lib.regions.region[static_cast<size_t>(j)];
      if (r == motion::BodyRegion::kLeftLeg || r == motion::BodyRegion::kRightLeg) continue;
      for (Eigen::Index f = 0; f < a->rows(); ++f) {
        const Eigen::Vector3d ra = (a->block<1, 3>(f, 3 * j) - a->block<1, 3>(f, 0)).transpose();
        const Eigen::Vector3d rp = (p->block<1, 3>(f, 3 * j) - p->block<1, 3>(f, 0)).transpose();
        ASSERT_LT((ra - rp).norm(), 1e-9) << lib.skeleton.joint(j).name << " frame " << f;
      }
    }
  }
}

// The frame stream (FrameAssembler, as the Control RPC uses it) plants frame
// by frame exactly as planting the finished clip offline does.
TEST(Controller, StreamedPlantingEqualsOfflinePlanting) {
  const auto& b = Get();
  const auto& c = *b.culled;
  const auto beliefs = BeliefsOfLibrary(c, b.model);
  SynthesisOptions off;
  off.feet.enabled = false;
  std::vector<double> us;
  auto streamed = RunOnline(c, beliefs, {}, &us);
  auto raw = RunOnline(c, beliefs, off, &us);
  ASSERT_TRUE(streamed.ok() && raw.ok());
  auto params = LibraryFootPlantParams(c.library(), motion::StandingFootPlantParams());
  ASSERT_TRUE(params.ok()) << params.status();
  motion::Clip offline = raw->clip;
  ASSERT_TRUE(motion::PlantFeet(&offline, c.library().regions, *params).ok());
  ASSERT_EQ(offline.frames.rows(), streamed->clip.frames.rows());
  EXPECT_EQ(offline.frames, streamed->clip.frames);
  EXPECT_NE(raw->clip.frames, streamed->clip.frames);
}

TEST(Controller, StyleShiftsKinematics) {
  // The energetic tone's transform moves the predicted parameters toward the
  // energetic clips'; the played segments' mean velocity V follows.
  const auto& b = Get();
  const auto& c = *b.culled;
  const SegmentLibrary& L = c.segments();
  auto mean_v = [&](const std::string& tone) {
    double v = 0, n = 0;
    for (int clip = 0; clip < 7; ++clip) {
      SynthesisOptions o;
      auto s = StyleFromWeights(c, {{tone, 1.0}});
      EXPECT_TRUE(s.ok());
      o.style = *s;
      auto r = Synthesize(c, BeliefsOfClip(c, b.model, clip), o);
      EXPECT_TRUE(r.ok());
      for (const auto& p : r->plays) {
        const double w = p.last - p.first + 1;
        v += w * L.segments[static_cast<size_t>(p.segment)].params(2);
        n += w;
      }
    }
    return v / n;
  };
  EXPECT_GT(mean_v("energetic"), mean_v("subdued"));
}

// Gesture emphasis on held-out motion: Bandai takes of tests/data/tones that
// the library does not have (their beliefs under the fitted model), played by
// the live policy (RunOnline, the path of the cube's style changes) in the
// neutral tone. The output's mean hand speed and amplitude, summed over the
// clips, are ordered e = +1 > 0 > −1 by at least kEmphasisMargin (speed) and
// e = +1 > 0 (amplitude; before the policy's memory: speed ×1.33 and ×0.29 of
// e = 0, amplitude ×1.33 and ×0.27). The other tones
// of this 7-clip library are printed, not judged: their e = +1 is not always
// faster here (docs/benchmarks.md "Tones": the bench's table on speech).
// Since the policy remembers the segments it showed (Policy::
// kDefaultRecentSeconds), e = −1 no longer holds one still stretch of the
// library (a replay) but moves among several slow segments: its hand speed
// stays lowest (measured ×0.74 of e = 0; ×1.28 for e = +1, and energetic and
// subdued are ordered too), but its hands wander among more rest poses, so
// its amplitude about their mean is not below e = 0's (0.42 vs 0.37): only
// e = +1's amplitude is judged.
constexpr double kEmphasisMargin = 1.15;

TEST(Controller, GestureEmphasisOrdersHandSpeed) {
  const auto& b = Get();
  const auto& c = *b.culled;
  const Vector6 s = c.EmphasisShift();
  EXPECT_EQ(s(0), 0.0);
  for (int j = 1; j < 6; ++j) EXPECT_GT(s(j), 0.0) << j;
  std::printf("emphasis shift (log) D %.3f V %.3f A %.3f C %.3f H %.3f\n", s(1), s(2), s(3), s(4), s(5));
  const std::string dir = std::string(KINEMO_TEST_DATA_DIR) + "/tones/";
  std::vector<std::vector<BeliefSpan>> held_out;
  for (const char* f : {"dataset-1_byebye_normal_001.bvh", "dataset-1_bye_happy_001.bvh", "dataset-1_bow_angry_001.bvh",
                        "dataset-1_guide_sad_001.bvh", "dataset-1_bye_active_001.bvh"})
    held_out.push_back(BeliefsOfHeldOutClip(b.model, dir + f));
  std::map<std::string, std::map<double, std::pair<double, double>>> m;  // tone -> e -> (speed, amplitude)
  for (const auto& tone : c.style_tones()) {
    for (double e : {-1.0, 0.0, 1.0}) {
      SynthesisOptions o;
      auto st = StyleFromWeights(c, {{tone, 1.0}}, e);
      ASSERT_TRUE(st.ok()) << st.status();
      o.style = *st;
      for (const auto& beliefs : held_out) {
        auto r = RunOnline(c, beliefs, o, nullptr);
        ASSERT_TRUE(r.ok()) << r.status();
        const auto [v, a] = HandSpeedAndAmplitude(r->clip);
        m[tone][e].first += v;
        m[tone][e].second += a;
      }
    }
    std::printf("%-10s hand speed (e = -1, 0, 1) %.3f %.3f %.3f   amplitude %.3f %.3f %.3f\n", tone.c_str(),
                m[tone][-1].first, m[tone][0].first, m[tone][1].first, m[tone][-1].second, m[tone][0].second,
                m[tone][1].second);
  }
  const auto& n = m["neutral"];
  EXPECT_GT(n.at(1).first, kEmphasisMargin * n.at(0).first);
  EXPECT_GT(n.at(0).first, kEmphasisMargin * n.at(-1).first);
  EXPECT_GT(n.at(1).second, kEmphasisMargin * n.at(0).second);
}

// The style vector of an emphasis: each tone's weight split between its own
// table and its emphasised one; bounds name style.gesture_emphasis.
TEST(Controller, GestureEmphasisStyleVector) {
  const auto& c = *Get().culled;
  const int energetic = c.ToneIndex("energetic"), neutral = c.ToneIndex("neutral");
  auto st = StyleFromWeights(c, {{"energetic", 3.0}, {"neutral", 1.0}}, 0.5);
  ASSERT_TRUE(st.ok()) << st.status();
  EXPECT_DOUBLE_EQ((*st)[static_cast<size_t>(energetic)], 0.375);
  EXPECT_DOUBLE_EQ((*st)[static_cast<size_t>(c.EmphasisIndex(energetic, 0.5))], 0.375);
  EXPECT_DOUBLE_EQ((*st)[static_cast<size_t>(neutral)], 0.125);
  EXPECT_DOUBLE_EQ((*st)[static_cast<size_t>(c.EmphasisIndex(neutral, 0.5))], 0.125);
  EXPECT_EQ(c.tones()[static_cast<size_t>(c.EmphasisIndex(neutral, -0.2))], "neutral:-");
  st = StyleFromWeights(c, {}, -1);
  ASSERT_TRUE(st.ok()) << st.status();
  EXPECT_EQ((*st)[static_cast<size_t>(neutral)], 0.0);
  EXPECT_EQ((*st)[static_cast<size_t>(c.EmphasisIndex(neutral, -1))], 1.0);
  EXPECT_EQ(*StyleFromWeights(c, {{"neutral", 1.0}}, 0), *StyleFromWeights(c, {{"neutral", 1.0}}));
  for (double bad : {1.01, -1.5, std::nan(""), std::numeric_limits<double>::infinity()}) {
    const Status s = StyleFromWeights(c, {}, bad).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(s.message().find("style.gesture_emphasis"), std::string::npos) << s;
  }
  // The emphasis tables are not tones a style may name.
  EXPECT_NE(StyleFromWeights(c, {{"neutral:+", 1.0}}).status().message().find("style.tone_weights"), std::string::npos);
  EXPECT_EQ(c.style_tones().size() * 3, c.tones().size());
}

TEST(Controller, SaveLoadRoundTrip) {
  const auto& c = *Get().culled;
  const std::string path = ::testing::TempDir() + "/ctrl_roundtrip.kctrl";
  ASSERT_TRUE(c.Save(path, {testing::DataDir() + "/manifest.json"}, "model.kmodel").ok());
  auto l = Controller::Load(path);
  ASSERT_TRUE(l.ok()) << l.status();
  EXPECT_EQ((*l)->inference_model_path(), "model.kmodel");
  EXPECT_EQ((*l)->report().entries, c.report().entries);
  Policy a(c), b(**l);
  std::vector<double> alpha(kStates);
  for (int i = 0; i < kStates; ++i) alpha[static_cast<size_t>(i)] = (1.0 + i % 3) / (2.0 * kStates);
  double total = 0;
  for (double v : alpha) total += v;
  for (double& v : alpha) v /= total;
  ASSERT_TRUE(a.SetBelief(alpha).ok());
  ASSERT_TRUE(b.SetBelief(alpha).ok());
  ASSERT_TRUE(a.SetKeyword(1).ok());
  ASSERT_TRUE(b.SetKeyword(1).ok());
  for (int e = 0; e < c.segments().num_end_points(); e += 5) {
    const Decision x = a.Decide(e), y = b.Decide(e);
    EXPECT_EQ(x.segment, y.segment);
    EXPECT_EQ(x.expected_cost, y.expected_cost);
  }
  std::remove(path.c_str());
  EXPECT_EQ(Controller::Load(path).status().code(), absl::StatusCode::kNotFound);
}

// A controller loaded on a library already loaded (the planner's stored
// version): accepted when it segments the same, whatever its sources' paths;
// refused for other clips.
TEST(Controller, LoadsOnAGivenLibraryAndRefusesOtherClips) {
  const auto& c = *Get().culled;
  const std::string path = ::testing::TempDir() + "/ctrl_given_library.kctrl";
  ASSERT_TRUE(c.Save(path, {"/nowhere/manifest.json"}).ok());
  EXPECT_FALSE(Controller::Load(path).ok());  // the recorded sources are gone
  auto same = LoadLibrary("stored", {.paths = {testing::DataDir() + "/manifest.json"}});
  ASSERT_TRUE(same.ok()) << same.status();
  auto l = Controller::Load(path, *same);
  ASSERT_TRUE(l.ok()) << l.status();
  EXPECT_EQ((*l)->library().id, "stored");
  EXPECT_EQ((*l)->segments().num_segments(), c.segments().num_segments());
  // The same clips as a folder (another order, no keyword tags): refused.
  auto other = LoadLibrary("other", {.paths = {testing::DataDir()}});
  ASSERT_TRUE(other.ok()) << other.status();
  auto refused = Controller::Load(path, *other);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition) << refused.status();
  EXPECT_NE(refused.status().message().find("library 'other'"), std::string::npos) << refused.status();
  std::remove(path.c_str());
}

// The random baseline (--policy random): whole library segments in random
// order through the same frame assembly: blended, feet planted, the same
// motion for the same seed.
TEST(Controller, RandomPolicyPlaysWholeSegments) {
  const auto& b = Get();
  const auto& c = *b.culled;
  const auto beliefs = BeliefsOfLibrary(c, b.model);
  auto r = SynthesizeRandom(c, beliefs, {}, 7);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_GT(r->plays.size(), 5u);
  EXPECT_TRUE(r->feet_planted);
  for (size_t k = 0; k + 1 < r->plays.size(); ++k) {
    const auto& p = r->plays[k];
    EXPECT_EQ(p.first, 0);
    EXPECT_EQ(p.last, c.segments().segments[static_cast<size_t>(p.segment)].num_frames - 1);
    EXPECT_NE(p.segment, r->plays[k + 1].segment);
  }
  EXPECT_LE(r->max_transition_dps, c.segments().angular_speed_max_dps);
  auto same = SynthesizeRandom(c, beliefs, {}, 7);
  auto other = SynthesizeRandom(c, beliefs, {}, 8);
  ASSERT_TRUE(same.ok() && other.ok());
  EXPECT_EQ(same->clip.frames, r->clip.frames);
  EXPECT_NE(other->clip.frames, r->clip.frames);
  EXPECT_EQ(r->clip.num_frames(), other->clip.num_frames());
  EXPECT_FALSE(SynthesizeRandom(c, {}, {}, 7).ok());
}

TEST(Controller, BadInputs) {
  const auto& b = Get();
  const auto& c = *b.culled;
  Policy p(c);
  auto st = p.SetBelief(std::vector<double>{0.5, 0.5});
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("probabilities"), std::string::npos);
  EXPECT_EQ(p.SetKeyword(7).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(StyleFromWeights(c, {{"grumpy", 1}}).status().code(), absl::StatusCode::kInvalidArgument);
  auto beliefs = BeliefsOfClip(c, b.model, 0);
  beliefs[1].probabilities[0] += 0.5;
  st = Synthesize(c, beliefs, {}).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("beliefs[1]"), std::string::npos);
  SynthesisOptions o;
  o.feet.contact.enter_speed_m_s = -1;
  st = Synthesize(c, BeliefsOfClip(c, b.model, 0), o).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("feet.contact.enter_speed_m_s"), std::string::npos) << st;
  StateModel bad = b.model;
  bad.transition(0, 0) += 0.5;
  st = Controller::Build(testing::TestLibrary(), bad, {}, nullptr, nullptr).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("transition_probabilities"), std::string::npos);
  ControllerParams pp;
  pp.discount = 1.0;
  EXPECT_EQ(Controller::Build(testing::TestLibrary(), b.model, pp, nullptr, nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);
  // Cancelling through the progress callback.
  st = Controller::Build(testing::TestLibrary(), b.model, {}, [](std::string_view, double) { return false; }, nullptr)
           .status();
  EXPECT_EQ(st.code(), absl::StatusCode::kCancelled);
}

}  // namespace
}  // namespace kinemo::planner::controller

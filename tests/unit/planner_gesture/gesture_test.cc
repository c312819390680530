// Gesture phrases, the Gesture Motion Graph, synthesis and visemes on real
// Bandai-Namco gesture clips (tests/data/planner_gesture, tests/data/motion)
// and real LibriVox speech (tests/data/speech) analysed by the prosody
// pipeline.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numeric>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "common/audio/decode.h"
#include "common/motion/kinematics.h"
#include "common/motion/speed_limit.h"
#include "common/motion/motion_check.h"
#include "common/testing/process.h"
#include "services/planner/gesture/graph.h"
#include "services/planner/gesture/phrases.h"
#include "services/planner/gesture/synthesis.h"
#include "services/planner/gesture/visemes.h"
#include "services/planner/library/library.h"
#include "services/prosody/core/pipeline.h"
#ifdef KINEMO_WITH_SPHINX
#include "services/prosody/core/recognizer.h"
#endif

namespace kinemo::planner::gesture {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;
constexpr char kSpeech[] = "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";

std::vector<std::string> ClipPaths() {
  return {kData + "/planner_gesture", kData + "/motion/dataset-1_bye_normal_001.bvh"};
}

std::shared_ptr<const Library> LoadTestLibrary() {
  LibrarySources src;
  src.paths = ClipPaths();
  auto lib = LoadLibrary("gestures", src);
  EXPECT_TRUE(lib.ok()) << lib.status();
  return lib.ok() ? std::shared_ptr<const Library>(*std::move(lib)) : nullptr;
}

struct Speech {
  std::vector<AccentInput> accents;
  std::vector<VisemeAccent> viseme_accents;
  std::vector<TimedPhone> phones;
  double duration_s = 0;
  bool recognized = false;
};

// Accents (and, with the recogniser built in and `recognize`, phones) of a
// speech file, by the prosody pipeline.
Speech AnalyseSpeech(const std::string& path, bool recognize) {
  Speech s;
  auto audio = audio::DecodeAudioFile(path);
  EXPECT_TRUE(audio.ok()) << audio.status();
  prosody::PipelineRequest req;
  prosody::SphinxRecognizer* rec = nullptr;
#ifdef KINEMO_WITH_SPHINX
  static const std::unique_ptr<prosody::SphinxRecognizer> owned = [] {
    auto created = prosody::SphinxRecognizer::Create({});
    return created.ok() ? *std::move(created) : nullptr;
  }();
  if (recognize && owned) {
    rec = owned.get();
    req.recognize = true;
  }
#endif
  auto r = prosody::RunPipeline(audio->samples, audio->sample_rate_hz, req, rec);
  EXPECT_TRUE(r.ok()) << r.status();
  s.duration_s = r->prosody.duration_s;
  for (const auto& a : r->prosody.accents) {
    s.accents.push_back({a.time_s, a.strength, a.psi});
    s.viseme_accents.push_back({a.time_s, a.strength, a.syllable_start_s, a.syllable_end_s});
  }
  for (const auto& p : r->phones) s.phones.push_back({p.phone, p.start_s, p.end_s});
  s.recognized = r->recognizer_ran;
  return s;
}

const Speech& AnalysedSpeech() {
  static const Speech speech = AnalyseSpeech(kData + kSpeech, /*recognize=*/true);
  return speech;
}

TEST(GesturePhrases, FoundInEveryGestureClipWithOrderedPhasesAndApexInStroke) {
  auto lib = LoadTestLibrary();
  ASSERT_TRUE(lib);
  auto set = ExtractPhrases(*lib);
  ASSERT_TRUE(set.ok()) << set.status();
  ASSERT_EQ(set->clip_counts.size(), lib->clips.size());
  for (size_t c = 0; c < lib->clips.size(); ++c) EXPECT_GE(set->clip_counts[c], 1) << lib->clips[c].name;
  double gmin = 1, gmax = 0;
  for (const auto& p : set->phrases) {
    ASSERT_FALSE(p.phases.empty());
    EXPECT_EQ(p.phases.front().first_frame, p.first_frame);
    EXPECT_EQ(p.phases.back().end_frame, p.end_frame);
    int strokes = 0;
    for (size_t k = 0; k < p.phases.size(); ++k) {
      EXPECT_LT(p.phases[k].first_frame, p.phases[k].end_frame);
      if (k > 0) {
        EXPECT_EQ(p.phases[k].first_frame, p.phases[k - 1].end_frame);
      }
      strokes += p.phases[k].phase == Phase::kStroke;
    }
    EXPECT_EQ(strokes, 1);
    EXPECT_GE(p.apex_frame, p.stroke().first_frame);
    EXPECT_LE(p.apex_frame, p.stroke().end_frame);
    EXPECT_GT(p.gsi_raw, 0);
    gmin = std::min(gmin, p.gsi);
    gmax = std::max(gmax, p.gsi);
  }
  EXPECT_DOUBLE_EQ(gmin, 0.0);
  EXPECT_DOUBLE_EQ(gmax, 1.0);
}

TEST(GesturePhrases, AngryByeIsStrongerThanNormalBye) {
  // FMDistance grows with the kinetic energy of the arms.
  auto lib = LoadTestLibrary();
  ASSERT_TRUE(lib);
  auto set = ExtractPhrases(*lib);
  ASSERT_TRUE(set.ok());
  std::map<std::string, double> best;
  for (const auto& p : set->phrases) {
    auto& b = best[lib->clips[static_cast<size_t>(p.clip)].name];
    b = std::max(b, p.gsi_raw);
  }
  EXPECT_GT(best["dataset-1_bye_angry_001"], best["dataset-1_bye_normal_001"]);
}

TEST(GesturePhrases, ManifestAnnotationOverridesAndIsValidated) {
  kinemo::testing::TempDir dir;
  const std::string bvh = kData + "/planner_gesture/dataset-1_guide_normal_001.bvh";
  auto write = [&](const std::string& phrases) {
    std::ofstream(dir.path() + "/m.json") << R"({"clips": [{"path": ")" << bvh << R"(", "phrases": )" << phrases
                                           << "}]}";
    LibrarySources src;
    src.paths = {dir.path() + "/m.json"};
    return LoadLibrary("m", src);
  };
  auto lib = write(R"([{"start_s": 0.5, "end_s": 2.0, "apex_s": 1.1, "phases": [
      {"phase": "preparation", "start_s": 0.5, "end_s": 0.9},
      {"phase": "stroke", "start_s": 0.9, "end_s": 1.2},
      {"phase": "retraction", "start_s": 1.2, "end_s": 2.0}]}])");
  ASSERT_TRUE(lib.ok()) << lib.status();
  auto set = ExtractPhrases(**lib);
  ASSERT_TRUE(set.ok()) << set.status();
  ASSERT_EQ(set->phrases.size(), 1u);
  const Phrase& p = set->phrases[0];
  EXPECT_TRUE(p.annotated);
  EXPECT_EQ(p.first_frame, 15);
  EXPECT_EQ(p.end_frame, 60);
  EXPECT_NEAR(p.apex_frame, 33, 1e-3);
  ASSERT_EQ(p.phases.size(), 3u);
  EXPECT_EQ(p.stroke().first_frame, 27);
  EXPECT_EQ(p.stroke().end_frame, 36);
  // An empty list means no phrases; a malformed one names the field.
  auto empty = write("[]");
  ASSERT_TRUE(empty.ok());
  EXPECT_EQ(ExtractPhrases(**empty)->phrases.size(), 0u);
  auto bad = write(R"([{"start_s": 0.5, "end_s": 2.0, "phases": [{"phase": "hold", "start_s": 0.5, "end_s": 1.0}]}])");
  ASSERT_TRUE(bad.ok());
  auto st = ExtractPhrases(**bad).status();
  EXPECT_TRUE(absl::IsInvalidArgument(st)) << st;
  EXPECT_NE(st.message().find("phrases[0].phases: needs exactly one stroke"), std::string::npos) << st;
  auto apex = write(R"([{"start_s": 0.5, "end_s": 2.0, "apex_s": 1.9, "phases": [
      {"phase": "stroke", "start_s": 0.5, "end_s": 1.0}]}])");
  ASSERT_TRUE(apex.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(ExtractPhrases(**apex).status()));
  // The automatic phrases round-trip through the annotation format.
  auto full = LoadTestLibrary();
  auto autos = ExtractPhrases(*full);
  ASSERT_TRUE(autos.ok());
  int guide = -1;
  for (size_t c = 0; c < full->clips.size(); ++c) {
    if (full->clips[c].name == "dataset-1_guide_normal_001") guide = static_cast<int>(c);
  }
  ASSERT_GE(guide, 0);
  const std::string json = PhrasesToAnnotationJson(*full, *autos, guide);
  auto again = write(json);
  ASSERT_TRUE(again.ok());
  auto reread = ExtractPhrases(**again);
  ASSERT_TRUE(reread.ok()) << reread.status() << json;
  std::vector<Phrase> expected;
  for (const auto& p : autos->phrases) {
    if (p.clip == guide) expected.push_back(p);
  }
  ASSERT_EQ(reread->phrases.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(reread->phrases[i].first_frame, expected[i].first_frame);
    EXPECT_EQ(reread->phrases[i].end_frame, expected[i].end_frame);
    EXPECT_EQ(reread->phrases[i].stroke().first_frame, expected[i].stroke().first_frame);
    EXPECT_NEAR(reread->phrases[i].apex_frame, expected[i].apex_frame, 0.05);
  }
}

TEST(GestureGraph, TarjanFindsTheLargestComponent) {
  // 0 -> 1 -> 2 -> 0 (cycle), 2 -> 3, 3 -> 4 -> 3 (cycle), 5 alone.
  std::vector<std::vector<int>> adj = {{1}, {2}, {0, 3}, {4}, {3}, {}};
  int largest = -1;
  auto comp = StronglyConnectedComponents(adj, &largest);
  EXPECT_EQ(comp[0], comp[1]);
  EXPECT_EQ(comp[1], comp[2]);
  EXPECT_EQ(comp[3], comp[4]);
  EXPECT_NE(comp[2], comp[3]);
  EXPECT_NE(comp[5], comp[0]);
  EXPECT_EQ(largest, comp[0]);
}

TEST(GestureGraph, SweepGrowsWithTheThresholdAndBuildKeepsTheScc) {
  auto lib = LoadTestLibrary();
  ASSERT_TRUE(lib);
  auto set = ExtractPhrases(*lib);
  ASSERT_TRUE(set.ok());
  const int n = static_cast<int>(set->phrases.size());
  auto rows = GestureGraph::Sweep(*lib, *set, {0.05, 0.3, 1.0, 3.0, 1e9}, {});
  ASSERT_TRUE(rows.ok()) << rows.status();
  for (size_t i = 0; i < rows->size(); ++i) {
    EXPECT_EQ((*rows)[i].size, n);
    EXPECT_LE((*rows)[i].scc_size, n);
    if (i > 0) {
      EXPECT_GE((*rows)[i].branching_factor, (*rows)[i - 1].branching_factor);
      EXPECT_GE((*rows)[i].scc_size, (*rows)[i - 1].scc_size);
    }
  }
  // With every pose similar, every phrase reaches every other.
  EXPECT_EQ(rows->back().scc_size, n);
  EXPECT_NEAR(rows->back().branching_factor, n - 1, 1e-9);
  auto g = GestureGraph::Build(lib, *set, {});
  ASSERT_TRUE(g.ok()) << g.status();
  EXPECT_EQ((*g)->stats().scc_size, (*rows)[2].scc_size);
  int kept = 0;
  for (int m = 0; m < n; ++m) {
    kept += (*g)->kept(m);
    for (const Edge& e : (*g)->out(m)) {
      EXPECT_TRUE((*g)->kept(e.to));
      if (e.kind == EdgeKind::kSimilarity) {
        EXPECT_LT(e.weight, 1.0);
        EXPECT_GE(e.blend_s, 0.1);
        EXPECT_LE(e.blend_s, 0.5);
      }
      if (e.kind == EdgeKind::kConsecutive) {
        EXPECT_EQ(e.weight, 0);
      }
    }
  }
  EXPECT_EQ(kept, (*g)->stats().scc_size);
  ASSERT_GE((*g)->rest_node(), 0);
  EXPECT_EQ(static_cast<int>((*g)->out((*g)->rest_node()).size()), kept);
  EXPECT_TRUE(absl::IsInvalidArgument(GestureGraph::Sweep(*lib, *set, {0.5, -1}, {}).status()));
  // BodySpeech §4.5.1: strokes as phrases of their own.
  GraphParams sp;
  sp.stroke_phrases = true;
  auto gs = GestureGraph::Build(lib, *set, sp);
  ASSERT_TRUE(gs.ok());
  ASSERT_GT((*gs)->num_phrases(), n);
  for (int i = n; i < (*gs)->num_phrases(); ++i) {
    const Phrase& p = (*gs)->phrases()[static_cast<size_t>(i)];
    ASSERT_EQ(p.phases.size(), 1u);
    EXPECT_EQ(p.phases[0].phase, Phase::kStroke);
    EXPECT_GE(p.apex_frame, p.first_frame);
    EXPECT_LE(p.apex_frame, p.end_frame);
  }
}

// Joint-angle difference (degrees) between two frames' rotation channels.
double MaxRotationStep(const motion::Clip& c, int a, int b) {
  double m = 0;
  for (int j = 0; j < c.skeleton.num_joints(); ++j) {
    const auto& jt = c.skeleton.joint(j);
    const Eigen::Quaterniond qa(motion::LocalRotation(jt, c.frame(a))), qb(motion::LocalRotation(jt, c.frame(b)));
    m = std::max(m, qa.angularDistance(qb) * 180 / M_PI);
  }
  return m;
}

// Foot planting (on by default) changes the legs: pose comparisons with the
// source skip them (PlantedFeet* below check the legs and the rest).
bool IsLeg(const Library& lib, int joint) {
  const motion::BodyRegion r = lib.regions.region[static_cast<size_t>(joint)];
  return r == motion::BodyRegion::kLeftLeg || r == motion::BodyRegion::kRightLeg;
}

void CheckSynthesis(Algorithm alg) {
  auto lib = LoadTestLibrary();
  ASSERT_TRUE(lib);
  auto set = ExtractPhrases(*lib);
  ASSERT_TRUE(set.ok());
  auto g = GestureGraph::Build(lib, *set, {});
  ASSERT_TRUE(g.ok());
  const Speech& sp = AnalysedSpeech();
  ASSERT_GE(sp.accents.size(), 3u);
  SynthesisParams p;
  p.duration_s = sp.duration_s;
  // Apex poses are compared with the library's to half a degree below: the
  // speed ceiling (which smooths the upper body where a hand would outpace
  // the library, Beat2HeldOutNoHandFasterThanTheLibrarys) is off here.
  p.max_speed_scale = 0;
  // A stopped token (the caller's deadline passed) ends it with its reason.
  CancelToken expired(CancelToken::Clock::now() - std::chrono::milliseconds(1));
  p.cancel = &expired;
  EXPECT_EQ(Synthesize(**g, sp.accents, alg, p).status().code(), absl::StatusCode::kDeadlineExceeded);
  p.cancel = nullptr;
  auto r = Synthesize(**g, sp.accents, alg, p);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->report.size(), sp.accents.size());
  const double dt = r->clip.frame_time_s;
  EXPECT_GE(r->clip.duration_s(), sp.duration_s - dt);
  // Back at rest by the end of the speech (unless the last apex is too late).
  EXPECT_LE(r->clip.duration_s(), sp.duration_s + 0.5 + 2 * dt);
  int placed = 0;
  for (const auto& pl : r->report) {
    if (!pl.placed) {
      EXPECT_FALSE(pl.skipped_reason.empty());
      continue;
    }
    ++placed;
    const double ta = pl.papt_s - pl.apex_s;
    EXPECT_GE(ta, p.synchrony_min_s - 1e-9);
    EXPECT_LE(ta, p.synchrony_max_s + 1e-9);
    // The output shows the phrase's apex pose at apex_s.
    const Phrase& ph = (*g)->phrases()[static_cast<size_t>(pl.phrase)];
    const motion::Clip& src = lib->clips[static_cast<size_t>(ph.clip)].clip;
    const int k = static_cast<int>(std::lround(pl.apex_s / dt));
    ASSERT_LT(k, r->clip.num_frames());
    // Output frame k lies within half a frame (played at most 2x faster) of
    // the apex: search the source around it at 1/100-frame steps.
    double best = 1e9;
    std::vector<double> lerped(static_cast<size_t>(src.skeleton.num_channels()));
    for (double x = ph.apex_frame - 1.5; x <= ph.apex_frame + 1.5; x += 0.01) {
      if (x < 0 || x > src.num_frames() - 1) continue;
      const int f0 = static_cast<int>(std::floor(x));
      const int f1 = std::min(src.num_frames() - 1, f0 + 1);
      const double a = x - f0;
      for (size_t c = 0; c < lerped.size(); ++c) {
        double d = src.frame(f1)[c] - src.frame(f0)[c];
        while (d > 180) d -= 360;
        while (d < -180) d += 360;
        lerped[c] = src.frame(f0)[c] + a * d;
      }
      double m = 0;
      for (int j = 1; j < src.skeleton.num_joints(); ++j) {
        if (IsLeg(*lib, j)) continue;
        const auto& jt = src.skeleton.joint(j);
        const Eigen::Quaterniond qa(motion::LocalRotation(jt, lerped));
        const Eigen::Quaterniond qb(motion::LocalRotation(jt, r->clip.frame(k)));
        m = std::max(m, qa.angularDistance(qb) * 180 / M_PI);
      }
      best = std::min(best, m);
    }
    EXPECT_LT(best, 0.5) << "accent " << pl.accent_index;
  }
  EXPECT_GE(placed, 2);
  EXPECT_DOUBLE_EQ(r->synchrony_rate, static_cast<double>(placed) / static_cast<double>(sp.accents.size()));
  // Continuous motion: no frame-to-frame jump larger than the fastest source.
  double src_max = 0;
  for (const auto& c : lib->clips) {
    for (int f = 1; f < c.clip.num_frames(); ++f) src_max = std::max(src_max, MaxRotationStep(c.clip, f - 1, f));
  }
  double out_max = 0;
  for (int f = 1; f < r->clip.num_frames(); ++f) out_max = std::max(out_max, MaxRotationStep(r->clip, f - 1, f));
  EXPECT_LE(out_max, 1.5 * src_max + 1.0);
  // Starts and ends at rest.
  const motion::Clip& rest = lib->clips[static_cast<size_t>((*g)->rest_clip())].clip;
  double end_diff = 0;
  for (int j = 1; j < rest.skeleton.num_joints(); ++j) {
    if (IsLeg(*lib, j)) continue;
    const auto& jt = rest.skeleton.joint(j);
    const Eigen::Quaterniond qa(motion::LocalRotation(jt, rest.frame((*g)->rest_frame())));
    const Eigen::Quaterniond qb(motion::LocalRotation(jt, r->clip.frame(r->clip.num_frames() - 1)));
    end_diff = std::max(end_diff, qa.angularDistance(qb) * 180 / M_PI);
  }
  EXPECT_LT(end_diff, 0.5);
  // Reproducible with the same seed.
  auto again = Synthesize(**g, sp.accents, alg, p);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->clip.frames, r->clip.frames);
}

TEST(GestureSynthesis, GmgPlacesApexesInTheSynchronyWindow) { CheckSynthesis(Algorithm::kGmg); }
TEST(GestureSynthesis, BodySpeechPlacesApexesInTheSynchronyWindow) { CheckSynthesis(Algorithm::kBodySpeech); }

// The same synthesis with the feet planted (the default) and without.
std::pair<StatusOr<SynthesisResult>, StatusOr<SynthesisResult>> SynthesizePlantedAndRaw(const GestureGraph& g,
                                                                                        const Speech& sp,
                                                                                        Algorithm alg,
                                                                                        SynthesisParams p = {}) {
  p.duration_s = sp.duration_s;
  auto planted = Synthesize(g, sp.accents, alg, p);
  p.feet.enabled = false;
  return {std::move(planted), Synthesize(g, sp.accents, alg, p)};
}

// GMG and BodySpeech plant the feet by default: measured with the code of
// `kinemo motion check`, the contact slide is under 3x the issue's target of
// 0.01 m/s and no contact floats more than 2 cm; without planting the same
// synthesis slides and floats. The upper body is the same either way.
void CheckPlantedFeet(Algorithm alg) {
  auto lib = LoadTestLibrary();
  ASSERT_TRUE(lib);
  auto g = GestureGraph::Build(lib, *ExtractPhrases(*lib), {});
  ASSERT_TRUE(g.ok());
  const Speech& sp = AnalysedSpeech();
  auto [planted, raw] = SynthesizePlantedAndRaw(**g, sp, alg);
  ASSERT_TRUE(planted.ok() && raw.ok());
  EXPECT_TRUE(planted->feet_planted);
  EXPECT_FALSE(raw->feet_planted);
  motion::MotionCheckParams mp;
  mp.contact.meters_per_unit = lib->meters_per_unit;
  auto after = motion::CheckMotion(planted->clip, lib->regions, mp, nullptr);
  auto before = motion::CheckMotion(raw->clip, lib->regions, mp, nullptr);
  ASSERT_TRUE(after.ok() && before.ok());
  EXPECT_GT(after->contact_fraction, 0.9);
  EXPECT_LT(after->foot_slide_p95_m_s, 0.03);
  EXPECT_LT(after->max_float_m, 0.02);
  EXPECT_GT(after->min_foot_height_m, -0.005);
  EXPECT_GT(before->foot_slide_p95_m_s, 2 * after->foot_slide_p95_m_s + 0.005);
  EXPECT_GT(before->max_float_m, 0.02);
  // Every joint outside the legs keeps its place relative to the root.
  auto a = motion::ComputeWorldPositions(raw->clip), b = motion::ComputeWorldPositions(planted->clip);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->rows(), b->rows());
  for (int j = 1; j < lib->skeleton.num_joints(); ++j) {
    if (IsLeg(*lib, j)) continue;
    for (Eigen::Index f = 0; f < a->rows(); ++f) {
      const Eigen::Vector3d ra = (a->block<1, 3>(f, 3 * j) - a->block<1, 3>(f, 0)).transpose();
      const Eigen::Vector3d rb = (b->block<1, 3>(f, 3 * j) - b->block<1, 3>(f, 0)).transpose();
      ASSERT_LT((ra - rb).norm(), 1e-9) << lib->skeleton.joint(j).name << " frame " << f;
    }
  }
}

TEST(GestureSynthesis, GmgPlantsTheFeet) { CheckPlantedFeet(Algorithm::kGmg); }
TEST(GestureSynthesis, BodySpeechPlantsTheFeet) { CheckPlantedFeet(Algorithm::kBodySpeech); }

// The bundled library (both test folders, as every deployment loads it) mixes
// Bandai takes that stand up to half a metre apart (the "tired" ones at
// z = -48 cm) while their joint 0 stays at the origin. Synthesis joins its
// pieces where the body stands, so unplanted the midpoint of the ankles stays
// near its first place (pieces joined at joint 0 glided it 48 cm, and the
// planted contacts then slid at 0.4 m/s p95); planted, the contacts meet the
// issue's target: slide p95 <= 0.01 m/s and no float over 2 cm, and no foot
// slides at any frame.
void CheckBundledLibraryFeet(Algorithm alg, bool plays_tired) {
  LibrarySources src;
  src.paths = {kData + "/planner_gesture", kData + "/planner_controller"};
  auto loaded = LoadLibrary("bundled", src);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  std::shared_ptr<const Library> lib = *std::move(loaded);
  auto g = GestureGraph::Build(lib, *ExtractPhrases(*lib), {});
  ASSERT_TRUE(g.ok()) << g.status();
  // The speech of the report (`kinemo gestures` on it slid at 0.40 m/s p95).
  static const Speech sp = AnalyseSpeech(kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav", false);
  ASSERT_FALSE(sp.accents.empty());
  // With up to 2x speed changes and 0.25 s blends (the defaults until
  // 2026-11-27) GMG plays a tired take on this speech, which showed the
  // defect; BodySpeech does not, and never slid.
  SynthesisParams old;
  old.max_speed_change = 2.0;
  old.blend_s = 0.25;
  auto [planted, raw] = SynthesizePlantedAndRaw(**g, sp, alg, old);
  ASSERT_TRUE(planted.ok() && raw.ok());
  // Whether a tired take is played.
  bool tired = false;
  for (const auto& pl : raw->report) {
    if (!pl.placed) continue;
    const int c = (*g)->phrases()[static_cast<size_t>(pl.phrase)].clip;
    tired = tired || lib->clips[static_cast<size_t>(c)].style == "tired";
  }
  EXPECT_EQ(tired, plays_tired);

  auto key = motion::FindKeyJoints(lib->skeleton, lib->regions);
  auto world = motion::ComputeWorldPositions(raw->clip);
  ASSERT_TRUE(key.ok() && world.ok());
  auto stance = [&](Eigen::Index f) {
    const Eigen::Vector3d l = world->block<1, 3>(f, 3 * key->left_foot).transpose();
    const Eigen::Vector3d r = world->block<1, 3>(f, 3 * key->right_foot).transpose();
    return Eigen::Vector2d(0.5 * (l.x() + r.x()), 0.5 * (l.z() + r.z()));
  };
  double wander_m = 0;
  for (Eigen::Index f = 0; f < world->rows(); ++f) {
    wander_m = std::max(wander_m, (stance(f) - stance(0)).norm() * lib->meters_per_unit);
  }
  EXPECT_LT(wander_m, 0.05);

  motion::MotionCheckParams mp;
  mp.contact.meters_per_unit = lib->meters_per_unit;
  auto after = motion::CheckMotion(planted->clip, lib->regions, mp, nullptr);
  ASSERT_TRUE(after.ok());
  EXPECT_GT(after->contact_fraction, 0.9);
  EXPECT_LE(after->foot_slide_p95_m_s, 0.01);
  // No foot slides at any frame: not when a blend between two stances moves
  // the animated feet faster than a step (0.75 m/s when the planter released
  // such contacts), nor when the hips move out of a locked leg's reach (9 mm/s
  // when the foot was pulled towards them rather than the body lowered).
  EXPECT_LT(after->foot_slide_max_m_s, 0.002);
  EXPECT_LT(after->max_float_m, 0.02);
  EXPECT_GT(after->min_foot_height_m, -0.005);
}

TEST(GestureSynthesis, GmgKeepsTheFeetOnTheBundledLibrary) { CheckBundledLibraryFeet(Algorithm::kGmg, true); }
TEST(GestureSynthesis, BodySpeechKeepsTheFeetOnTheBundledLibrary) { CheckBundledLibraryFeet(Algorithm::kBodySpeech, false); }

// Choice, not playback, on BEAT2 (library take 1_1, speech of take 2_2):
// the speaker rarely rests his hands, and uncut gesture units made phrases
// of up to 10 s on this take (23 s on the other) that played whole, and
// chains of recorded continuations: 43-51 % of GMG's and BodySpeech's output
// lay in near copies of the library over 2 s. Now no phrase reaches further
// than 1.5 s before or after its stroke, no phrase is entered again within 4 s
// of its last play, and no chain of recorded continuations (E1) outlasts the
// run cap by more than one phrase.
// BEAT2 held out: take 1_1's motion is the library, take 2_2's speech is
// heard (null when the library does not load).
std::shared_ptr<const Library> Beat2Library() {
  LibrarySources src;
  src.paths = {kData + "/paired/beat2/2_scott_0_1_1.bvh"};
  auto loaded = LoadLibrary("beat2", src);
  EXPECT_TRUE(loaded.ok()) << loaded.status();
  return loaded.ok() ? *std::move(loaded) : nullptr;
}
const Speech& Beat2HeldOutSpeech() {
  static const Speech sp = AnalyseSpeech(kData + "/paired/beat2/2_scott_0_2_2.wav", false);
  return sp;
}
// `alg` on the held-out speech, as long as it lasts.
StatusOr<SynthesisResult> SynthesizeHeldOut(const GestureGraph& g, Algorithm alg, SynthesisParams params = {}) {
  params.duration_s = Beat2HeldOutSpeech().duration_s;
  return Synthesize(g, Beat2HeldOutSpeech().accents, alg, params);
}

// On speech the library never heard (BEAT2 take 2_2's speech, take 1_1's
// motion), the planted feet meet the contact target of `kinemo motion check`:
// slide p95 <= 0.01 m/s. A relaxed foot the animation held still just above
// the contact height, that the lowered body put on the floor, glided along it
// with the body (GMG: 19 cm at up to 0.6 m/s, slide p95 0.017).
TEST(GestureSynthesis, Beat2HeldOutFeetDoNotGlide) {
  std::shared_ptr<const Library> lib = Beat2Library();
  ASSERT_TRUE(lib);
  auto g = GestureGraph::Build(lib, *ExtractPhrases(*lib), {});
  ASSERT_TRUE(g.ok()) << g.status();
  for (Algorithm alg : {Algorithm::kGmg, Algorithm::kBodySpeech}) {
    auto r = SynthesizeHeldOut(**g, alg);
    ASSERT_TRUE(r.ok()) << r.status();
    ASSERT_TRUE(r->feet_planted);
    motion::MotionCheckParams mp;
    mp.contact.meters_per_unit = lib->meters_per_unit;
    auto check = motion::CheckMotion(r->clip, lib->regions, mp, nullptr);
    ASSERT_TRUE(check.ok()) << check.status();
    std::printf("%s: slide p95 %.4f m/s over %d contact samples\n", alg == Algorithm::kGmg ? "GMG" : "BodySpeech",
                check->foot_slide_p95_m_s, check->contact_samples);
    EXPECT_GT(check->contact_fraction, 0.9);
    EXPECT_LE(check->foot_slide_p95_m_s, 0.01);
  }
}

// The motion begins and ends at rest with both hands down, as people do. The
// library take opens with the right hand raised to the chest (16 cm above its
// median height), and its first frame was the rest pose: every output began
// and ended with that hand up.
TEST(GestureSynthesis, Beat2HeldOutStartsAndEndsWithTheHandsDown) {
  std::shared_ptr<const Library> lib = Beat2Library();
  ASSERT_TRUE(lib);
  auto key = motion::FindKeyJoints(lib->skeleton, lib->regions);
  ASSERT_TRUE(key.ok()) << key.status();
  // A wrist's height above the lower foot.
  auto heights = [&](const motion::Clip& clip, int hand) {
    auto world = motion::ComputeWorldPositions(clip);
    EXPECT_TRUE(world.ok());
    std::vector<double> h;
    for (Eigen::Index f = 0; world.ok() && f < world->rows(); ++f)
      h.push_back((*world)(f, 3 * hand + 1) -
                  std::min((*world)(f, 3 * key->left_foot + 1), (*world)(f, 3 * key->right_foot + 1)));
    return h;
  };
  auto g = GestureGraph::Build(lib, *ExtractPhrases(*lib), {});
  ASSERT_TRUE(g.ok()) << g.status();
  for (int hand : {key->left_hand, key->right_hand}) {
    std::vector<double> library = heights(lib->clips[0].clip, hand);
    std::nth_element(library.begin(), library.begin() + static_cast<long>(library.size() / 2), library.end());
    const double median = library[library.size() / 2];
    for (Algorithm alg : {Algorithm::kGmg, Algorithm::kBodySpeech}) {
      auto r = SynthesizeHeldOut(**g, alg);
      ASSERT_TRUE(r.ok()) << r.status();
      const std::vector<double> out = heights(r->clip, hand);
      ASSERT_FALSE(out.empty());
      std::printf("%s, %s wrist: %.1f at the start, %.1f at the end, the library's median %.1f (units above the feet)\n",
                  alg == Algorithm::kGmg ? "GMG" : "BodySpeech", hand == key->left_hand ? "left" : "right",
                  out.front(), out.back(), median);
      EXPECT_LT(out.front(), median);
      EXPECT_LT(out.back(), median);
    }
  }
}

// No hand faster than the library's fastest: on held-out speech BodySpeech's
// right wrist reached 2.75 m/s (a stroke over a weight shift; `kinemo
// gestures`) where the library's fastest hand moves at 2.41 (its own scale).
// With the ceiling (SynthesisParams.max_speed_scale) neither method's head,
// elbows or wrists move faster than the library's; without it BodySpeech's
// do (here 2.44).
TEST(GestureSynthesis, Beat2HeldOutNoHandFasterThanTheLibrarys) {
  std::shared_ptr<const Library> lib = Beat2Library();
  ASSERT_TRUE(lib);
  auto upper = motion::FindUpperBodyJoints(lib->skeleton, lib->regions);
  ASSERT_TRUE(upper.ok()) << upper.status();
  const double mpu = lib->meters_per_unit > 0 ? lib->meters_per_unit : 0.01;
  const double fastest = motion::MaxUpperBodySpeed(lib->clips[0].clip, *upper, mpu);
  auto g = GestureGraph::Build(lib, *ExtractPhrases(*lib), {});
  ASSERT_TRUE(g.ok()) << g.status();
  for (Algorithm alg : {Algorithm::kGmg, Algorithm::kBodySpeech}) {
    auto r = SynthesizeHeldOut(**g, alg);
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_NEAR(r->speed_limit_m_s, fastest, 1e-9);
    EXPECT_LE(motion::MaxUpperBodySpeed(r->clip, *upper, mpu), fastest * 1.001);
  }
  SynthesisParams off;
  off.max_speed_scale = 0;
  auto free = SynthesizeHeldOut(**g, Algorithm::kBodySpeech, off);
  ASSERT_TRUE(free.ok()) << free.status();
  EXPECT_EQ(free->speed_limit_m_s, 0);
  EXPECT_GT(motion::MaxUpperBodySpeed(free->clip, *upper, mpu), fastest);
}

// Joins as smooth as the library's own motion: on held-out speech the
// wrists' mean jerk (third difference of their world positions) stays within
// 1.4x the library take's own, and so do their spikes (the 99th percentile
// over frames). The smoothstep cross-fade the joins were (both phrases
// coasting into it) gave GMG 1.5x and BodySpeech 1.7x on the mean; the
// inertialized joins 1.3x. A phrase continuing the recording (E1) skipped a
// frame at once and re-anchored the root, and the play rate jumped at every
// knot of a phrase's time map: spikes of 700-1100 m/s^3, a 99th percentile
// of 1.5x the library's (GMG and BodySpeech); now 1.2x.
TEST(GestureSynthesis, Beat2HeldOutJoinsKeepTheWristsNearTheLibrarysJerk) {
  std::shared_ptr<const Library> lib = Beat2Library();
  ASSERT_TRUE(lib);
  auto key = motion::FindKeyJoints(lib->skeleton, lib->regions);
  ASSERT_TRUE(key.ok()) << key.status();
  const double fps = lib->frame_rate_hz, m = lib->meters_per_unit;
  // Mean and 99th percentile of the wrists' jerk over frames.
  auto wrist_jerk = [&](const motion::Clip& clip) {
    auto world = motion::ComputeWorldPositions(clip);
    EXPECT_TRUE(world.ok());
    std::vector<double> j;
    for (Eigen::Index f = 3; world.ok() && f < world->rows(); ++f)
      for (int hand : {key->left_hand, key->right_hand}) {
        const auto p = [&](Eigen::Index g) { return world->block<1, 3>(g, 3 * hand).transpose().eval(); };
        j.push_back((p(f) - 3 * p(f - 1) + 3 * p(f - 2) - p(f - 3)).norm() * m * fps * fps * fps);
      }
    if (j.empty()) return std::pair<double, double>(0, 0);
    const double mean = std::accumulate(j.begin(), j.end(), 0.0) / static_cast<double>(j.size());
    auto at = j.begin() + static_cast<std::ptrdiff_t>(0.99 * static_cast<double>(j.size() - 1));
    std::nth_element(j.begin(), at, j.end());
    return std::pair<double, double>(mean, *at);
  };
  const auto [own, own_p99] = wrist_jerk(lib->clips[0].clip);
  auto g = GestureGraph::Build(lib, *ExtractPhrases(*lib), {});
  ASSERT_TRUE(g.ok()) << g.status();
  for (Algorithm alg : {Algorithm::kGmg, Algorithm::kBodySpeech}) {
    auto r = SynthesizeHeldOut(**g, alg);
    ASSERT_TRUE(r.ok()) << r.status();
    const auto [out, out_p99] = wrist_jerk(r->clip);
    std::printf("%s: wrist jerk %.1f m/s^3 (p99 %.0f), the library's own %.1f (p99 %.0f)\n",
                alg == Algorithm::kGmg ? "GMG" : "BodySpeech", out, out_p99, own, own_p99);
    EXPECT_LT(out, 1.4 * own);
    EXPECT_LT(out_p99, 1.4 * own_p99);
  }
}

TEST(GestureSynthesis, Beat2PhrasesAreCutAndNotReplayed) {
  std::shared_ptr<const Library> lib = Beat2Library();
  ASSERT_TRUE(lib);
  const PhraseParams pp;
  auto phrases = ExtractPhrases(*lib, pp);
  ASSERT_TRUE(phrases.ok()) << phrases.status();
  const double dt = 1.0 / lib->frame_rate_hz;
  double longest = 0;
  for (const Phrase& ph : phrases->phrases) {
    const PhaseSpan& st = ph.stroke();
    EXPECT_LE((st.first_frame - ph.first_frame) * dt, pp.max_preparation_s + 1e-9);
    EXPECT_LE((ph.end_frame - st.end_frame) * dt, pp.max_after_stroke_s + 1e-9);
    longest = std::max(longest, ph.frames() * dt);
  }
  auto g = GestureGraph::Build(lib, *phrases, {});
  ASSERT_TRUE(g.ok()) << g.status();
  const Speech& sp = Beat2HeldOutSpeech();
  for (Algorithm alg : {Algorithm::kGmg, Algorithm::kBodySpeech}) {
    SynthesisParams params;
    params.duration_s = sp.duration_s;
    auto r = SynthesizeHeldOut(**g, alg, params);
    ASSERT_TRUE(r.ok()) << r.status();
    // The motion ends with the speech (a last apex too late for the blend
    // back to rest once ran it 0.4 s past a recording).
    EXPECT_NEAR(r->clip.num_frames() * dt, sp.duration_s, 2 * dt + 1e-6);  // as cli_animate_long
    std::map<int, double> last_apex;  // phrase -> apex of its last placement
    int placed = 0, returns = 0, waived = 0;
    double chain = 0, longest_chain = 0;
    for (const auto& pl : r->report) {
      if (!pl.placed) continue;
      ++placed;
      const Phrase& ph = (*g)->phrases()[static_cast<size_t>(pl.phrase)];
      // A phrase's play ends after its apex and the next play of it starts
      // recent_s later, before its own apex.
      // (Unless nothing fitted the accent with the memory.)
      if (auto it = last_apex.find(pl.phrase);
          it != last_apex.end() && pl.apex_s - it->second < params.recent_s && !pl.memory_waived)
        ++returns;
      waived += pl.memory_waived;
      last_apex[pl.phrase] = pl.apex_s;
      const double recorded = ph.frames() * dt;
      chain = pl.edge_kind == EdgeKind::kConsecutive ? chain + recorded : recorded;
      longest_chain = std::max(longest_chain, chain);
    }
    std::printf("%s: %d placed (%d with the memory waived), longest phrase %.2f s, %d returns within %.0f s, longest E1 chain %.2f s (recorded)\n",
                alg == Algorithm::kGmg ? "GMG" : "BodySpeech", placed, waived, longest, returns, params.recent_s, longest_chain);
    EXPECT_GT(placed, 40);
    EXPECT_EQ(returns, 0);
    EXPECT_LE(waived, placed / 5);
    // The cap is on output time; a chain's recorded length may exceed it by
    // the last phrase and the speed limit.
    EXPECT_LE(longest_chain, params.max_speed_change * params.max_run_s + longest);
    // Without the memory phrases come back sooner.
    SynthesisParams free = params;
    free.recent_s = 0;
    free.max_run_s = 0;
    auto f = Synthesize(**g, sp.accents, alg, free);
    ASSERT_TRUE(f.ok()) << f.status();
    std::map<int, double> seen;
    int free_returns = 0;
    for (const auto& pl : f->report) {
      if (!pl.placed) continue;
      if (auto it = seen.find(pl.phrase); it != seen.end() && pl.apex_s - it->second < params.recent_s) ++free_returns;
      seen[pl.phrase] = pl.apex_s;
    }
    std::printf("  without the memory: %d returns within %.0f s\n", free_returns, params.recent_s);
    EXPECT_GT(free_returns, 0);
  }
}

TEST(GestureSynthesis, EmphasisSliderPicksStrongerOrWeakerStrokes) {
  auto lib = LoadTestLibrary();
  auto g = GestureGraph::Build(lib, *ExtractPhrases(*lib), {});
  ASSERT_TRUE(g.ok());
  const Speech& sp = AnalysedSpeech();
  // The strokes' GSI: the first placed one and the mean over those placed.
  auto gsi = [&](double slider) {
    SynthesisParams p;
    p.gesture_emphasis = slider;
    auto r = Synthesize(**g, sp.accents, Algorithm::kBodySpeech, p);
    EXPECT_TRUE(r.ok());
    double first = -1, sum = 0;
    int n = 0;
    for (const auto& pl : r->report) {
      if (!pl.placed) continue;
      if (first < 0) first = pl.gsi;
      sum += pl.gsi;
      ++n;
    }
    return std::pair<double, double>(first, n > 0 ? sum / n : -1.0);
  };
  const auto [strong_first, strong] = gsi(1.0);
  const auto [weak_first, weak] = gsi(-1.0);
  // The first accent sees the same candidates whatever the slider, so the
  // stronger slider can only pick a stroke at least as strong there; over
  // the recording its strokes are stronger (0.51 against 0.38 on this
  // speech with phrases cut 1.5 s around their strokes; with 2 s the first
  // accent alone differed).
  EXPECT_GE(weak, 0);
  EXPECT_GE(strong_first, weak_first);
  EXPECT_GT(strong, weak);
}

TEST(GestureSynthesis, RejectsBadInputNamingTheField) {
  auto lib = LoadTestLibrary();
  auto g = GestureGraph::Build(lib, *ExtractPhrases(*lib), {});
  ASSERT_TRUE(g.ok());
  std::vector<AccentInput> acc = {{1.0, 0.5, 0.1}, {0.5, 0.5, 0.1}};
  auto st = Synthesize(**g, acc, Algorithm::kGmg, {}).status();
  EXPECT_TRUE(absl::IsInvalidArgument(st));
  EXPECT_NE(st.message().find("accents[1]"), std::string::npos) << st;
  acc = {{1.0, 1.5, 0.1}};
  EXPECT_NE(Synthesize(**g, acc, Algorithm::kGmg, {}).status().message().find("accents[0].strength"),
            std::string::npos);
  SynthesisParams p;
  p.synchrony_min_s = 0.3;
  EXPECT_NE(Synthesize(**g, {}, Algorithm::kGmg, p).status().message().find("synchrony_min_s"), std::string::npos);
  p = {};
  p.feet.blend_s = -1;
  EXPECT_NE(Synthesize(**g, {}, Algorithm::kGmg, p).status().message().find("feet.blend_s"), std::string::npos);
  p = {};
  p.max_speed_scale = 0.2;  // a ceiling far under the library's own motion
  EXPECT_NE(Synthesize(**g, {}, Algorithm::kGmg, p).status().message().find("params.max_speed_scale"), std::string::npos);
  p = {};
  p.duration_s = 1e6;  // past any bound a request may carry
  st = Synthesize(**g, {}, Algorithm::kGmg, p).status();
  EXPECT_TRUE(absl::IsInvalidArgument(st)) << st;
  EXPECT_EQ(st.message().rfind("duration_s: ", 0), 0u) << st;
  p.duration_s = 1200;  // allowed, but longer than this server's max_output_s (600 s)
  EXPECT_TRUE(absl::IsResourceExhausted(Synthesize(**g, {}, Algorithm::kGmg, p).status()));
}

TEST(GestureSynthesis, IntensityRule) {
  // GSI ∈ (0.6633·ln PSI + 10.24, 0.6633·ln PSI + 12.24).
  EXPECT_TRUE(IntensityRuleHolds(11.24, 1.0));
  EXPECT_FALSE(IntensityRuleHolds(10.0, 1.0));
  EXPECT_FALSE(IntensityRuleHolds(12.5, 1.0));
  EXPECT_TRUE(IntensityRuleHolds(11.24 + 0.6633 * std::log(2.0), 2.0));
  EXPECT_FALSE(IntensityRuleHolds(11.0, 0.0));
}

TEST(Visemes, TableCategories) {
  Viseme v;
  ASSERT_TRUE(PhoneToViseme("AH", &v));
  EXPECT_EQ(v, Viseme::kAa);
  ASSERT_TRUE(PhoneToViseme("iy1", &v));
  EXPECT_EQ(v, Viseme::kAo);
  ASSERT_TRUE(PhoneToViseme("ER", &v));
  EXPECT_EQ(v, Viseme::kEy);
  ASSERT_TRUE(PhoneToViseme("M", &v));
  EXPECT_EQ(v, Viseme::kBPM);
  ASSERT_TRUE(PhoneToViseme("+NSN+", &v));
  EXPECT_EQ(v, Viseme::kPau);
  EXPECT_FALSE(PhoneToViseme("QQ", &v));
}

TEST(Visemes, TracksFromRecognisedPhonesSumToOneAndFollowThePhones) {
  const Speech& sp = AnalysedSpeech();
  if (!sp.recognized) GTEST_SKIP() << "built without the recognizer";
  ASSERT_GT(sp.phones.size(), 20u);
  VisemeParams vp;
  auto t = ComputeVisemes(sp.phones, sp.viseme_accents, vp);
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_TRUE(t->unknown_phones.empty());
  int emphatic = 0;
  for (const auto& f : t->frames) {
    double sum = 0;
    for (double w : f.weights) {
      EXPECT_GE(w, 0);
      sum += w;
    }
    EXPECT_NEAR(sum, 1.0, 1e-9);
    EXPECT_GE(f.emphasis, -1);
    EXPECT_LE(f.emphasis, 1);
    emphatic += f.emphasis != 0;
    // The dominant category is that of the phone under the frame.
    for (const auto& p : sp.phones) {
      if (f.time_s >= p.start_s && f.time_s < p.end_s) {
        Viseme v;
        PhoneToViseme(p.phone, &v);
        const auto best = std::max_element(f.weights.begin(), f.weights.end()) - f.weights.begin();
        EXPECT_GE(f.weights[static_cast<size_t>(v)], 0.5 - 1e-9) << p.phone << " at " << f.time_s;
        (void)best;
      }
    }
  }
  EXPECT_GT(emphatic, 0);
  // Face emphasis slider moves the emphasis up.
  vp.face_emphasis = 1;
  auto up = ComputeVisemes(sp.phones, sp.viseme_accents, vp);
  ASSERT_TRUE(up.ok());
  double a = 0, b = 0;
  for (size_t i = 0; i < t->frames.size(); ++i) a += t->frames[i].emphasis, b += up->frames[i].emphasis;
  EXPECT_GT(b, a);
  // JSON and CSV carry every frame.
  auto j = nlohmann::json::parse(VisemesToJson(*t));
  EXPECT_EQ(j["frames"].size(), t->frames.size());
  EXPECT_EQ(j["categories"].size(), 15u);
  const std::string csv = VisemesToCsv(*t);
  EXPECT_EQ(static_cast<size_t>(std::count(csv.begin(), csv.end(), '\n')), t->frames.size() + 1);
}

TEST(Visemes, RejectsPhonesOutOfOrder) {
  std::vector<TimedPhone> ph = {{"AH", 0.5, 0.6}, {"M", 0.2, 0.3}};
  auto st = ComputeVisemes(ph, {}, {}).status();
  EXPECT_TRUE(absl::IsInvalidArgument(st));
  EXPECT_NE(st.message().find("phones[1]"), std::string::npos) << st;
}

}  // namespace
}  // namespace kinemo::planner::gesture

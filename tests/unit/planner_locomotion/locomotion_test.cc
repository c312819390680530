// Body Part Motion Graphs on real motion capture: CMU walk / run / brisk walk
// (iClone exports, 60 fps, two skeleton variants mapped by joint name) and
// Bandai walk / run / standing clips (30 fps) for the AvatAR.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <set>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "services/planner/library/library.h"
#include "services/planner/locomotion/locomotion.h"

namespace kinemo::planner::locomotion {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR "/";

std::shared_ptr<const Library> CmuLibrary() {
  static std::shared_ptr<const Library> lib = [] {
    auto l = LoadLibrary("cmu", {.paths = {kData + "planner_locomotion/cmu_007_01.bvh", kData + "motion/cmu_002_03.bvh",
                                           kData + "motion/cmu_007_12_first40.bvh"}});
    EXPECT_TRUE(l.ok()) << l.status();
    return std::shared_ptr<const Library>(*std::move(l));
  }();
  return lib;
}

std::shared_ptr<const LocomotionData> CmuData() {
  static std::shared_ptr<const LocomotionData> data = [] {
    auto d = BuildLocomotionData(CmuLibrary(), {});
    EXPECT_TRUE(d.ok()) << d.status();
    return *d;
  }();
  return data;
}

std::shared_ptr<const LocomotionGraph> Graph(const std::string& profile, double threshold) {
  auto p = BuiltinProfile(profile);
  EXPECT_TRUE(p.ok());
  GraphParams params;
  params.threshold = threshold;
  auto g = LocomotionGraph::Build(CmuData(), *p, params);
  EXPECT_TRUE(g.ok()) << g.status();
  return *g;
}

TEST(Profiles, BuiltinsCoverEveryChainOnceAndCustomOnesAreChecked) {
  for (const auto& name : BuiltinProfileNames()) {
    auto p = BuiltinProfile(name);
    ASSERT_TRUE(p.ok()) << name;
    EXPECT_TRUE(ValidateProfile(*p).ok()) << name;
  }
  EXPECT_EQ(BuiltinProfile("SMG")->parts.size(), 1u);
  EXPECT_EQ(BuiltinProfile("SP5")->parts.size(), 5u);
  auto unknown = BuiltinProfile("SP9");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("profile.name"), std::string::npos);
  SplitProfile twice{"x", {{Chain::kLower, Chain::kHead}, {Chain::kHead, Chain::kTrunk, Chain::kUpperLeft, Chain::kUpperRight}}};
  const Status st = ValidateProfile(twice);
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("head"), std::string::npos) << st;
}

TEST(Data, JointWeightsFollowTheThesisOnTheIcloneSkeleton) {
  const auto d = CmuData();
  std::map<std::string, double> w;
  for (const auto& wj : d->weighted) w[d->library->skeleton.joint(wj.joint).name] = wj.weight;
  EXPECT_EQ(w["CC_Base_Hip"], 1.0);
  EXPECT_EQ(w["CC_Base_L_Thigh"], 1.2);
  EXPECT_EQ(w["CC_Base_R_Thigh"], 1.2);
  EXPECT_EQ(w["CC_Base_L_Calf"], 1.0);
  EXPECT_EQ(w["CC_Base_L_Upperarm"], 0.7);
  EXPECT_EQ(w["CC_Base_R_Forearm"], 0.3);
  EXPECT_EQ(w["CC_Base_Waist"], 0.3);
  EXPECT_EQ(w["CC_Base_NeckTwist01"], 0.5);
  EXPECT_EQ(w.size(), 11u);
  EXPECT_NEAR(d->chain_weight[static_cast<size_t>(Chain::kLower)], 5.4, 1e-12);
  EXPECT_NEAR(d->chain_weight[static_cast<size_t>(Chain::kUpperLeft)], 1.0, 1e-12);
  EXPECT_EQ(d->num_frames, 157 + 86 + 40);
  EXPECT_NEAR(d->fps, 60.0, 0.01);
}

TEST(Data, FootContactsShowWalkingSupportAndRunningFlight) {
  const auto d = CmuData();
  auto phases_of = [&](int clip) {
    std::map<int, int> count;
    for (int g = d->clip_begin[static_cast<size_t>(clip)]; g < d->clip_begin[static_cast<size_t>(clip) + 1]; ++g) {
      ++count[d->phase[static_cast<size_t>(g)]];
    }
    return count;
  };
  const auto walk = phases_of(0), run = phases_of(1);
  // Walking: single support on each foot.
  EXPECT_GT(walk.count(1) ? walk.at(1) : 0, 10);
  EXPECT_GT(walk.count(2) ? walk.at(2) : 0, 10);
  // Running: a flight phase (no foot in contact), more of it than walking.
  const int run_flight = run.count(0) ? run.at(0) : 0;
  const int walk_flight = walk.count(0) ? walk.at(0) : 0;
  EXPECT_GT(static_cast<double>(run_flight) / 86, static_cast<double>(walk_flight) / 157);
  // Walking forward: the root moves about 1-2 m/s.
  double travel = 0;
  for (int g = 0; g + 1 < 157; ++g) travel += d->velocity_m[static_cast<size_t>(g)].x();
  EXPECT_GT(travel / (156 / 60.0), 0.7);
  EXPECT_LT(travel / (156 / 60.0), 2.5);
}

TEST(Graph, LowerBodyEdgesKeepTheFootPhaseAndStayInTheScc) {
  const auto g = Graph("SP5", 0.15);
  const auto& d = g->data();
  ASSERT_EQ(g->parts().size(), 5u);
  EXPECT_TRUE(g->parts()[0].lower);
  double share = 0;
  for (const auto& pg : g->parts()) {
    share += pg.threshold;
    int transitions = 0;
    for (int a = 0; a < d.num_frames; ++a) {
      for (int e = pg.first_edge[static_cast<size_t>(a)]; e < pg.first_edge[static_cast<size_t>(a) + 1]; ++e) {
        const int b = pg.edge_to[static_cast<size_t>(e)];
        if (!pg.edge_transition[static_cast<size_t>(e)]) {
          EXPECT_EQ(b, a + 1);
          continue;
        }
        ++transitions;
        EXPECT_TRUE(pg.in_scc[static_cast<size_t>(a)] && pg.in_scc[static_cast<size_t>(b)]);
        EXPECT_LT(pg.edge_weight[static_cast<size_t>(e)], pg.threshold);
        if (pg.lower) {
          EXPECT_EQ(d.phase[static_cast<size_t>(a)], d.phase[static_cast<size_t>(b)]);
        }
      }
    }
    EXPECT_GT(transitions, 0);
    EXPECT_LE(pg.scc_nodes, d.num_frames);
  }
  EXPECT_NEAR(share, 0.15, 1e-12);  // the global threshold is split across the parts
  EXPECT_GE(g->connectivity(), 0.0);
  EXPECT_LE(g->connectivity(), 1.0);
}

TEST(Search, WalkToBriskWalkTransitionIsSynchronisedAsInEquation33) {
  const auto g = Graph("SP5", 0.4);
  const auto& d = g->data();
  SearchWorkspace ws;
  Transition tr;
  int ok = 0;
  for (int r = 0; r < 156; ++r) {
    const Status st = PlanTransition(*g, r, /*brisk walk*/ 2, &ws, &tr);
    if (!st.ok()) {
      EXPECT_EQ(st.code(), absl::StatusCode::kNotFound) << st;
      continue;
    }
    ++ok;
    int first_start = 1 << 30;
    for (size_t p = 0; p < tr.parts.size(); ++p) {
      const PartPath& pp = tr.parts[p];
      EXPECT_EQ(d.clip_of[static_cast<size_t>(pp.origin)], 0);
      EXPECT_EQ(d.clip_of[static_cast<size_t>(pp.target)], 2);
      EXPECT_GE(pp.origin, r);
      EXPECT_EQ(pp.path.front(), pp.origin);
      EXPECT_EQ(pp.path.back(), pp.target);
      // Every step is an edge of the part's graph.
      const PartGraph& pg = g->parts()[p];
      for (size_t k = 0; k + 1 < pp.path.size(); ++k) {
        bool edge = false;
        for (int e = pg.first_edge[static_cast<size_t>(pp.path[k])]; e < pg.first_edge[static_cast<size_t>(pp.path[k]) + 1]; ++e) {
          edge = edge || pg.edge_to[static_cast<size_t>(e)] == pp.path[k + 1];
        }
        EXPECT_TRUE(edge) << "part " << p << " step " << k;
      }
      // (3.3): (i_p - f_req) + l_p + (max J - j_p) is the same for every part.
      EXPECT_NEAR((pp.origin - r) + pp.duration + (tr.end_frame - pp.target), tr.total_frames, 1e-9);
      if (p > 0) {
        // Non-prior parts' lengths within 20 % of each other.
        for (size_t q = 1; q < tr.parts.size(); ++q) {
          EXPECT_GE(std::min(pp.length, tr.parts[q].length), 0.8 * std::max(pp.length, tr.parts[q].length) - 1e-9);
        }
        EXPECT_GE(pp.duration, 1);
        EXPECT_LE(pp.origin - tr.parts[0].origin, g->window_frames());
        EXPECT_GE(pp.target, tr.parts[0].target);
        EXPECT_LE(pp.target - tr.parts[0].target, g->window_frames());
      }
      first_start = std::min(first_start, static_cast<int>(pp.start));
    }
    EXPECT_EQ(tr.response_frames, first_start);
    EXPECT_GT(TransitionCost(*g, tr), 0);
  }
  EXPECT_GE(ok, 1);
  EXPECT_EQ(PlanTransition(*g, 5, 0, &ws, &tr).code(), absl::StatusCode::kInvalidArgument);
}

TEST(Search, SmgResponseIsTheWaitBeforeItsSinglePath) {
  const auto g = Graph("SMG", 0.4);
  SearchWorkspace ws;
  Transition tr;
  int ok = 0;
  for (int r = 0; r < 150; r += 15) {
    if (!PlanTransition(*g, r, 1, &ws, &tr).ok()) continue;
    ++ok;
    ASSERT_EQ(tr.parts.size(), 1u);
    EXPECT_EQ(tr.response_frames, tr.parts[0].origin - r);
    EXPECT_EQ(tr.total_frames, tr.response_frames + tr.parts[0].length);
    EXPECT_EQ(tr.end_frame, tr.parts[0].target);
  }
  EXPECT_GT(ok, 0);
}

TEST(Motion, TransitionStartsAtTheRequestPoseAndEndsInTheTargetClip) {
  const auto g = Graph("SP5", 0.4);
  const auto& d = g->data();
  SearchWorkspace ws;
  Transition tr;
  int r = 0;
  while (r < 156 && !PlanTransition(*g, r, 2, &ws, &tr).ok()) ++r;
  ASSERT_LT(r, 156);
  auto clip = TransitionMotion(*g, tr);
  ASSERT_TRUE(clip.ok()) << clip.status();
  ASSERT_EQ(clip->num_frames(), tr.total_frames + 1);
  const auto& lib = *d.library;
  auto src = motion::ComputeWorldPose(lib.clips[0].clip, r);
  auto out0 = motion::ComputeWorldPose(*clip, 0);
  ASSERT_TRUE(src.ok() && out0.ok());
  for (int j = 0; j < lib.skeleton.num_joints(); ++j) {
    EXPECT_LT((src->positions[static_cast<size_t>(j)] - out0->positions[static_cast<size_t>(j)]).norm(), 0.05)
        << lib.skeleton.joint(j).name;
  }
  // The last frame's pose is the target clip's end frame (up to the root's place on the surface).
  const int end = d.FrameInClip(tr.end_frame);
  auto tgt = motion::ComputeWorldPose(lib.clips[2].clip, end);
  auto last = motion::ComputeWorldPose(*clip, clip->num_frames() - 1);
  ASSERT_TRUE(tgt.ok() && last.ok());
  const int hand = lib.skeleton.FindJoint("CC_Base_L_Hand");
  const Eigen::Vector3d rel_t = tgt->rotations[static_cast<size_t>(d.hips)].transpose() *
                                (tgt->positions[static_cast<size_t>(hand)] - tgt->positions[static_cast<size_t>(d.hips)]);
  const Eigen::Vector3d rel_o = last->rotations[static_cast<size_t>(d.hips)].transpose() *
                                (last->positions[static_cast<size_t>(hand)] - last->positions[static_cast<size_t>(d.hips)]);
  EXPECT_LT((rel_t - rel_o).norm(), 0.5);  // cm
  // The root moves on smoothly: no frame-to-frame jump above 10 cm.
  auto world = motion::ComputeWorldPositions(*clip);
  ASSERT_TRUE(world.ok());
  for (int f = 1; f < clip->num_frames(); ++f) {
    const Eigen::Vector3d a((*world)(f - 1, 3 * d.hips), (*world)(f - 1, 3 * d.hips + 1), (*world)(f - 1, 3 * d.hips + 2));
    const Eigen::Vector3d b((*world)(f, 3 * d.hips), (*world)(f, 3 * d.hips + 1), (*world)(f, 3 * d.hips + 2));
    EXPECT_LT((b - a).norm() * d.meters_per_unit, 0.10) << "frame " << f;
  }
  // BVH out and back.
  auto bvh = motion::WriteBvh(*clip);
  ASSERT_TRUE(bvh.ok());
  auto back = motion::ParseBvh(*bvh, "transition");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->num_frames(), clip->num_frames());
}

// A cancelled token ends the evaluation (the planner passes the caller's
// deadline and cancellation).
TEST(Evaluate, StopsWhenItsCancelTokenStops) {
  EvaluationOptions o;
  o.profiles = {*BuiltinProfile("SMG")};
  o.thresholds = {0.2, 0.4};
  o.request_stride = 10;
  CancelToken cancelled;
  cancelled.Cancel();
  o.cancel = &cancelled;
  auto rows = Evaluate(CmuData(), o);
  EXPECT_EQ(rows.status().code(), absl::StatusCode::kCancelled) << rows.status();
  EXPECT_EQ(rows.status().message().substr(0, 11), "evaluation:");
}

TEST(Evaluate, RowsPerProfileAndThreshold) {
  EvaluationOptions o;
  o.profiles = {*BuiltinProfile("SMG"), *BuiltinProfile("SP5")};
  o.thresholds = {0.2, 0.4};
  o.request_stride = 10;
  o.maneuverability = true;
  auto rows = Evaluate(CmuData(), o);
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 4u);
  EXPECT_EQ((*rows)[0].method, "SMG");
  EXPECT_EQ((*rows)[3].method, "SP5");
  for (const auto& r : *rows) {
    EXPECT_GE(r.connected_clips, 0);
    EXPECT_LE(r.connected_clips, 3);
    EXPECT_EQ(r.maneuverability.size(), 9u);
    if (r.transitions > 0) {
      EXPECT_TRUE(std::isfinite(r.tbf_frames));
      EXPECT_GE(r.tbf_frames, r.response_frames);
      EXPECT_GE(r.response_frames, 0);
    }
  }
  // More edges at the higher threshold: at least as many frames connected.
  EXPECT_GE((*rows)[1].connectivity + 1e-12, (*rows)[0].connectivity);
  EXPECT_GT((*rows)[3].transitions, 0);
  o.request_stride = 0;
  EXPECT_EQ(Evaluate(CmuData(), o).status().code(), absl::StatusCode::kInvalidArgument);
}

// Evaluate shares work (candidates found once per part, searches shared by
// profiles and requests, several threads): its rows must be those of the
// plain way, one graph per (profile, threshold) and one PlanTransition per
// (request, target) in order, summed in that order.
TEST(Evaluate, SharedWorkGivesTheRowsOfOnePlanPerRequest) {
  EvaluationOptions o;
  o.thresholds = {0.1, 0.3};
  o.request_stride = 3;
  o.maneuverability = true;
  const auto data = CmuData();
  const int nclips = static_cast<int>(data->clip_begin.size()) - 1;
  std::vector<EvaluationRow> expected;
  for (const auto& name : BuiltinProfileNames()) {
    for (double threshold : o.thresholds) {
      GraphParams params;
      params.threshold = threshold;
      auto graph = LocomotionGraph::Build(data, *BuiltinProfile(name), params);
      ASSERT_TRUE(graph.ok()) << graph.status();
      EvaluationRow row;
      row.method = name;
      row.threshold = threshold;
      row.connected_clips = (*graph)->connected_clips();
      row.connectivity = (*graph)->connectivity();
      std::vector<double> total(static_cast<size_t>(nclips * nclips), 0), response(total.size(), 0);
      std::vector<int> count(total.size(), 0);
      double cost = 0;
      int attempts = 0, ok = 0;
      SearchWorkspace ws;
      Transition tr;
      for (int c = 0; c < nclips; ++c) {
        for (int g = data->clip_begin[static_cast<size_t>(c)]; g + 1 < data->clip_begin[static_cast<size_t>(c) + 1];
             g += o.request_stride) {
          for (int t = 0; t < nclips; ++t) {
            if (t == c) continue;
            ++attempts;
            if (!PlanTransition(**graph, g, t, &ws, &tr).ok()) continue;
            const size_t cell = static_cast<size_t>(c * nclips + t);
            total[cell] += tr.total_frames;
            response[cell] += tr.response_frames;
            ++count[cell];
            ++ok;
            cost += TransitionCost(**graph, tr);
          }
        }
      }
      double all_total = 0, all_response = 0;
      for (size_t k = 0; k < total.size(); ++k) {
        all_total += total[k];
        all_response += response[k];
        row.maneuverability.push_back(count[k] ? total[k] / count[k] : std::nan(""));
      }
      row.transitions = ok;
      row.success_rate = static_cast<double>(ok) / attempts;
      row.tbf_frames = all_total / ok;
      row.response_frames = all_response / ok;
      row.cost = cost / ok;
      expected.push_back(row);
    }
  }
  for (int threads : {1, 3}) {
    o.threads = threads;
    auto rows = Evaluate(data, o);
    ASSERT_TRUE(rows.ok()) << rows.status();
    ASSERT_EQ(rows->size(), expected.size());
    for (size_t i = 0; i < expected.size(); ++i) {
      const EvaluationRow& a = expected[i];
      const EvaluationRow& b = (*rows)[i];
      const std::string what = a.method + " " + std::to_string(a.threshold) + ", threads " + std::to_string(threads);
      EXPECT_EQ(b.method, a.method) << what;
      EXPECT_EQ(b.threshold, a.threshold) << what;
      EXPECT_EQ(b.connected_clips, a.connected_clips) << what;
      EXPECT_EQ(b.connectivity, a.connectivity) << what;
      EXPECT_EQ(b.transitions, a.transitions) << what;
      EXPECT_EQ(b.success_rate, a.success_rate) << what;
      EXPECT_EQ(b.tbf_frames, a.tbf_frames) << what;
      EXPECT_EQ(b.response_frames, a.response_frames) << what;
      EXPECT_EQ(b.cost, a.cost) << what;  // bit for bit: the same sums in the same order
      ASSERT_EQ(b.maneuverability.size(), a.maneuverability.size()) << what;
      for (size_t k = 0; k < a.maneuverability.size(); ++k) {
        if (std::isnan(a.maneuverability[k])) {
          EXPECT_TRUE(std::isnan(b.maneuverability[k])) << what << " cell " << k;
        } else {
          EXPECT_EQ(b.maneuverability[k], a.maneuverability[k]) << what << " cell " << k;
        }
      }
    }
  }
  EXPECT_GT(expected.back().transitions, 0);
  o.threads = -1;
  EXPECT_EQ(Evaluate(data, o).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(Params, BadValuesNameTheField) {
  GraphParams p;
  p.threshold = -1;
  auto r = ResolveParams(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("params.threshold"), std::string::npos);
  p = {};
  p.joint_weights["NoSuchJoint"] = 1;
  auto d = BuildLocomotionData(CmuLibrary(), p);
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.status().message().find("params.joint_weights"), std::string::npos);
}

TEST(Avatar, CubeAngleMapsToSpeedAsInSection524) {
  EXPECT_EQ(CubeAngleToSpeed(0), 0);
  EXPECT_EQ(CubeAngleToSpeed(45), 0);
  EXPECT_NEAR(CubeAngleToSpeed(90), 3.55, 1e-12);
  EXPECT_NEAR(CubeAngleToSpeed(180), 5.55, 1e-12);
  EXPECT_NEAR(CubeAngleToSpeed(-90), 3.55, 1e-12);
  EXPECT_NEAR(CubeAngleToSpeed(270), 3.55, 1e-12);
  EXPECT_NEAR(CubeAngleToSpeed(46), 1.55 + 4.0 * 46 / 180, 1e-12);
}

// CMU subject 131 trial 1 ("start walk stop", 120 fps): its first 1.6 s of
// standing is the idle clip, 2 s of its walking the walk clip (no run clip:
// the walk clip serves run speeds).
std::shared_ptr<const LocomotionGraph> AvatarGraph() {
  static std::shared_ptr<const LocomotionGraph> graph = [] {
    auto full = motion::ReadBvhFile(kData + "motion/131_01.bvh");
    EXPECT_TRUE(full.ok()) << full.status();
    auto slice = [&](int first, int last) {
      motion::Clip c = *full;
      c.frames = full->frames.middleRows(first, last - first).eval();
      return *motion::WriteBvh(c);
    };
    LibrarySources sources;
    sources.inline_clips = {{"idle", slice(0, 200), "", {}}, {"walk", slice(520, 780), "", {}}};
    sources.frame_rate_hz = 60;
    auto lib = LoadLibrary("avatar", sources);
    EXPECT_TRUE(lib.ok()) << lib.status();
    auto data = BuildLocomotionData(std::shared_ptr<const Library>(*std::move(lib)), {});
    EXPECT_TRUE(data.ok()) << data.status();
    GraphParams params;
    params.threshold = 0.4;
    auto g = LocomotionGraph::Build(*data, *BuiltinProfile("SP2"), params);
    EXPECT_TRUE(g.ok()) << g.status();
    return *g;
  }();
  return graph;
}

TEST(Avatar, WalksToATargetOneMetreAwayAndStops) {
  auto g = AvatarGraph();
  DriveParams p;
  p.idle_clip = "idle";
  p.walk_clip = "walk";
  p.start.heading_rad = 0;
  auto drv = AvatarDriver::Create(g, p);
  ASSERT_TRUE(drv.ok()) << drv.status();
  ASSERT_TRUE((*drv)->SetSpeed(CubeAngleToSpeed(60)).ok());  // 'Speed' 2.88: walk
  (*drv)->SetTarget(Eigen::Vector2d(1.0, 0.0));
  std::vector<double> frame(static_cast<size_t>(g->data().library->skeleton.num_channels()));
  double min_dist = 1e9, max_speed = 0, reached_s = -1;
  std::set<DriveState> states;
  for (int f = 0; f < 60 * 12; ++f) {
    (*drv)->Step(frame);
    const auto& st = (*drv)->status();
    min_dist = std::min(min_dist, (st.root.position_m - Eigen::Vector2d(1, 0)).norm());
    max_speed = std::max(max_speed, st.speed_mps);
    states.insert(st.state);
    if (st.target_reached && reached_s < 0) reached_s = st.time_s;
  }
  const auto& st = (*drv)->status();
  EXPECT_GT(reached_s, 0) << "target not reached";
  EXPECT_LT((st.root.position_m - Eigen::Vector2d(1, 0)).norm(), 0.3);
  EXPECT_TRUE(states.count(DriveState::kWalk));
  EXPECT_FALSE(states.count(DriveState::kRun));
  EXPECT_EQ(st.state, DriveState::kIdle);
  std::cout << "reached at " << reached_s << " s, min distance " << min_dist << " m, final distance "
            << (st.root.position_m - Eigen::Vector2d(1, 0)).norm() << " m, max speed " << max_speed << " m/s\n";
  EXPECT_GT(max_speed, 0.5);
  // Every transition the avatar played keeps the foot phase across its jumps.
  const auto& d = g->data();
  ASSERT_GE((*drv)->transitions().size(), 2u);
  for (const auto& rec : (*drv)->transitions()) {
    for (size_t k = 0; k + 1 < rec.lower_path.size(); ++k) {
      const int a = rec.lower_path[k], b = rec.lower_path[k + 1];
      if (b == a + 1) continue;
      EXPECT_EQ(d.phase[static_cast<size_t>(a)], d.phase[static_cast<size_t>(b)]);
    }
  }
}

TEST(Avatar, FollowsSpeedCommands) {
  auto g = AvatarGraph();
  DriveParams p;
  p.idle_clip = "idle";
  p.walk_clip = "walk";
  auto drv = AvatarDriver::Create(g, p);
  ASSERT_TRUE(drv.ok()) << drv.status();
  std::vector<double> frame(static_cast<size_t>(g->data().library->skeleton.num_channels()));
  auto mean_speed = [&](int frames) {
    const Eigen::Vector2d a = (*drv)->status().root.position_m;
    for (int f = 0; f < frames; ++f) (*drv)->Step(frame);
    return ((*drv)->status().root.position_m - a).norm() / (frames / 60.0);
  };
  // Cube at 30 degrees: 'Speed' 0, the avatar stands.
  ASSERT_TRUE((*drv)->SetSpeed(CubeAngleToSpeed(30)).ok());
  EXPECT_LT(mean_speed(120), 0.2);
  EXPECT_EQ((*drv)->status().state, DriveState::kIdle);
  // Cube at 60 degrees: walk.
  ASSERT_TRUE((*drv)->SetSpeed(CubeAngleToSpeed(60)).ok());
  mean_speed(120);
  EXPECT_GT(mean_speed(120), 0.6);
  EXPECT_EQ((*drv)->status().state, DriveState::kWalk);
  // Back to idle.
  ASSERT_TRUE((*drv)->SetSpeed(0).ok());
  mean_speed(180);
  EXPECT_LT(mean_speed(60), 0.2);
  EXPECT_FALSE((*drv)->SetSpeed(7).ok());
  p.walk_clip = "nope";
  auto bad = AvatarDriver::Create(g, p);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("config.walk_clip"), std::string::npos);
}

}  // namespace
}  // namespace kinemo::planner::locomotion

// The AvatAR (thesis §5.2): idle / walk / run chosen from 'Speed', steering
// to a target or along a sketched path, BPMG transitions between the clips.
#include <algorithm>
#include <cmath>
#include <numbers>

#include "services/planner/locomotion/locomotion.h"

namespace kinemo::planner::locomotion {
namespace {

// Loop of a clip: a jump from a late frame to an early one with the lowest
// full-body distance and the same foot phase.
std::pair<int, int> FindLoop(const LocomotionData& d, int clip) {
  const int b0 = d.clip_begin[static_cast<size_t>(clip)], b1 = d.clip_begin[static_cast<size_t>(clip) + 1];
  const int n = b1 - b0;
  const size_t nn = static_cast<size_t>(d.num_frames);
  std::pair<int, int> best = {b1 - 1, b0};
  double best_d = 1e300;
  for (int a = b0 + n / 2; a < b1 - 1; ++a) {
    for (int b = b0; b < b0 + n / 2 && b < a - 2; ++b) {
      if (d.phase[static_cast<size_t>(a)] != d.phase[static_cast<size_t>(b)]) continue;
      double dist = 0;
      for (const auto& m : d.chain_distance) dist += m[static_cast<size_t>(a) * nn + static_cast<size_t>(b)];
      // Prefer long loops slightly (less repetition).
      dist += 1e-4 * (n - (a - b)) / n;
      if (dist < best_d) {
        best_d = dist;
        best = {a, b};
      }
    }
  }
  return best;
}

}  // namespace

StatusOr<std::unique_ptr<AvatarDriver>> AvatarDriver::Create(std::shared_ptr<const LocomotionGraph> graph,
                                                             DriveParams params) {
  if (!graph) return InvalidField("config.graph_id", "no graph");
  const LocomotionData& d = graph->data();
  auto drv = std::unique_ptr<AvatarDriver>(new AvatarDriver());
  drv->graph_ = graph;
  const std::pair<const char*, const std::string*> names[] = {
      {"config.idle_clip", &params.idle_clip}, {"config.walk_clip", &params.walk_clip}, {"config.run_clip", &params.run_clip}};
  int* slots[] = {&drv->idle_, &drv->walk_, &drv->run_};
  for (int k = 0; k < 3; ++k) {
    if (k == 2 && params.run_clip.empty()) {
      drv->run_ = drv->walk_;  // no run clip: the walk clip at run speeds
      continue;
    }
    *slots[k] = d.ClipIndex(*names[k].second);
    if (*slots[k] < 0) return InvalidField(names[k].first, kinemo::StrCat("no clip '", *names[k].second, "' in the graph's library"));
  }
  if (drv->idle_ == drv->walk_ || drv->idle_ == drv->run_) {
    return InvalidField("config", "the idle clip must differ from the walk and run clips");
  }
  if (params.walk_min_speed <= 0) params.walk_min_speed = 0.5;
  if (params.run_min_speed <= 0) params.run_min_speed = 3.5;
  if (params.run_min_speed < params.walk_min_speed) return InvalidField("run_min_speed", "must be >= walk_min_speed");
  if (params.arrival_radius_m <= 0) params.arrival_radius_m = 0.05;
  if (params.max_turn_deg_per_s <= 0) params.max_turn_deg_per_s = 180;
  drv->params_ = params;
  for (int c = 0; c + 1 < static_cast<int>(d.clip_begin.size()); ++c) drv->loop_.push_back(FindLoop(d, c));
  drv->ws_.Reserve(d.num_frames);
  drv->part_of_chain_.assign(kNumChains, 0);
  for (size_t p = 0; p < graph->parts().size(); ++p) {
    for (Chain c : graph->parts()[p].chains) drv->part_of_chain_[static_cast<size_t>(c)] = static_cast<int>(p);
  }
  drv->samples_.resize(graph->parts().size());
  drv->previous_.resize(static_cast<size_t>(d.library->skeleton.num_channels()));
  drv->frame_ = d.clip_begin[static_cast<size_t>(drv->idle_)];
  drv->status_.root = params.start;
  drv->status_.state = DriveState::kIdle;
  return drv;
}

Status AvatarDriver::SetSpeed(double speed) {
  if (!std::isfinite(speed) || speed < 0 || speed > 5.55 + 1e-9) return InvalidField("speed", "must be in [0, 5.55]");
  speed_ = speed;
  return absl::OkStatus();
}

void AvatarDriver::SetTarget(const Eigen::Vector2d& target_m) {
  if (!has_target_ || (target_m - target_).norm() > params_.arrival_radius_m) {
    stopping_ = false;
    arrived_ = false;
  }
  has_target_ = true;
  target_ = target_m;
  path_.clear();
}

Status AvatarDriver::SetPath(std::vector<Eigen::Vector2d> points_m, bool loop) {
  if (points_m.empty() || points_m.size() > 1000) return InvalidField("path.points_m", "needs 1 to 1000 points");
  for (const auto& p : points_m) {
    if (!p.allFinite()) return InvalidField("path.points_m", "must be finite");
  }
  path_ = std::move(points_m);
  path_loop_ = loop;
  path_index_ = 0;
  has_target_ = false;
  stopping_ = false;
  arrived_ = false;
  return absl::OkStatus();
}

void AvatarDriver::Stop() {
  has_target_ = false;
  path_.clear();
  speed_ = 0;
}

bool AvatarDriver::HasGoal() const { return (has_target_ || !path_.empty()) && !arrived_; }

Eigen::Vector2d AvatarDriver::Goal() const { return has_target_ ? target_ : path_[path_index_]; }

int AvatarDriver::DesiredClip() const {
  if (speed_ < params_.walk_min_speed) return idle_;
  if ((has_target_ || !path_.empty()) && (arrived_ || stopping_)) return idle_;
  return speed_ >= params_.run_min_speed ? run_ : walk_;
}

double AvatarDriver::PredictStopTravel() {
  Transition tr;
  if (!PlanTransition(*graph_, frame_, idle_, &ws_, &tr).ok()) return -1;
  const LocomotionData& d = graph_->data();
  double travel = 0;
  PartSample s;
  for (int t = 0; t <= tr.total_frames; ++t) {
    SamplePart(*graph_, tr, 0, t, &s);
    travel += d.velocity_m[static_cast<size_t>(s.a)].norm();
  }
  return travel;
}

void AvatarDriver::StartTransition(int clip) {
  const LocomotionData& d = graph_->data();
  if (PlanTransition(*graph_, frame_, clip, &ws_, &transition_).ok()) {
    in_transition_ = true;
    t_ = 0;
    DriveTransitionRecord rec;
    rec.from_clip = d.clip_of[static_cast<size_t>(frame_)];
    rec.to_clip = clip;
    rec.lower_path = transition_.parts[0].path;
    rec.start_s = static_cast<double>(frames_out_) / d.fps;
    records_.push_back(std::move(rec));
  } else {
    retry_wait_ = 3;  // try again a few frames later
  }
}

void AvatarDriver::Step(std::span<double> out) {
  const LocomotionData& d = graph_->data();
  const double dt = 1.0 / d.fps;
  RootState& root = status_.root;
  status_.target_reached = false;
  // Goals.
  if (HasGoal()) {
    const double dist = (Goal() - root.position_m).norm();
    const bool final_point = has_target_ || (!path_loop_ && path_index_ + 1 == path_.size());
    if (dist <= params_.arrival_radius_m || (stopping_ && !in_transition_ &&
                                              d.clip_of[static_cast<size_t>(frame_)] == idle_)) {
      status_.target_reached = dist <= params_.arrival_radius_m || stopping_;
      if (final_point) {
        arrived_ = true;
      } else {
        path_index_ = (path_index_ + 1) % path_.size();
      }
      stopping_ = false;
    } else if (final_point && !stopping_ && !in_transition_ && dist < 3.0 &&
               d.clip_of[static_cast<size_t>(frame_)] != idle_) {
      const double travel = PredictStopTravel();
      if (travel >= 0 && travel >= dist - 0.5 * params_.arrival_radius_m) stopping_ = true;
    }
  }
  const int desired = DesiredClip();
  const int current = d.clip_of[static_cast<size_t>(frame_)];
  if (!in_transition_ && current != desired) {
    if (retry_wait_ > 0) {
      --retry_wait_;
    } else {
      StartTransition(desired);
    }
  }
  // Samples.
  if (in_transition_) {
    for (size_t p = 0; p < samples_.size(); ++p) SamplePart(*graph_, transition_, p, t_, &samples_[p]);
  } else {
    for (auto& s : samples_) s = PartSample{frame_, frame_, 0};
  }
  ComposeFrame(d, samples_, part_of_chain_, root, has_previous_ ? previous_.data() : nullptr, out);
  std::copy(out.begin(), out.end(), previous_.begin());
  has_previous_ = true;
  // Root.
  const PartSample& lo = samples_[0];
  Eigen::Vector2d v = d.velocity_m[static_cast<size_t>(lo.a)] +
                      lo.alpha * (d.velocity_m[static_cast<size_t>(lo.b)] - d.velocity_m[static_cast<size_t>(lo.a)]);
  double turn = d.turn_rad[static_cast<size_t>(lo.a)];
  // The idle clip plays in place (a standing actor's drift would accumulate
  // over its loops); steering only while walking or running.
  const bool idle_frame = d.clip_of[static_cast<size_t>(lo.a)] == idle_ && d.clip_of[static_cast<size_t>(lo.b)] == idle_;
  if (idle_frame) {
    v.setZero();
    turn = 0;
  }
  const bool moving = !idle_frame && v.norm() > 1e-4;
  if (HasGoal() && moving) {
    const Eigen::Vector2d to = Goal() - root.position_m;
    const double err = WrapAngle(std::atan2(to.y(), to.x()) - root.heading_rad);
    const double max_turn = params_.max_turn_deg_per_s * std::numbers::pi / 180 * dt;
    turn = std::clamp(err, -max_turn, max_turn);
  }
  const double h = root.heading_rad;
  root.position_m += Eigen::Vector2d(std::cos(h) * v.x() - std::sin(h) * v.y(), std::sin(h) * v.x() + std::cos(h) * v.y());
  root.heading_rad = WrapAngle(h + turn);
  status_.speed_mps = v.norm() / dt;
  // Playback.
  auto advance = [&]() {
    const int c = d.clip_of[static_cast<size_t>(frame_)];
    const auto [from, to] = loop_[static_cast<size_t>(c)];
    frame_ = frame_ == from || frame_ + 1 >= d.clip_begin[static_cast<size_t>(c) + 1] ? to : frame_ + 1;
  };
  if (in_transition_) {
    if (t_ < transition_.total_frames) {
      ++t_;
    } else {
      in_transition_ = false;
      frame_ = transition_.end_frame;
      advance();
    }
  } else {
    advance();
  }
  ++frames_out_;
  status_.time_s = static_cast<double>(frames_out_) * dt;
  const int now = d.clip_of[static_cast<size_t>(frame_)];
  status_.state = in_transition_                ? DriveState::kTransition
                  : now == idle_                  ? DriveState::kIdle
                  : now == run_ && run_ != walk_  ? DriveState::kRun
                  : now == walk_ && speed_ >= params_.run_min_speed ? DriveState::kRun
                                                  : DriveState::kWalk;
  status_.distance_to_target_m = HasGoal() ? (Goal() - root.position_m).norm() : 0;
}

}  // namespace kinemo::planner::locomotion

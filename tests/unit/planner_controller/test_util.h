// Shared fixtures: the real test library (tests/data/planner_controller) and
// a state model fitted to its own segments (a Gaussian HMM over the six
// kinematic parameters, as the inference layer's Λ_Y); that model as the
// planner API's StateModel, and beliefs for the controller RPCs.
#pragma once

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "kinemo/planner/v1/planner.pb.h"

#include "services/inference/core/gaussian_hmm.h"
#include "services/inference/corpus/corpus.h"
#include "services/planner/controller/controller.h"

namespace kinemo::planner::controller::testing {

inline std::string DataDir() { return std::string(KINEMO_TEST_DATA_DIR) + "/planner_controller"; }

inline std::shared_ptr<const Library> TestLibrary() {
  static std::shared_ptr<const Library> lib = [] {
    LibrarySources src;
    src.paths.push_back(DataDir() + "/manifest.json");
    auto l = LoadLibrary("test", src);
    if (!l.ok()) throw std::runtime_error(std::string(l.status().message()));
    return std::shared_ptr<const Library>(*std::move(l));
  }();
  return lib;
}

inline StateModel FitStateModel(const Library& lib, int states) {
  std::vector<Eigen::MatrixXd> seqs;
  for (const auto& c : lib.clips) {
    auto segs = ::kinemo::gesture::ComputeKinematicSegments(c.clip);
    if (!segs.ok() || segs->size() < 2) continue;
    Eigen::MatrixXd y(static_cast<Eigen::Index>(segs->size()), 6);
    for (size_t k = 0; k < segs->size(); ++k) y.row(static_cast<Eigen::Index>(k)) = (*segs)[k].params.transpose();
    seqs.push_back(y);
  }
  inference::HmmTrainParams p;
  p.num_states = states;
  p.restarts = 2;
  p.full_covariance = true;
  auto hmm = inference::GaussianHmm::Train(seqs, p);
  if (!hmm.ok()) throw std::runtime_error(std::string(hmm.status().message()));
  StateModel m;
  m.initial = hmm->initial();
  m.transition = hmm->transition();
  for (int i = 0; i < states; ++i) {
    m.means.push_back(hmm->means().row(i).transpose());
    Matrix6 c = hmm->covariances()[static_cast<size_t>(i)];
    m.covariances.push_back(0.5 * (c + c.transpose()));
  }
  return m;
}

inline v1::StateModel StateModelProto(const StateModel& model) {
  v1::StateModel m;
  const int s = model.num_states();
  m.set_num_states(static_cast<uint32_t>(s));
  for (int i = 0; i < s; ++i) m.add_initial_probabilities(model.initial(i));
  for (int i = 0; i < s; ++i)
    for (int j = 0; j < s; ++j) m.add_transition_probabilities(model.transition(i, j));
  for (int i = 0; i < s; ++i) {
    auto* g = m.add_states();
    for (int k = 0; k < 6; ++k) g->add_mean(model.means[static_cast<size_t>(i)](k));
    for (int k = 0; k < 36; ++k) g->add_covariance(model.covariances[static_cast<size_t>(i)](k / 6, k % 6));
  }
  return m;
}

// A belief that drifts between `states` states, one step per 0.25 s.
inline std::vector<v1::BeliefStep> DriftingBeliefs(int states, double duration_s) {
  std::vector<v1::BeliefStep> out;
  for (int t = 0; t * 0.25 < duration_s; ++t) {
    v1::BeliefStep b;
    b.set_step(static_cast<uint64_t>(t));
    b.set_start_s(t * 0.25);
    b.set_end_s(t * 0.25 + 0.25);
    double sum = 0;
    std::vector<double> p(static_cast<size_t>(states));
    for (int i = 0; i < states; ++i) sum += p[static_cast<size_t>(i)] = 1.0 + std::sin(0.7 * t + 1.3 * i);
    for (double v : p) b.add_probabilities(v / sum);
    out.push_back(b);
  }
  return out;
}

}  // namespace kinemo::planner::controller::testing

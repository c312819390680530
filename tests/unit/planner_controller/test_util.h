// Shared fixtures: the real test library (tests/data/planner_controller) and
// a state model fitted to its own segments (a Gaussian HMM over the six
// kinematic parameters, as the inference layer's Λ_Y).
#pragma once

#include <memory>
#include <string>

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
    auto segs = inference::ComputeKinematicSegments(c.clip);
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

}  // namespace kinemo::planner::controller::testing

// Helpers for the inference tests: best label permutation, CRF sampling.
#pragma once

#include <algorithm>
#include <numeric>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "services/inference/core/chain.h"
#include "services/inference/core/remapped_crf.h"

namespace kinemo::inference::testing {

// Fraction of steps where perm[argmax γ_t] == truth_t, maximised over label
// permutations greedily on the confusion matrix (exact when the confusion
// matrix is dominated by its assignment, which holds for well-recovered models).
inline double AccuracyBestPermutation(const RowMatrix& gamma, const std::vector<int>& truth,
                                      int num_states) {
  Eigen::MatrixXd conf = Eigen::MatrixXd::Zero(num_states, num_states);  // learned × true
  for (Eigen::Index t = 0; t < gamma.rows(); ++t) {
    Eigen::Index arg;
    gamma.row(t).maxCoeff(&arg);
    conf(arg, truth[t]) += 1;
  }
  double correct = 0;
  Eigen::MatrixXd c = conf;
  for (int k = 0; k < num_states; ++k) {
    Eigen::Index r, col;
    const double v = c.maxCoeff(&r, &col);
    if (v < 0) break;
    correct += conf(r, col);
    c.row(r).setConstant(-1);
    c.col(col).setConstant(-1);
  }
  return correct / static_cast<double>(gamma.rows());
}

// Samples Q ~ P_CRF(Q | features) by forward filtering, backward sampling.
inline std::vector<int> SampleCrf(const RemappedCrf& crf, const RowMatrix& features,
                                  std::mt19937_64& rng) {
  const RowMatrix alpha = crf.Filtered(features);
  const Eigen::Index n = features.rows();
  std::vector<int> q(n);
  auto draw = [&](const Eigen::VectorXd& p) {
    std::discrete_distribution<int> d(p.data(), p.data() + p.size());
    return d(rng);
  };
  q[n - 1] = draw(alpha.row(n - 1).transpose());
  for (Eigen::Index t = n - 2; t >= 0; --t) {
    Eigen::VectorXd p = alpha.row(t).transpose().cwiseProduct(crf.exp_transition().col(q[t + 1]));
    q[t] = draw(p);
  }
  return q;
}

}  // namespace kinemo::inference::testing

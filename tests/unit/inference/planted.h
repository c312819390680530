// A planted generative model for the whole pipeline: a sticky Markov chain
// over hidden states; kinematics y_t ~ N(μ_{q_t}, σ²I) (6-D); prosody x_t
// drawn from a state-dependent Gaussian over (semitones, dB, log length),
// voiced with probability 0.8, and tied to q_{t+lead}.
#pragma once

#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "services/inference/core/remapped_model.h"

namespace kinemo::inference::testing {

struct PlantedPipeline {
  int s = 4;
  int lead = 0;
  Eigen::MatrixXd trans;
  Eigen::MatrixXd y_means;  // S × 6
  double y_sigma = 0.4;
  Eigen::MatrixXd x_means;  // S × 3 (semitones, dB, log s)
  Eigen::Vector3d x_sigma{2.0, 3.0, 0.25};

  explicit PlantedPipeline(int states, int lead_steps, std::uint64_t seed) : s(states), lead(lead_steps) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> nd;
    trans = Eigen::MatrixXd::Constant(s, s, 0.25 / (s - 1));
    trans.diagonal().setConstant(0.75);
    y_means.resize(s, 6);
    x_means.resize(s, 3);
    for (int i = 0; i < s; ++i) {
      for (int d = 0; d < 6; ++d) y_means(i, d) = 2.0 * nd(rng);
      x_means(i, 0) = 10.0 + 4.0 * (i % 3) + nd(rng);
      x_means(i, 1) = 60.0 + 6.0 * ((i / 3) % 3) + nd(rng);
      x_means(i, 2) = std::log(0.2) + 0.4 * ((i + 1) % 2);
    }
  }

  PairedSequence Sample(int n, std::mt19937_64& rng, std::vector<int>* states) const {
    std::normal_distribution<double> nd;
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<int> q(n + lead);
    std::uniform_int_distribution<int> pick(0, s - 1);
    q[0] = pick(rng);
    for (int t = 1; t < n + lead; ++t) {
      Eigen::VectorXd p = trans.row(q[t - 1]).transpose();
      std::discrete_distribution<int> d(p.data(), p.data() + s);
      q[t] = d(rng);
    }
    PairedSequence seq;
    seq.name = "planted";
    seq.outputs.resize(n, 6);
    double time = 0;
    for (int t = 0; t < n; ++t) {
      for (int d = 0; d < 6; ++d) seq.outputs(t, d) = y_means(q[t], d) + y_sigma * nd(rng);
      const int qx = q[t + lead];
      ProsodyStep x;
      x.voiced = u(rng) < 0.8;
      x.f0_mean_hz = x.voiced ? 100.0 * std::pow(2.0, (x_means(qx, 0) + x_sigma(0) * nd(rng)) / 12.0) : 0.0;
      x.intensity_mean_db = x_means(qx, 1) + x_sigma(1) * nd(rng);
      x.length_s = std::exp(x_means(qx, 2) + x_sigma(2) * nd(rng));
      x.start_s = time;
      time += x.length_s;
      x.end_s = time;
      seq.inputs.push_back(x);
    }
    if (states) states->assign(q.begin(), q.begin() + n);
    return seq;
  }

  // log P(Y | X) per step under the generating model (exact).
  double TrueLogLikelihoodPerStep(const PairedSequence& seq) const {
    const Eigen::Index n = seq.outputs.rows();
    if (lead != 0) return std::nan("");
    RowMatrix lx(n, s), ly(n, s);
    for (Eigen::Index t = 0; t < n; ++t) {
      const ProsodyStep& x = seq.inputs[t];
      const Eigen::Vector3d raw = RawInput(x);
      for (int i = 0; i < s; ++i) {
        double l = 0;
        for (int d = x.voiced ? 0 : 1; d < 3; ++d) {
          const double z = (raw(d) - x_means(i, d)) / x_sigma(d);
          l += -0.5 * z * z - std::log(x_sigma(d));
        }
        lx(t, i) = l;
        ly(t, i) = -0.5 * (seq.outputs.row(t) - y_means.row(i)).squaredNorm() / (y_sigma * y_sigma) -
                   6 * std::log(y_sigma) - 3 * std::log(2 * std::numbers::pi);
      }
    }
    const Eigen::VectorXd init = Eigen::VectorXd::Constant(s, 1.0 / s);
    return (ChainForward(lx + ly, trans, init, nullptr) - ChainForward(lx, trans, init, nullptr)) /
           static_cast<double>(n);
  }
};

}  // namespace kinemo::inference::testing

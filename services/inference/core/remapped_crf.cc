#include "services/inference/core/remapped_crf.h"

#include <cmath>

namespace kinemo::inference {

RowMatrix RemappedCrf::WindowFeatures(const RowMatrix& post, int window) {
  const Eigen::Index n = post.rows();
  const Eigen::Index k = post.cols();
  const int lo = WindowLow(window);
  RowMatrix f = RowMatrix::Zero(n, window * k + 1);
  for (Eigen::Index t = 0; t < n; ++t) {
    for (int o = 0; o < window; ++o) {
      const Eigen::Index src = t + lo + o;
      if (src < 0 || src >= n) continue;
      f.row(t).segment(o * k, k) = post.row(src);
    }
    f(t, window * k) = 1.0;
  }
  return f;
}

StatusOr<RemappedCrf> RemappedCrf::FromParameters(int window, int num_clusters,
                                                  Eigen::MatrixXd transition_weights,
                                                  Eigen::VectorXd initial_weights,
                                                  RowMatrix observation_weights) {
  const Eigen::Index s = initial_weights.size();
  if (window < 1) return InvalidField("crf.window", window, " must be ≥ 1");
  if (num_clusters < 1) return InvalidField("crf.num_clusters", num_clusters, " must be ≥ 1");
  if (s < 1) return InvalidField("crf.initial_weights", "empty");
  if (transition_weights.rows() != s || transition_weights.cols() != s)
    return InvalidField("crf.transition_weights", "expected ", s, "x", s);
  if (observation_weights.rows() != s ||
      observation_weights.cols() != FeatureCount(window, num_clusters))
    return InvalidField("crf.observation_weights", "expected ", s, "x",
                        FeatureCount(window, num_clusters));
  if (!transition_weights.allFinite() || !initial_weights.allFinite() ||
      !observation_weights.allFinite())
    return InvalidField("crf", "non-finite weight");
  RemappedCrf c;
  c.window_ = window;
  c.num_clusters_ = num_clusters;
  c.transition_weights_ = std::move(transition_weights);
  c.initial_weights_ = std::move(initial_weights);
  c.observation_weights_ = std::move(observation_weights);
  c.exp_transition_ = c.transition_weights_.array().exp();
  c.exp_initial_ = c.initial_weights_.array().exp();
  return c;
}

Eigen::VectorXd RemappedCrf::Pack() const {
  const Eigen::Index s = num_states();
  const Eigen::Index f = observation_weights_.cols();
  Eigen::VectorXd theta(s * s + s + s * f);
  Eigen::Map<Eigen::MatrixXd>(theta.data(), s, s) = transition_weights_;
  theta.segment(s * s, s) = initial_weights_;
  Eigen::Map<RowMatrix>(theta.data() + s * s + s, s, f) = observation_weights_;
  return theta;
}

double RemappedCrf::Objective(const std::vector<CrfTarget>& targets, int num_states, int features,
                              double l2, const Eigen::VectorXd& theta,
                              Eigen::VectorXd* gradient) {
  const Eigen::Index s = num_states;
  const Eigen::Index f = features;
  Eigen::Map<const Eigen::MatrixXd> w(theta.data(), s, s);
  const auto b = theta.segment(s * s, s);
  Eigen::Map<const RowMatrix> u(theta.data() + s * s + s, s, f);
  gradient->setZero(theta.size());
  Eigen::Map<Eigen::MatrixXd> gw(gradient->data(), s, s);
  auto gb = gradient->segment(s * s, s);
  Eigen::Map<RowMatrix> gu(gradient->data() + s * s + s, s, f);
  const Eigen::MatrixXd exp_w = w.array().exp();
  const Eigen::VectorXd exp_b = b.array().exp();
  double expected_ll = 0.0;
  Eigen::Index total = 0;
  ChainPosteriors post;
  for (const auto& tg : targets) {
    const RowMatrix log_node = tg.features * u.transpose();
    if (!ChainForwardBackward(log_node, exp_w, exp_b, true, &post)) {
      return std::numeric_limits<double>::infinity();
    }
    expected_ll += (tg.gamma.array() * log_node.array()).sum() +
                   (tg.xi_sum.array() * w.array()).sum() + tg.gamma.row(0).dot(b) - post.log_z;
    const RowMatrix dgamma = post.gamma - tg.gamma;  // model − target
    gu.noalias() += dgamma.transpose() * tg.features;
    gw += post.xi_sum - tg.xi_sum;
    gb += (post.gamma.row(0) - tg.gamma.row(0)).transpose();
    total += tg.features.rows();
  }
  const double inv_n = 1.0 / static_cast<double>(std::max<Eigen::Index>(1, total));
  *gradient = *gradient * inv_n + (l2 * inv_n) * theta;
  return -expected_ll * inv_n + 0.5 * l2 * inv_n * theta.squaredNorm();
}

StatusOr<RemappedCrf> RemappedCrf::Train(const std::vector<CrfTarget>& targets, int num_states,
                                         int window, int num_clusters,
                                         const CrfTrainParams& params,
                                         const std::function<bool(int, double)>& iteration) {
  if (targets.empty()) return InvalidField("targets", "empty");
  const int f = FeatureCount(window, num_clusters);
  for (size_t k = 0; k < targets.size(); ++k) {
    const auto& t = targets[k];
    if (t.features.rows() == 0) return InvalidField(kinemo::StrCat("targets[", k, "]"), "empty");
    if (t.features.cols() != f || t.gamma.cols() != num_states ||
        t.gamma.rows() != t.features.rows() || t.xi_sum.rows() != num_states ||
        t.xi_sum.cols() != num_states)
      return InvalidField(kinemo::StrCat("targets[", k, "]"), "mismatched dimensions");
  }
  if (!(params.l2 >= 0.0)) return InvalidField("crf_l2", params.l2, " must be ≥ 0");
  const Eigen::Index s = num_states;
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(s * s + s + s * f);
  LbfgsParams lp;
  lp.max_iterations = params.max_iterations;
  lp.tolerance = params.tolerance;
  MinimizeLbfgs(
      [&](const Eigen::VectorXd& x, Eigen::VectorXd* g) {
        return Objective(targets, num_states, f, params.l2, x, g);
      },
      &theta, lp, iteration);
  Eigen::MatrixXd w = Eigen::Map<Eigen::MatrixXd>(theta.data(), s, s);
  Eigen::VectorXd b = theta.segment(s * s, s);
  RowMatrix u = Eigen::Map<RowMatrix>(theta.data() + s * s + s, s, f);
  return FromParameters(window, num_clusters, std::move(w), std::move(b), std::move(u));
}

RowMatrix RemappedCrf::LogNode(const RowMatrix& features) const {
  return features * observation_weights_.transpose();
}

double RemappedCrf::LogPartition(const RowMatrix& features) const {
  return ChainForward(LogNode(features), exp_transition_, exp_initial_, nullptr);
}

bool RemappedCrf::Posteriors(const RowMatrix& features, ChainPosteriors* out) const {
  return ChainForwardBackward(LogNode(features), exp_transition_, exp_initial_, false, out);
}

RowMatrix RemappedCrf::Filtered(const RowMatrix& features) const {
  RowMatrix alpha;
  ChainForward(LogNode(features), exp_transition_, exp_initial_, &alpha);
  return alpha;
}

std::vector<int> RemappedCrf::Viterbi(const RowMatrix& features) const {
  return ChainViterbi(LogNode(features), transition_weights_, initial_weights_);
}

Eigen::MatrixXd RemappedCrf::NormalizedTransition() const {
  Eigen::MatrixXd t = exp_transition_;
  for (Eigen::Index i = 0; i < t.rows(); ++i) t.row(i) /= t.row(i).sum();
  return t;
}

Eigen::MatrixXd RemappedCrf::TransitionPower(int n) const {
  Eigen::MatrixXd result = Eigen::MatrixXd::Identity(num_states(), num_states());
  Eigen::MatrixXd base = NormalizedTransition();
  while (n > 0) {
    if (n & 1) result = result * base;
    base = base * base;
    n >>= 1;
  }
  return result;
}

}  // namespace kinemo::inference

#include "services/inference/core/chain.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace kinemo::inference {
namespace {

// Brute force over all S^n paths.
struct Brute {
  double log_z;
  RowMatrix gamma;
  Eigen::MatrixXd xi;
};
Brute Enumerate(const RowMatrix& ln, const Eigen::MatrixXd& tr, const Eigen::VectorXd& init) {
  const int n = static_cast<int>(ln.rows()), s = static_cast<int>(ln.cols());
  int paths = 1;
  for (int t = 0; t < n; ++t) paths *= s;
  Brute b{0, RowMatrix::Zero(n, s), Eigen::MatrixXd::Zero(s, s)};
  double z = 0;
  std::vector<int> q(n);
  for (int p = 0; p < paths; ++p) {
    int r = p;
    for (int t = 0; t < n; ++t) {
      q[t] = r % s;
      r /= s;
    }
    double w = init(q[0]) * std::exp(ln(0, q[0]));
    for (int t = 1; t < n; ++t) w *= tr(q[t - 1], q[t]) * std::exp(ln(t, q[t]));
    z += w;
    for (int t = 0; t < n; ++t) b.gamma(t, q[t]) += w;
    for (int t = 1; t < n; ++t) b.xi(q[t - 1], q[t]) += w;
  }
  b.log_z = std::log(z);
  b.gamma /= z;
  b.xi /= z;
  return b;
}

TEST(ChainTest, ForwardBackwardMatchesEnumeration) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> nd;
  const int n = 5, s = 3;
  RowMatrix ln(n, s);
  for (int t = 0; t < n; ++t)
    for (int i = 0; i < s; ++i) ln(t, i) = 3.0 * nd(rng) - 200.0;  // large offsets: scaling
  Eigen::MatrixXd tr = Eigen::MatrixXd::Random(s, s).array().abs() + 0.1;
  Eigen::VectorXd init = Eigen::VectorXd::Random(s).array().abs() + 0.1;
  // Brute force in linear space needs the offset removed; the chain code does not.
  const Brute b = Enumerate(ln.array() + 200.0, tr, init);
  ChainPosteriors post;
  ASSERT_TRUE(ChainForwardBackward(ln, tr, init, true, &post));
  EXPECT_NEAR(post.log_z, b.log_z - 200.0 * n, 1e-9);
  EXPECT_LT((post.gamma - b.gamma).cwiseAbs().maxCoeff(), 1e-10);
  EXPECT_LT((post.xi_sum - b.xi).cwiseAbs().maxCoeff(), 1e-10);
  EXPECT_NEAR(ChainForward(ln, tr, init, nullptr), b.log_z - 200.0 * n, 1e-9);
}

TEST(ChainTest, ViterbiFindsBestPath) {
  const int n = 4, s = 3;
  RowMatrix ln = RowMatrix::Zero(n, s);
  ln(0, 2) = 5;
  ln(1, 1) = 5;
  ln(2, 1) = 5;
  ln(3, 0) = 5;
  Eigen::MatrixXd lt = Eigen::MatrixXd::Constant(s, s, std::log(1.0 / s));
  Eigen::VectorXd li = Eigen::VectorXd::Constant(s, std::log(1.0 / s));
  EXPECT_EQ(ChainViterbi(ln, lt, li), (std::vector<int>{2, 1, 1, 0}));
}

}  // namespace
}  // namespace kinemo::inference

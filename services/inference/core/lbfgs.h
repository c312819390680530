// Limited-memory BFGS (Nocedal & Wright, Alg. 7.4/7.5) with a backtracking
// line search that enforces the Armijo condition, for smooth minimisation.
#pragma once

#include <functional>

#include <Eigen/Core>

namespace kinemo::inference {

struct LbfgsParams {
  int memory = 10;
  int max_iterations = 500;
  double tolerance = 1e-6;       // relative objective change
  double gradient_tolerance = 1e-7;  // max |g_i|
};

struct LbfgsResult {
  double value = 0.0;
  int iterations = 0;
  int evaluations = 0;
  bool converged = false;
};

// f(x, g) returns the objective and writes the gradient into g (same size as
// x). `iteration` (may be null) is called after each step with (iteration,
// value); returning false stops the optimisation.
using Objective = std::function<double(const Eigen::VectorXd&, Eigen::VectorXd*)>;
LbfgsResult MinimizeLbfgs(const Objective& f, Eigen::VectorXd* x, const LbfgsParams& params,
                          const std::function<bool(int, double)>& iteration = nullptr);

}  // namespace kinemo::inference

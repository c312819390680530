#include "services/inference/core/lbfgs.h"

#include <algorithm>
#include <cmath>
#include <deque>

namespace kinemo::inference {

LbfgsResult MinimizeLbfgs(const Objective& f, Eigen::VectorXd* x, const LbfgsParams& params,
                          const std::function<bool(int, double)>& iteration) {
  LbfgsResult res;
  const Eigen::Index n = x->size();
  Eigen::VectorXd g(n), g_new(n), x_new(n), d(n);
  double fx = f(*x, &g);
  ++res.evaluations;
  std::deque<Eigen::VectorXd> s_hist, y_hist;
  std::deque<double> rho_hist;
  std::vector<double> alpha(params.memory);
  for (int it = 0; it < params.max_iterations; ++it) {
    if (g.cwiseAbs().maxCoeff() < params.gradient_tolerance) {
      res.converged = true;
      break;
    }
    // Two-loop recursion: d = -H g.
    d = -g;
    const int m = static_cast<int>(s_hist.size());
    for (int k = m - 1; k >= 0; --k) {
      alpha[k] = rho_hist[k] * s_hist[k].dot(d);
      d -= alpha[k] * y_hist[k];
    }
    if (m > 0) d *= s_hist.back().dot(y_hist.back()) / y_hist.back().squaredNorm();
    else d /= std::max(1.0, g.norm());
    for (int k = 0; k < m; ++k) {
      const double beta = rho_hist[k] * y_hist[k].dot(d);
      d += s_hist[k] * (alpha[k] - beta);
    }
    double slope = g.dot(d);
    if (slope >= 0.0) {  // not a descent direction: restart with steepest descent
      s_hist.clear();
      y_hist.clear();
      rho_hist.clear();
      d = -g / std::max(1.0, g.norm());
      slope = g.dot(d);
    }
    // Backtracking line search (Armijo, c1 = 1e-4).
    double step = 1.0;
    double f_new = 0.0;
    bool accepted = false;
    for (int ls = 0; ls < 40; ++ls) {
      x_new = *x + step * d;
      f_new = f(x_new, &g_new);
      ++res.evaluations;
      if (std::isfinite(f_new) && f_new <= fx + 1e-4 * step * slope) {
        accepted = true;
        break;
      }
      step *= 0.5;
    }
    if (!accepted) break;
    Eigen::VectorXd s = x_new - *x;
    Eigen::VectorXd y = g_new - g;
    const double sy = s.dot(y);
    if (sy > 1e-12 * y.squaredNorm()) {
      if (static_cast<int>(s_hist.size()) == params.memory) {
        s_hist.pop_front();
        y_hist.pop_front();
        rho_hist.pop_front();
      }
      s_hist.push_back(std::move(s));
      y_hist.push_back(std::move(y));
      rho_hist.push_back(1.0 / sy);
    }
    const double rel = std::abs(fx - f_new) / std::max({1.0, std::abs(fx), std::abs(f_new)});
    x->swap(x_new);
    g.swap(g_new);
    fx = f_new;
    res.iterations = it + 1;
    if (iteration && !iteration(it, fx)) break;
    if (rel < params.tolerance) {
      res.converged = true;
      break;
    }
  }
  res.value = fx;
  return res;
}

}  // namespace kinemo::inference

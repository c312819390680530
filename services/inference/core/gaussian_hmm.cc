#include "services/inference/core/gaussian_hmm.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <numbers>
#include <thread>

#include <Eigen/Cholesky>

namespace kinemo::inference {
namespace {

constexpr double kTransitionFloor = 1e-10;

Eigen::MatrixXd Stack(const std::vector<Eigen::MatrixXd>& sequences) {
  Eigen::Index n = 0;
  for (const auto& s : sequences) n += s.rows();
  Eigen::MatrixXd all(n, sequences.front().cols());
  Eigen::Index row = 0;
  for (const auto& s : sequences) {
    all.middleRows(row, s.rows()) = s;
    row += s.rows();
  }
  return all;
}

// Applies the floor to a covariance; drops off-diagonals for diagonal models.
void FloorCovariance(const Eigen::VectorXd& floor, bool full, Eigen::MatrixXd* cov) {
  if (!full) {
    Eigen::VectorXd d = cov->diagonal();
    cov->setZero();
    cov->diagonal() = d;
  }
  for (Eigen::Index k = 0; k < cov->rows(); ++k) (*cov)(k, k) = std::max((*cov)(k, k), floor(k));
  if (full) {
    Eigen::LLT<Eigen::MatrixXd> llt(*cov);
    if (llt.info() != Eigen::Success) cov->diagonal() += floor;
  }
}

}  // namespace

Eigen::MatrixXd KMeansPlusPlus(const Eigen::MatrixXd& x, int k, int lloyd_iterations,
                               std::mt19937_64& rng, std::vector<int>* assignment) {
  const Eigen::Index n = x.rows();
  Eigen::MatrixXd centres(k, x.cols());
  std::uniform_int_distribution<Eigen::Index> pick(0, n - 1);
  centres.row(0) = x.row(pick(rng));
  Eigen::VectorXd d2 = (x.rowwise() - centres.row(0)).rowwise().squaredNorm();
  // Greedy k-means++ (as in scikit-learn): 2 + ln k candidates per centre,
  // drawn with probability ∝ D², keep the one that lowers the potential most.
  const int trials = 2 + static_cast<int>(std::log(static_cast<double>(k)));
  for (int c = 1; c < k; ++c) {
    const double total = d2.sum();
    Eigen::Index best_index = pick(rng);
    double best_potential = std::numeric_limits<double>::infinity();
    Eigen::VectorXd best_d2;
    for (int trial = 0; trial < trials; ++trial) {
      Eigen::Index chosen = pick(rng);
      if (total > 0.0) {
        std::uniform_real_distribution<double> u(0.0, total);
        double r = u(rng);
        for (Eigen::Index i = 0; i < n; ++i) {
          r -= d2(i);
          if (r <= 0.0) {
            chosen = i;
            break;
          }
        }
      }
      Eigen::VectorXd cand = d2.cwiseMin((x.rowwise() - x.row(chosen)).rowwise().squaredNorm());
      const double potential = cand.sum();
      if (potential < best_potential) {
        best_potential = potential;
        best_index = chosen;
        best_d2 = std::move(cand);
      }
    }
    centres.row(c) = x.row(best_index);
    d2 = std::move(best_d2);
  }
  assignment->assign(n, 0);
  for (int it = 0; it <= lloyd_iterations; ++it) {
    for (Eigen::Index i = 0; i < n; ++i) {
      Eigen::Index best;
      (centres.rowwise() - x.row(i)).rowwise().squaredNorm().minCoeff(&best);
      (*assignment)[i] = static_cast<int>(best);
    }
    if (it == lloyd_iterations) break;
    Eigen::MatrixXd sum = Eigen::MatrixXd::Zero(k, x.cols());
    Eigen::VectorXd count = Eigen::VectorXd::Zero(k);
    for (Eigen::Index i = 0; i < n; ++i) {
      sum.row((*assignment)[i]) += x.row(i);
      count((*assignment)[i]) += 1.0;
    }
    for (int c = 0; c < k; ++c) {
      if (count(c) > 0) centres.row(c) = sum.row(c) / count(c);
    }
  }
  return centres;
}

StatusOr<GaussianHmm> GaussianHmm::FromParameters(Eigen::VectorXd initial,
                                                  Eigen::MatrixXd transition,
                                                  Eigen::MatrixXd means,
                                                  std::vector<Eigen::MatrixXd> covariances,
                                                  bool full_covariance) {
  const Eigen::Index s = initial.size();
  if (s < 1) return InvalidField("hmm.initial", "empty");
  if (transition.rows() != s || transition.cols() != s)
    return InvalidField("hmm.transition", "expected ", s, "x", s);
  if (means.rows() != s || means.cols() < 1) return InvalidField("hmm.means", "expected ", s, " rows");
  if (static_cast<Eigen::Index>(covariances.size()) != s)
    return InvalidField("hmm.covariances", "expected ", s, " matrices");
  if (!initial.allFinite() || !transition.allFinite() || !means.allFinite())
    return InvalidField("hmm", "non-finite parameter");
  if (std::abs(initial.sum() - 1.0) > 1e-6 || (initial.array() < 0).any())
    return InvalidField("hmm.initial", "not a probability vector");
  for (Eigen::Index i = 0; i < s; ++i) {
    if (std::abs(transition.row(i).sum() - 1.0) > 1e-6 || (transition.row(i).array() < 0).any())
      return InvalidField(kinemo::StrCat("hmm.transition[", i, "]"), "row is not a distribution");
    const auto& c = covariances[i];
    if (c.rows() != means.cols() || c.cols() != means.cols() || !c.allFinite())
      return InvalidField(kinemo::StrCat("hmm.covariances[", i, "]"), "bad shape or value");
    Eigen::LLT<Eigen::MatrixXd> llt(c);
    if (llt.info() != Eigen::Success)
      return InvalidField(kinemo::StrCat("hmm.covariances[", i, "]"), "not positive definite");
  }
  GaussianHmm h;
  h.initial_ = std::move(initial);
  h.transition_ = std::move(transition);
  h.means_ = std::move(means);
  h.covariances_ = std::move(covariances);
  h.full_ = full_covariance;
  h.Prepare();
  return h;
}

void GaussianHmm::Prepare() {
  const int s = num_states();
  const int d = dims();
  chol_.resize(s);
  log_norm_.resize(s);
  for (int i = 0; i < s; ++i) {
    Eigen::LLT<Eigen::MatrixXd> llt(covariances_[i]);
    chol_[i] = llt.matrixL();
    const double log_det = 2.0 * chol_[i].diagonal().array().log().sum();
    log_norm_(i) = -0.5 * (d * std::log(2.0 * std::numbers::pi) + log_det);
  }
}

RowMatrix GaussianHmm::LogEmissions(const Eigen::MatrixXd& y) const {
  const int s = num_states();
  RowMatrix out(y.rows(), s);
  if (!full_) {
    // Diagonal: Σ_d (y_d − μ_d)² / σ²_d without a triangular solve.
    for (int i = 0; i < s; ++i) {
      const Eigen::ArrayXd inv_var = covariances_[i].diagonal().array().inverse();
      out.col(i) = (log_norm_(i) -
                    0.5 * ((y.rowwise() - means_.row(i)).array().square().matrix() * inv_var.matrix()).array())
                       .matrix();
    }
    return out;
  }
  for (int i = 0; i < s; ++i) {
    Eigen::MatrixXd diff = (y.rowwise() - means_.row(i)).transpose();  // D × n
    chol_[i].triangularView<Eigen::Lower>().solveInPlace(diff);
    out.col(i) = (log_norm_(i) - 0.5 * diff.colwise().squaredNorm().array()).transpose();
  }
  return out;
}

double GaussianHmm::LogLikelihood(const Eigen::MatrixXd& y) const {
  return ChainForward(LogEmissions(y), transition_, initial_, nullptr);
}

bool GaussianHmm::Posteriors(const Eigen::MatrixXd& y, ChainPosteriors* out) const {
  return ChainForwardBackward(LogEmissions(y), transition_, initial_, true, out);
}

void GaussianHmm::Sample(int n, std::mt19937_64& rng, std::vector<int>* states,
                         Eigen::MatrixXd* y) const {
  states->resize(n);
  y->resize(n, dims());
  std::normal_distribution<double> normal;
  auto draw = [&](const Eigen::VectorXd& p) {
    std::discrete_distribution<int> dist(p.data(), p.data() + p.size());
    return dist(rng);
  };
  int q = draw(initial_);
  for (int t = 0; t < n; ++t) {
    if (t > 0) q = draw(transition_.row(q).transpose());
    (*states)[t] = q;
    Eigen::VectorXd z(dims());
    for (int k = 0; k < dims(); ++k) z(k) = normal(rng);
    y->row(t) = (means_.row(q).transpose() + chol_[q] * z).transpose();
  }
}

namespace {

struct RestartResult {
  double ll_per_step = -std::numeric_limits<double>::infinity();
  Eigen::VectorXd initial;
  Eigen::MatrixXd transition, means;
  std::vector<Eigen::MatrixXd> covs;
  Status status;
  // EM state, so that a restart can be continued.
  bool started = false;
  bool converged = false;
  int iterations = 0;
  double prev = -std::numeric_limits<double>::infinity();
  std::mt19937_64 rng;
  Eigen::VectorXd cur_initial;
  Eigen::MatrixXd cur_transition, cur_means;
  std::vector<Eigen::MatrixXd> cur_covs;
};

}  // namespace

StatusOr<GaussianHmm> GaussianHmm::Train(const std::vector<Eigen::MatrixXd>& sequences,
                                         const HmmTrainParams& params,
                                         const HmmProgress& progress) {
  if (sequences.empty()) return InvalidField("sequences", "empty");
  const Eigen::Index d = sequences.front().cols();
  Eigen::Index total = 0;
  for (size_t k = 0; k < sequences.size(); ++k) {
    if (sequences[k].rows() == 0) return InvalidField(kinemo::StrCat("sequences[", k, "]"), "empty");
    if (sequences[k].cols() != d)
      return InvalidField(kinemo::StrCat("sequences[", k, "]"), "has ", sequences[k].cols(),
                          " dimensions, expected ", d);
    if (!sequences[k].allFinite())
      return InvalidField(kinemo::StrCat("sequences[", k, "]"), "contains NaN or infinity");
    total += sequences[k].rows();
  }
  const int s = params.num_states;
  if (s < 1) return InvalidField("num_states", "must be ≥ 1");
  if (total < s) return InvalidField("sequences", total, " steps are fewer than ", s, " states");
  const int restarts = std::max(1, params.restarts);

  const Eigen::MatrixXd all = Stack(sequences);
  const Eigen::RowVectorXd mean = all.colwise().mean();
  const Eigen::MatrixXd centred = all.rowwise() - mean;
  Eigen::MatrixXd data_cov = centred.transpose() * centred / static_cast<double>(total);
  Eigen::VectorXd floor = (data_cov.diagonal().array() * params.variance_floor).max(1e-12);
  data_cov.diagonal() = data_cov.diagonal().cwiseMax(floor);

  std::vector<RestartResult> results(restarts);
  std::mutex progress_mutex;

  // Runs (or continues) restart r until `budget` EM iterations in total or
  // convergence.
  auto run = [&](int r, int budget) {
    RestartResult& res = results[r];
    if (!res.status.ok() || res.converged) return;
    std::mt19937_64& rng = res.rng;
    Eigen::VectorXd& initial = res.cur_initial;
    Eigen::MatrixXd& transition = res.cur_transition;
    Eigen::MatrixXd& means = res.cur_means;
    std::vector<Eigen::MatrixXd>& covs = res.cur_covs;
    double& prev = res.prev;
    if (!res.started) {
      res.started = true;
      rng.seed(params.seed * 7919 + static_cast<std::uint64_t>(r) * 104729 + 17);
      std::vector<int> assign;
      means = KMeansPlusPlus(all, s, 10, rng, &assign);
      covs.assign(s, Eigen::MatrixXd());
      std::vector<Eigen::MatrixXd> acc(s, Eigen::MatrixXd::Zero(d, d));
      Eigen::VectorXd cnt = Eigen::VectorXd::Zero(s);
      for (Eigen::Index t = 0; t < total; ++t) {
        Eigen::VectorXd diff = (all.row(t) - means.row(assign[t])).transpose();
        acc[assign[t]] += diff * diff.transpose();
        cnt(assign[t]) += 1;
      }
      for (int i = 0; i < s; ++i) {
        covs[i] = cnt(i) > 1 ? Eigen::MatrixXd(acc[i] / cnt(i)) : data_cov;
        FloorCovariance(floor, params.full_covariance, &covs[i]);
      }
      initial = Eigen::VectorXd::Constant(s, 1.0 / s);
      transition = Eigen::MatrixXd::Constant(s, s, 0.5 / std::max(1, s - 1));
      transition.diagonal().setConstant(s > 1 ? 0.5 : 1.0);
    }
    while (res.iterations < std::min(budget, params.max_iterations)) {
      const int it = res.iterations++;
      auto hmm_or = FromParameters(initial, transition, means, covs, params.full_covariance);
      if (!hmm_or.ok()) {
        res.status = hmm_or.status();
        return;
      }
      const GaussianHmm& hmm = *hmm_or;
      // E-step.
      Eigen::VectorXd init_acc = Eigen::VectorXd::Zero(s);
      Eigen::MatrixXd xi_acc = Eigen::MatrixXd::Zero(s, s);
      Eigen::VectorXd w = Eigen::VectorXd::Zero(s);
      Eigen::MatrixXd wx = Eigen::MatrixXd::Zero(s, d);
      std::vector<Eigen::MatrixXd> wxx(s, Eigen::MatrixXd::Zero(d, d));
      double ll = 0.0;
      ChainPosteriors post;
      for (const auto& y : sequences) {
        if (!hmm.Posteriors(y, &post)) {
          ll = -std::numeric_limits<double>::infinity();
          break;
        }
        ll += post.log_z;
        init_acc += post.gamma.row(0).transpose();
        xi_acc += post.xi_sum;
        w += post.gamma.colwise().sum().transpose();
        wx.noalias() += post.gamma.transpose() * y;
        if (params.full_covariance) {
          for (int i = 0; i < s; ++i) {
            wxx[i].noalias() += y.transpose() * post.gamma.col(i).asDiagonal() * y;
          }
        } else {
          const Eigen::MatrixXd wyy = post.gamma.transpose() * y.array().square().matrix();  // S × D
          for (int i = 0; i < s; ++i) wxx[i].diagonal() += wyy.row(i).transpose();
        }
      }
      const double ll_step = ll / static_cast<double>(total);
      if (progress) {
        std::lock_guard<std::mutex> lock(progress_mutex);
        progress(r, it, ll_step);
      }
      if (!std::isfinite(ll_step)) {
        res.status = absl::InternalError("hmm: EM lost support (log-likelihood -inf)");
        return;
      }
      // Keep the parameters that produced this likelihood.
      res.ll_per_step = ll_step;
      res.initial = initial;
      res.transition = transition;
      res.means = means;
      res.covs = covs;
      if (it > 0 && ll_step - prev < params.tolerance) {
        res.converged = true;
        break;
      }
      prev = ll_step;
      // M-step.
      initial = (init_acc / static_cast<double>(sequences.size())).array() + kTransitionFloor;
      initial /= initial.sum();
      for (int i = 0; i < s; ++i) {
        Eigen::RowVectorXd row = xi_acc.row(i).array() + kTransitionFloor;
        transition.row(i) = row / row.sum();
        if (w(i) < 1e-8) {
          // An empty state: re-seed at a random data point.
          std::uniform_int_distribution<Eigen::Index> pick(0, total - 1);
          means.row(i) = all.row(pick(rng));
          covs[i] = data_cov;
        } else {
          means.row(i) = wx.row(i) / w(i);
          covs[i] = wxx[i] / w(i) - means.row(i).transpose() * means.row(i);
          covs[i] = 0.5 * (covs[i] + covs[i].transpose());
        }
        FloorCovariance(floor, params.full_covariance, &covs[i]);
      }
    }
  };

  // Phase 1: every restart runs a short EM budget (in parallel); phase 2:
  // the best one so far continues to convergence. Bad initialisations are
  // usually evident after a few dozen iterations, and most of EM's cost is
  // the slow final approach, which only the winner needs.
  const int short_budget = std::min(params.max_iterations, restarts > 1 ? 30 : params.max_iterations);
  const int threads = std::max(1, std::min(params.threads, restarts));
  std::vector<std::thread> pool;
  std::mutex next_mutex;
  int next = 0;
  for (int k = 0; k < threads; ++k) {
    pool.emplace_back([&] {
      for (;;) {
        int r;
        {
          std::lock_guard<std::mutex> lock(next_mutex);
          if (next >= restarts) return;
          r = next++;
        }
        run(r, short_budget);
      }
    });
  }
  for (auto& t : pool) t.join();
  {
    int lead = -1;
    for (int r = 0; r < restarts; ++r) {
      if (results[r].status.ok() && results[r].initial.size() > 0 &&
          (lead < 0 || results[r].ll_per_step > results[lead].ll_per_step)) {
        lead = r;
      }
    }
    if (lead >= 0) run(lead, params.max_iterations);
  }

  int best = -1;
  for (int r = 0; r < restarts; ++r) {
    if (results[r].status.ok() && results[r].initial.size() > 0 &&
        (best < 0 || results[r].ll_per_step > results[best].ll_per_step)) {
      best = r;
    }
  }
  if (best < 0) {
    return results[0].status.ok() ? absl::InternalError("hmm: no restart converged")
                                  : results[0].status;
  }
  RestartResult& b = results[best];
  return FromParameters(std::move(b.initial), std::move(b.transition), std::move(b.means),
                        std::move(b.covs), params.full_covariance);
}

}  // namespace kinemo::inference

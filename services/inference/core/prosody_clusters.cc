#include "services/inference/core/prosody_clusters.h"

#include "services/inference/core/gaussian_hmm.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

namespace kinemo::inference {

Status ValidateProsodyStep(const ProsodyStep& x, std::string_view field) {
  auto outside = [&](std::string_view name, double v, std::string_view range) {
    return InvalidField(kinemo::StrCat(field, ".", name), v, " is outside ", range);
  };
  if (!(x.start_s >= 0.0 && x.start_s <= kMaxStepTimeS)) return outside("start_s", x.start_s, "[0, 86400] s");
  if (!(x.end_s >= x.start_s && x.end_s <= kMaxStepTimeS))
    return outside("end_s", x.end_s, "[start_s, 86400] s");
  if (!(x.intensity_mean_db >= kMinStepIntensityDb && x.intensity_mean_db <= kMaxStepIntensityDb))
    return outside("intensity_mean_db", x.intensity_mean_db, "[-200, 200] dB");
  if (!(x.length_s > 0.0 && x.length_s <= kMaxStepLengthS)) return outside("length_s", x.length_s, "(0, 60] s");
  if (x.voiced && !(x.f0_mean_hz > 0.0 && x.f0_mean_hz <= kMaxStepF0Hz))
    return outside("f0_mean_hz", x.f0_mean_hz, "(0, 5000] Hz on a voiced step");
  return absl::OkStatus();
}

Status ValidateProsodySequence(std::span<const ProsodyStep> xs, std::string_view field) {
  if (xs.empty()) return InvalidField(field, "empty sequence");
  for (size_t t = 0; t < xs.size(); ++t) {
    KINEMO_RETURN_IF_ERROR(ValidateProsodyStep(xs[t], kinemo::StrCat(field, "[", t, "]")));
  }
  return absl::OkStatus();
}

Eigen::Vector3d RawInput(const ProsodyStep& x) {
  const double semitones = x.voiced ? 12.0 * std::log2(x.f0_mean_hz / 100.0) : 0.0;
  return {semitones, x.intensity_mean_db, std::log(x.length_s)};
}

InputNormalizer InputNormalizer::Fit(const std::vector<std::vector<ProsodyStep>>& sequences) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d count = Eigen::Vector3d::Zero();
  for (const auto& seq : sequences) {
    for (const auto& x : seq) {
      const Eigen::Vector3d r = RawInput(x);
      for (int d = 0; d < 3; ++d) {
        if (d == 0 && !x.voiced) continue;
        sum(d) += r(d);
        sum2(d) += r(d) * r(d);
        count(d) += 1;
      }
    }
  }
  InputNormalizer n;
  for (int d = 0; d < 3; ++d) {
    if (count(d) > 0) {
      n.mean(d) = sum(d) / count(d);
      const double var = sum2(d) / count(d) - n.mean(d) * n.mean(d);
      n.scale(d) = var > 1e-12 ? std::sqrt(var) : 1.0;
    }
  }
  return n;
}

InputMatrix MakeInputMatrix(const InputNormalizer& norm, std::span<const ProsodyStep> xs) {
  InputMatrix m;
  m.x.resize(static_cast<Eigen::Index>(xs.size()), 3);
  m.voiced.resize(xs.size());
  for (size_t t = 0; t < xs.size(); ++t) {
    m.x.row(static_cast<Eigen::Index>(t)) = norm.Apply(xs[t]).transpose();
    m.voiced[t] = xs[t].voiced ? 1 : 0;
    if (!xs[t].voiced) m.x(static_cast<Eigen::Index>(t), 0) = 0.0;
  }
  return m;
}

StatusOr<ProsodyClusters> ProsodyClusters::FromParameters(Eigen::VectorXd weights,
                                                          Eigen::MatrixXd means,
                                                          Eigen::MatrixXd variances) {
  const Eigen::Index k = weights.size();
  if (k < 1) return InvalidField("clusters.weights", "empty");
  if (means.rows() != k || means.cols() != 3)
    return InvalidField("clusters.means", "expected ", k, "x3");
  if (variances.rows() != k || variances.cols() != 3)
    return InvalidField("clusters.variances", "expected ", k, "x3");
  if (!weights.allFinite() || !means.allFinite() || !variances.allFinite() ||
      (variances.array() <= 0).any() || (weights.array() < 0).any())
    return InvalidField("clusters", "non-finite or non-positive parameter");
  ProsodyClusters c;
  c.weights_ = weights / weights.sum();
  c.means_ = std::move(means);
  c.variances_ = std::move(variances);
  c.Prepare();
  return c;
}

void ProsodyClusters::Prepare() {
  log_weight_ = weights_.array().max(1e-300).log();
  inv_var_ = variances_.cwiseInverse();
  log_norm_dim_ = -0.5 * (2.0 * std::numbers::pi * variances_.array()).log();
}

void ProsodyClusters::Posterior(const double* x, bool voiced, double* out) const {
  const int k = num_clusters();
  const int d0 = voiced ? 0 : 1;
  double mx = -std::numeric_limits<double>::infinity();
  for (int c = 0; c < k; ++c) {
    double l = log_weight_(c);
    for (int d = d0; d < 3; ++d) {
      const double diff = x[d] - means_(c, d);
      l += log_norm_dim_(c, d) - 0.5 * diff * diff * inv_var_(c, d);
    }
    out[c] = l;
    mx = std::max(mx, l);
  }
  double sum = 0.0;
  for (int c = 0; c < k; ++c) {
    out[c] = std::exp(out[c] - mx);
    sum += out[c];
  }
  const double inv = 1.0 / sum;
  for (int c = 0; c < k; ++c) out[c] *= inv;
}

RowMatrix ProsodyClusters::Posteriors(const InputMatrix& m) const {
  RowMatrix p(m.x.rows(), num_clusters());
  Eigen::Vector3d row;
  for (Eigen::Index t = 0; t < m.x.rows(); ++t) {
    row = m.x.row(t).transpose();
    Posterior(row.data(), m.voiced[t] != 0, p.row(t).data());
  }
  return p;
}

double ProsodyClusters::LogLikelihoodPerStep(const std::vector<InputMatrix>& data) const {
  double ll = 0.0;
  Eigen::Index n = 0;
  const int k = num_clusters();
  Eigen::VectorXd l(k);
  for (const auto& m : data) {
    for (Eigen::Index t = 0; t < m.x.rows(); ++t) {
      const int d0 = m.voiced[t] ? 0 : 1;
      for (int c = 0; c < k; ++c) {
        l(c) = log_weight_(c);
        for (int d = d0; d < 3; ++d) {
          const double diff = m.x(t, d) - means_(c, d);
          l(c) += log_norm_dim_(c, d) - 0.5 * diff * diff * inv_var_(c, d);
        }
      }
      const double mx = l.maxCoeff();
      ll += mx + std::log((l.array() - mx).exp().sum());
      ++n;
    }
  }
  return n > 0 ? ll / static_cast<double>(n) : 0.0;
}

StatusOr<ProsodyClusters> ProsodyClusters::Train(const std::vector<InputMatrix>& data,
                                                 const TrainParams& params) {
  Eigen::Index n = 0;
  for (const auto& m : data) n += m.x.rows();
  const int k = params.num_clusters;
  if (k < 1) return InvalidField("num_clusters", "must be ≥ 1");
  if (n < k) return InvalidField("inputs", n, " steps are fewer than ", k, " clusters");
  Eigen::MatrixXd all(n, 3);
  std::vector<unsigned char> voiced(n);
  {
    Eigen::Index r = 0;
    for (const auto& m : data) {
      all.middleRows(r, m.x.rows()) = m.x;
      std::copy(m.voiced.begin(), m.voiced.end(), voiced.begin() + r);
      r += m.x.rows();
    }
  }
  // Per-dimension data variance (voiced only for F0) for floors.
  Eigen::Vector3d var = Eigen::Vector3d::Ones();
  {
    Eigen::Vector3d s = Eigen::Vector3d::Zero(), s2 = Eigen::Vector3d::Zero(), c = Eigen::Vector3d::Zero();
    for (Eigen::Index t = 0; t < n; ++t) {
      for (int d = voiced[t] ? 0 : 1; d < 3; ++d) {
        s(d) += all(t, d);
        s2(d) += all(t, d) * all(t, d);
        c(d) += 1;
      }
    }
    for (int d = 0; d < 3; ++d) {
      if (c(d) > 1) var(d) = std::max(1e-12, s2(d) / c(d) - (s(d) / c(d)) * (s(d) / c(d)));
    }
  }
  const Eigen::Vector3d floor = var * params.variance_floor;
  // k-means++ over (I, L) plus F0 where voiced (unvoiced F0 was set to 0,
  // the normalised mean, for seeding only).
  std::mt19937_64 rng(params.seed * 31 + 5);
  std::vector<int> assign;
  Eigen::MatrixXd means = KMeansPlusPlus(all, k, 10, rng, &assign);
  Eigen::MatrixXd variances = var.transpose().replicate(k, 1);
  Eigen::VectorXd weights = Eigen::VectorXd::Constant(k, 1.0 / k);
  auto model_or = FromParameters(weights, means, variances);
  if (!model_or.ok()) return model_or.status();
  ProsodyClusters model = *std::move(model_or);
  double prev = -std::numeric_limits<double>::infinity();
  RowMatrix r(n, k);
  for (int it = 0; it < params.max_iterations; ++it) {
    for (Eigen::Index t = 0; t < n; ++t) {
      Eigen::Vector3d x = all.row(t).transpose();
      model.Posterior(x.data(), voiced[t] != 0, r.row(t).data());
    }
    Eigen::VectorXd w = r.colwise().sum().transpose();
    Eigen::MatrixXd sx = Eigen::MatrixXd::Zero(k, 3), sxx = Eigen::MatrixXd::Zero(k, 3),
                    sw = Eigen::MatrixXd::Zero(k, 3);
    for (Eigen::Index t = 0; t < n; ++t) {
      for (int d = voiced[t] ? 0 : 1; d < 3; ++d) {
        const double x = all(t, d);
        sw.col(d) += r.row(t).transpose();
        sx.col(d) += r.row(t).transpose() * x;
        sxx.col(d) += r.row(t).transpose() * (x * x);
      }
    }
    for (int c = 0; c < k; ++c) {
      for (int d = 0; d < 3; ++d) {
        if (sw(c, d) > 1e-8) {
          means(c, d) = sx(c, d) / sw(c, d);
          variances(c, d) = std::max(floor(d), sxx(c, d) / sw(c, d) - means(c, d) * means(c, d));
        } else {
          variances(c, d) = var(d);
        }
      }
    }
    weights = (w.array() + 1e-10) / (w.sum() + k * 1e-10);
    model_or = FromParameters(weights, means, variances);
    if (!model_or.ok()) return model_or.status();
    model = *std::move(model_or);
    const double ll = model.LogLikelihoodPerStep(data);
    if (it > 0 && std::abs(ll - prev) < params.tolerance * std::max(1.0, std::abs(ll))) break;
    prev = ll;
  }
  return model;
}

}  // namespace kinemo::inference

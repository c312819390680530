#include "services/inference/core/remapped_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>

namespace kinemo::inference {

Status ValidatePairedSequence(const PairedSequence& seq, std::string_view field) {
  KINEMO_RETURN_IF_ERROR(ValidateProsodySequence(seq.inputs, kinemo::StrCat(field, ".inputs")));
  if (seq.outputs.cols() != kKinematicDims)
    return InvalidField(kinemo::StrCat(field, ".outputs"), "has ", seq.outputs.cols(),
                        " dimensions, expected ", kKinematicDims);
  if (seq.outputs.rows() != static_cast<Eigen::Index>(seq.inputs.size()))
    return InvalidField(kinemo::StrCat(field, ".outputs"), "has ", seq.outputs.rows(),
                        " steps but inputs have ", seq.inputs.size());
  for (Eigen::Index t = 0; t < seq.outputs.rows(); ++t) {
    if (!seq.outputs.row(t).allFinite())
      return InvalidField(kinemo::StrCat(field, ".outputs[", t, "]"), "NaN or infinite value");
  }
  return absl::OkStatus();
}

Status ValidateTrainParams(const ModelTrainParams& p) {
  if (p.num_states < 2 || p.num_states > 200)
    return InvalidField("num_states", p.num_states, " is outside 2..200");
  if (p.window < 1 || p.window > 9) return InvalidField("window", p.window, " is outside 1..9");
  if (p.num_clusters < 1 || p.num_clusters > 100)
    return InvalidField("num_clusters", p.num_clusters, " is outside 1..100");
  if (p.hmm_restarts < 1 || p.hmm_restarts > 100)
    return InvalidField("hmm_restarts", p.hmm_restarts, " is outside 1..100");
  if (p.hmm_max_iterations < 1 || p.hmm_max_iterations > 100000)
    return InvalidField("hmm_max_iterations", p.hmm_max_iterations, " is outside 1..100000");
  if (!(p.hmm_tolerance > 0)) return InvalidField("hmm_tolerance", "must be > 0");
  if (!(p.crf_l2 >= 0) || !std::isfinite(p.crf_l2)) return InvalidField("crf_l2", "must be ≥ 0");
  if (p.crf_max_iterations < 1 || p.crf_max_iterations > 100000)
    return InvalidField("crf_max_iterations", p.crf_max_iterations, " is outside 1..100000");
  if (!(p.crf_tolerance > 0)) return InvalidField("crf_tolerance", "must be > 0");
  if (!(p.variance_floor > 0) || p.variance_floor >= 1)
    return InvalidField("variance_floor", "must be in (0, 1)");
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------
// Baseline

StatusOr<RemappedHmmBaseline> RemappedHmmBaseline::FromParameters(int window, int num_states,
                                                                  Eigen::MatrixXd means,
                                                                  Eigen::MatrixXd variances) {
  if (window < 1 || num_states < 1) return InvalidField("baseline", "bad window or states");
  if (means.rows() != window * num_states || means.cols() != kInputDims ||
      variances.rows() != means.rows() || variances.cols() != kInputDims)
    return InvalidField("baseline.means", "expected ", window * num_states, "x", kInputDims);
  if (!means.allFinite() || !variances.allFinite() || (variances.array() <= 0).any())
    return InvalidField("baseline", "non-finite or non-positive parameter");
  RemappedHmmBaseline b;
  b.window_ = window;
  b.num_states_ = num_states;
  b.means_ = std::move(means);
  b.variances_ = std::move(variances);
  return b;
}

RemappedHmmBaseline RemappedHmmBaseline::Fit(const std::vector<InputMatrix>& inputs,
                                             const std::vector<RowMatrix>& gammas, int window,
                                             double variance_floor) {
  const int s = static_cast<int>(gammas.front().cols());
  const int lo = RemappedCrf::WindowLow(window);
  Eigen::MatrixXd sw = Eigen::MatrixXd::Zero(window * s, 3), sx = sw, sxx = sw;
  Eigen::Vector3d gs = Eigen::Vector3d::Zero(), gs2 = gs, gc = gs;
  for (size_t q = 0; q < inputs.size(); ++q) {
    const auto& m = inputs[q];
    const auto& g = gammas[q];
    const Eigen::Index n = m.x.rows();
    for (Eigen::Index t = 0; t < n; ++t) {
      for (int o = 0; o < window; ++o) {
        const Eigen::Index src = t + lo + o;
        if (src < 0 || src >= n) continue;
        for (int d = m.voiced[src] ? 0 : 1; d < 3; ++d) {
          const double x = m.x(src, d);
          sw.block(o * s, d, s, 1) += g.row(t).transpose();
          sx.block(o * s, d, s, 1) += g.row(t).transpose() * x;
          sxx.block(o * s, d, s, 1) += g.row(t).transpose() * (x * x);
        }
      }
      for (int d = m.voiced[t] ? 0 : 1; d < 3; ++d) {
        gs(d) += m.x(t, d);
        gs2(d) += m.x(t, d) * m.x(t, d);
        gc(d) += 1;
      }
    }
  }
  Eigen::Vector3d var = Eigen::Vector3d::Ones();
  for (int d = 0; d < 3; ++d) {
    if (gc(d) > 1) var(d) = std::max(1e-12, gs2(d) / gc(d) - std::pow(gs(d) / gc(d), 2));
  }
  RemappedHmmBaseline b;
  b.window_ = window;
  b.num_states_ = s;
  b.means_ = Eigen::MatrixXd::Zero(window * s, 3);
  b.variances_ = Eigen::MatrixXd::Zero(window * s, 3);
  for (int r = 0; r < window * s; ++r) {
    for (int d = 0; d < 3; ++d) {
      if (sw(r, d) > 1e-8) {
        b.means_(r, d) = sx(r, d) / sw(r, d);
        b.variances_(r, d) =
            std::max(var(d) * variance_floor, sxx(r, d) / sw(r, d) - std::pow(b.means_(r, d), 2));
      } else {
        b.variances_(r, d) = var(d);
      }
    }
  }
  return b;
}

RowMatrix RemappedHmmBaseline::LogObservation(const InputMatrix& m) const {
  const int s = num_states_;
  const int lo = RemappedCrf::WindowLow(window_);
  const Eigen::Index n = m.x.rows();
  RowMatrix out = RowMatrix::Zero(n, s);
  const double log2pi = std::log(2.0 * std::numbers::pi);
  for (Eigen::Index t = 0; t < n; ++t) {
    for (int o = 0; o < window_; ++o) {
      const Eigen::Index src = t + lo + o;
      if (src < 0 || src >= n) continue;
      for (int d = m.voiced[src] ? 0 : 1; d < 3; ++d) {
        const double x = m.x(src, d);
        for (int i = 0; i < s; ++i) {
          const double mu = means_(o * s + i, d);
          const double v = variances_(o * s + i, d);
          out(t, i) += -0.5 * (log2pi + std::log(v) + (x - mu) * (x - mu) / v);
        }
      }
    }
  }
  return out;
}

// ---------------------------------------------------------------------------
// Model

StatusOr<RemappedModel> RemappedModel::FromParts(InputNormalizer normalizer,
                                                 ProsodyClusters clusters, GaussianHmm hmm,
                                                 RemappedCrf crf, RemappedHmmBaseline baseline) {
  if (hmm.num_states() != crf.num_states() || hmm.num_states() != baseline.num_states())
    return InvalidField("model", "HMM, CRF and baseline disagree on the number of states");
  if (hmm.dims() != kKinematicDims)
    return InvalidField("model.hmm", "has ", hmm.dims(), " dimensions, expected 6");
  if (crf.num_clusters() != clusters.num_clusters())
    return InvalidField("model.crf", "expects ", crf.num_clusters(), " clusters, model has ",
                        clusters.num_clusters());
  if (crf.window() != baseline.window())
    return InvalidField("model.baseline", "window differs from the CRF's");
  if (!normalizer.mean.allFinite() || !normalizer.scale.allFinite() ||
      (normalizer.scale.array() <= 0).any())
    return InvalidField("model.normalizer", "non-finite or non-positive value");
  RemappedModel m;
  m.normalizer_ = std::move(normalizer);
  m.clusters_ = std::move(clusters);
  m.hmm_ = std::move(hmm);
  m.crf_ = std::move(crf);
  m.baseline_ = std::move(baseline);
  return m;
}

RowMatrix RemappedModel::Features(std::span<const ProsodyStep> inputs) const {
  return RemappedCrf::WindowFeatures(clusters_.Posteriors(MakeInputMatrix(normalizer_, inputs)),
                                     crf_.window());
}

StatusOr<RemappedModel> RemappedModel::Train(const std::vector<PairedSequence>& data,
                                             const ModelTrainParams& params,
                                             const TrainProgress& progress, TrainReport* report) {
  const auto start = std::chrono::steady_clock::now();
  KINEMO_RETURN_IF_ERROR(ValidateTrainParams(params));
  if (data.empty()) return InvalidField("sequences", "empty training set");
  std::uint64_t total = 0;
  double data_s = 0.0;
  for (size_t k = 0; k < data.size(); ++k) {
    KINEMO_RETURN_IF_ERROR(ValidatePairedSequence(data[k], kinemo::StrCat("sequences[", k, "]")));
    total += data[k].inputs.size();
    data_s += std::max(0.0, data[k].inputs.back().end_s - data[k].inputs.front().start_s);
  }
  bool cancelled = false;
  auto report_progress = [&](std::string_view stage, double fraction, std::string_view msg) {
    if (progress && !cancelled && !progress(stage, fraction, msg)) cancelled = true;
    return !cancelled;
  };
  // 1. Λ_Y on the kinematic parameters.
  std::vector<Eigen::MatrixXd> ys;
  for (const auto& s : data) ys.push_back(s.outputs);
  HmmTrainParams hp;
  hp.num_states = params.num_states;
  hp.full_covariance = params.full_covariance;
  hp.restarts = params.hmm_restarts;
  hp.max_iterations = params.hmm_max_iterations;
  hp.tolerance = params.hmm_tolerance;
  hp.variance_floor = params.variance_floor;
  hp.seed = params.seed;
  hp.threads = params.threads;
  report_progress("hmm_em", 0.0, "");
  KINEMO_ASSIGN_OR_RETURN(
      GaussianHmm hmm,
      GaussianHmm::Train(ys, hp, [&](int restart, int it, double ll) {
        report_progress("hmm_em",
                        std::min(1.0, (restart + static_cast<double>(it) / hp.max_iterations) /
                                          hp.restarts),
                        kinemo::StrCat("restart ", restart, " iteration ", it, " ll/step ", ll));
      }));
  if (cancelled) return absl::CancelledError("training cancelled");
  const auto t_hmm = std::chrono::steady_clock::now();
  // 2. Clusters of the inputs.
  report_progress("clustering", 0.0, "");
  std::vector<std::vector<ProsodyStep>> xs;
  for (const auto& s : data) xs.push_back(s.inputs);
  InputNormalizer norm = InputNormalizer::Fit(xs);
  std::vector<InputMatrix> inputs;
  for (const auto& s : data) inputs.push_back(MakeInputMatrix(norm, s.inputs));
  ProsodyClusters::TrainParams cp;
  cp.num_clusters = params.num_clusters;
  cp.variance_floor = params.variance_floor;
  cp.seed = params.seed;
  KINEMO_ASSIGN_OR_RETURN(ProsodyClusters clusters, ProsodyClusters::Train(inputs, cp));
  if (!report_progress("clustering", 1.0, "")) return absl::CancelledError("training cancelled");
  const auto t_clusters = std::chrono::steady_clock::now();
  // 3. Targets from Λ_Y's posteriors, then the CRF.
  std::vector<CrfTarget> targets(data.size());
  std::vector<RowMatrix> gammas(data.size());
  double hmm_ll = 0.0;
  for (size_t k = 0; k < data.size(); ++k) {
    ChainPosteriors post;
    if (!hmm.Posteriors(data[k].outputs, &post))
      return absl::InternalError(kinemo::StrCat("sequences[", k, "]: no support under the HMM"));
    hmm_ll += post.log_z;
    targets[k].features =
        RemappedCrf::WindowFeatures(clusters.Posteriors(inputs[k]), params.window);
    targets[k].gamma = post.gamma;
    targets[k].xi_sum = post.xi_sum;
    gammas[k] = std::move(post.gamma);
  }
  CrfTrainParams crp;
  crp.l2 = params.crf_l2;
  crp.max_iterations = params.crf_max_iterations;
  crp.tolerance = params.crf_tolerance;
  int crf_iterations = 0;
  KINEMO_ASSIGN_OR_RETURN(
      RemappedCrf crf,
      RemappedCrf::Train(targets, params.num_states, params.window, params.num_clusters, crp,
                         [&](int it, double value) {
                           crf_iterations = it + 1;
                           return report_progress(
                               "crf_optimize",
                               std::min(1.0, static_cast<double>(it) / crp.max_iterations),
                               kinemo::StrCat("iteration ", it, " objective ", value));
                         }));
  if (cancelled) return absl::CancelledError("training cancelled");
  const auto t_crf = std::chrono::steady_clock::now();
  // 4. Baseline.
  report_progress("baseline", 0.0, "");
  RemappedHmmBaseline baseline =
      RemappedHmmBaseline::Fit(inputs, gammas, params.window, params.variance_floor);
  KINEMO_ASSIGN_OR_RETURN(RemappedModel model,
                          FromParts(std::move(norm), std::move(clusters), std::move(hmm),
                                    std::move(crf), std::move(baseline)));
  if (report != nullptr) {
    double crf_ll = 0.0;
    for (const auto& s : data) {
      KINEMO_ASSIGN_OR_RETURN(SequenceScore sc, model.Evaluate(s));
      crf_ll += sc.crf_ll_per_step * static_cast<double>(sc.steps);
    }
    report->hmm_ll_per_step = hmm_ll / static_cast<double>(total);
    report->crf_ll_per_step = crf_ll / static_cast<double>(total);
    report->steps = total;
    report->data_s = data_s;
    report->crf_iterations = crf_iterations;
    report->hmm_s = std::chrono::duration<double>(t_hmm - start).count();
    report->clustering_s = std::chrono::duration<double>(t_clusters - t_hmm).count();
    report->crf_s = std::chrono::duration<double>(t_crf - t_clusters).count();
    report->train_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return model;
}

StatusOr<InferenceResult> RemappedModel::Infer(std::span<const ProsodyStep> inputs, bool filtered,
                                               bool viterbi) const {
  KINEMO_RETURN_IF_ERROR(ValidateProsodySequence(inputs, "inputs"));
  const RowMatrix f = Features(inputs);
  InferenceResult r;
  ChainPosteriors post;
  if (!crf_.Posteriors(f, &post)) return absl::InternalError("inputs: no support under the CRF");
  r.smoothed = std::move(post.gamma);
  if (filtered) r.filtered = crf_.Filtered(f);
  if (viterbi) r.viterbi = crf_.Viterbi(f);
  return r;
}

StatusOr<SequenceScore> RemappedModel::Evaluate(const PairedSequence& seq) const {
  KINEMO_RETURN_IF_ERROR(ValidatePairedSequence(seq, seq.name.empty() ? "sequence" : seq.name));
  const auto n = static_cast<double>(seq.inputs.size());
  const RowMatrix log_y = hmm_.LogEmissions(seq.outputs);
  // CRF: P(Y|X) = Σ_q P(Y|q) P(q|X) = Z(φ + log N(y)) / Z(φ).
  const RowMatrix phi = crf_.LogNode(Features(seq.inputs));
  const double crf_num = ChainForward(phi + log_y, crf_.exp_transition(), crf_.exp_initial(), nullptr);
  const double crf_den = ChainForward(phi, crf_.exp_transition(), crf_.exp_initial(), nullptr);
  // Remapped HMM: P(Y|X) = P(X, Y) / P(X) with windowed emissions.
  const RowMatrix obs = baseline_.LogObservation(MakeInputMatrix(normalizer_, seq.inputs));
  const double hmm_num = ChainForward(obs + log_y, hmm_.transition(), hmm_.initial(), nullptr);
  const double hmm_den = ChainForward(obs, hmm_.transition(), hmm_.initial(), nullptr);
  SequenceScore s;
  s.steps = seq.inputs.size();
  s.crf_ll_per_step = (crf_num - crf_den) / n;
  s.hmm_ll_per_step = (hmm_num - hmm_den) / n;
  return s;
}

// ---------------------------------------------------------------------------
// Online filter

OnlineFilter::OnlineFilter(const RemappedModel& model)
    : model_(&model),
      s_(model.num_states()),
      k_(model.num_clusters()),
      w_(model.window()),
      lo_(RemappedCrf::WindowLow(model.window())),
      f_(RemappedCrf::FeatureCount(model.window(), model.num_clusters())),
      ring_(Eigen::VectorXd::Zero(static_cast<Eigen::Index>(w_) * k_)),
      feature_(Eigen::VectorXd::Zero(f_)),
      phi_(s_),
      alpha_(s_),
      tmp_(s_) {}

void OnlineFilter::Reset() {
  received_ = 0;
  emitted_ = 0;
}

void OnlineFilter::Emit(std::int64_t step, std::span<double> alpha) {
  ScopedFlushDenormals ftz;
  // Window features of `step` from the ring; steps outside [0, received_) are 0.
  for (int o = 0; o < w_; ++o) {
    const std::int64_t src = step + lo_ + o;
    double* dst = feature_.data() + static_cast<Eigen::Index>(o) * k_;
    if (src < 0 || src >= received_) {
      std::fill(dst, dst + k_, 0.0);
    } else {
      const double* from = ring_.data() + static_cast<Eigen::Index>(src % w_) * k_;
      std::copy(from, from + k_, dst);
    }
  }
  feature_(f_ - 1) = 1.0;
  const RemappedCrf& crf = model_->crf();
  phi_.noalias() = crf.observation_weights() * feature_;
  const double mx = phi_.maxCoeff();
  if (step == 0) {
    alpha_ = crf.exp_initial().cwiseProduct((phi_.array() - mx).exp().matrix());
  } else {
    tmp_.noalias() = crf.exp_transition().transpose() * alpha_;
    alpha_ = tmp_.cwiseProduct((phi_.array() - mx).exp().matrix());
  }
  alpha_ /= alpha_.sum();
  std::copy(alpha_.data(), alpha_.data() + s_, alpha.begin());
  ++emitted_;
}

bool OnlineFilter::Push(const ProsodyStep& x, std::span<double> alpha) {
  x_ = model_->normalizer().Apply(x);
  if (!x.voiced) x_(0) = 0.0;
  model_->clusters().Posterior(x_.data(), x.voiced,
                               ring_.data() + static_cast<Eigen::Index>(received_ % w_) * k_);
  ++received_;
  const std::int64_t ready = received_ - 1 - model_->lookahead();
  if (ready < emitted_) return false;
  Emit(emitted_, alpha);
  return true;
}

bool OnlineFilter::Finish(std::span<double> alpha) {
  if (emitted_ >= received_) return false;
  Emit(emitted_, alpha);
  return true;
}

}  // namespace kinemo::inference

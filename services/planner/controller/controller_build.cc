// Offline build of the Gesture Controller (Gesture Controllers §7.2 "Online
// Animation as a Markov Decision Process": value iteration and culling;
// Appendix A, the reduced value table; §8.1/§8.2 keyword states and style
// tables): Controller::Build, the Controller's accessors and the validation
// of its inputs. The runtime policy and frame assembly are in
// controller_runtime.cc, offline synthesis in controller_synthesis.cc.
#include "services/planner/controller/controller.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <thread>

#include "common/parallel/parallel.h"
#include "services/planner/controller/controller_internal.h"

namespace kinemo::planner::controller {

using internal::kInf;
using internal::Seconds;

Status ValidateStateModel(const StateModel& m) {
  const int s = m.num_states();
  if (s < 1 || s > 1000) return InvalidField("state_model.num_states", "must be in [1, 1000]");
  if (!m.initial.allFinite() || (m.initial.array() < 0).any() || std::abs(m.initial.sum() - 1) > 1e-6)
    return InvalidField("state_model.initial_probabilities", "must be S non-negative values summing to 1");
  if (m.transition.rows() != s || m.transition.cols() != s)
    return InvalidField("state_model.transition_probabilities", "must be S x S");
  if (!m.transition.allFinite() || (m.transition.array() < 0).any())
    return InvalidField("state_model.transition_probabilities", "must be finite and non-negative");
  for (int i = 0; i < s; ++i) {
    if (std::abs(m.transition.row(i).sum() - 1) > 1e-6)
      return InvalidField("state_model.transition_probabilities", "row ", i, " does not sum to 1");
  }
  if (static_cast<int>(m.means.size()) != s || static_cast<int>(m.covariances.size()) != s)
    return InvalidField("state_model.states", "must have S entries");
  for (int i = 0; i < s; ++i) {
    auto n = ExpectedNorm::Create(m.means[static_cast<size_t>(i)], m.covariances[static_cast<size_t>(i)]);
    if (!n.ok()) return Annotate(n.status(), kinemo::StrCat("state_model.states[", i, "]"));
  }
  return absl::OkStatus();
}

Status ValidateControllerParams(const ControllerParams& p) {
  if (!(p.discount > 0 && p.discount < 1)) return InvalidField("params.discount", "must be in (0, 1)");
  if (!(p.belief_step_s > 0 && p.belief_step_s <= 10)) return InvalidField("params.belief_step_s", "must be in (0, 10]");
  if (!(p.tolerance > 0) || !std::isfinite(p.tolerance)) return InvalidField("params.tolerance", "must be > 0");
  if (p.max_iterations < 1 || p.max_iterations > 100000) return InvalidField("params.max_iterations", "must be in [1, 100000]");
  if (!std::isfinite(p.semantic_cost) || p.semantic_cost < 0) return InvalidField("params.semantic_cost", "must be >= 0");
  if (!(p.semantic_start_max_fraction >= 0 && p.semantic_start_max_fraction < 1))
    return InvalidField("params.semantic_start_max_fraction", "must be in [0, 1)");
  if (p.threads < 0 || p.threads > 256) return InvalidField("params.threads", "must be in [0, 256]");
  if (p.tone_transfers.size() > 16) return InvalidField("params.tone_transforms", "at most 16 tones");
  for (size_t i = 0; i < p.tone_transfers.size(); ++i) {
    const std::string f = kinemo::StrCat("params.tone_transforms[", i, "]");
    KINEMO_RETURN_IF_ERROR(ValidateToneTransfer(p.tone_transfers[i], f));
    if (p.tone_transfers[i].name == p.neutral_tone) return InvalidField(f + ".name", "is the neutral tone");
    for (size_t j = 0; j < i; ++j)
      if (p.tone_transfers[j].name == p.tone_transfers[i].name) return InvalidField(f + ".name", "repeats '", p.tone_transfers[i].name, "'");
  }
  return Annotate(ValidateSegmentOptions(p.segmentation), "params.segmentation");
}

std::vector<std::string> Controller::style_tones() const {
  std::vector<std::string> out;
  for (const auto& t : tones_)
    if (!IsEmphasisTone(t)) out.push_back(t);
  return out;
}

int Controller::EmphasisIndex(int tone, double e) const {
  if (tone < 0 || tone >= num_tones() || IsEmphasisTone(tones_[static_cast<size_t>(tone)])) return -1;
  return ToneIndex(kinemo::StrCat(tones_[static_cast<size_t>(tone)], e >= 0 ? ":+" : ":-"));
}

Vector6 Controller::EmphasisShift() const {
  const int up = EmphasisIndex(0, 1);
  if (up < 0) return Vector6::Zero();
  return transforms_[static_cast<size_t>(up)].b - transforms_[0].b;
}

int Controller::ToneIndex(std::string_view tone) const {
  for (size_t i = 0; i < tones_.size(); ++i)
    if (tones_[i] == tone) return static_cast<int>(i);
  return -1;
}

int Controller::KeywordIndex(std::string_view word) const {
  const auto& k = keywords();
  auto it = std::lower_bound(k.begin(), k.end(), word);
  return it != k.end() && *it == word ? static_cast<int>(it - k.begin()) : -1;
}

bool Controller::Matches(int segment, int w) const {
  if (w <= 0) return false;
  const auto& s = segments_->segments[static_cast<size_t>(segment)];
  return s.stroke && std::find(s.keywords.begin(), s.keywords.end(), w - 1) != s.keywords.end();
}

std::span<const Controller::SemanticEntry> Controller::SemanticEntries(int w, int e) const {
  if (w <= 0) return {};
  const auto& off = sem_offsets_[static_cast<size_t>(w)];
  const auto& v = sem_[static_cast<size_t>(w)];
  return {v.data() + off[static_cast<size_t>(e)], static_cast<size_t>(off[static_cast<size_t>(e) + 1] - off[static_cast<size_t>(e)])};
}

std::span<const double> Controller::SemanticValues(int tone, int w, int index) const {
  const RowMatrix& m = sem_values_[Index(tone, w)];
  return {m.data() + static_cast<Eigen::Index>(index) * m.cols(), static_cast<size_t>(m.cols())};
}

std::span<const int> Controller::Kept(int w, int e) const {
  const auto& off = kept_offsets_[static_cast<size_t>(w)];
  const auto& v = kept_[static_cast<size_t>(w)];
  return {v.data() + off[static_cast<size_t>(e)], static_cast<size_t>(off[static_cast<size_t>(e) + 1] - off[static_cast<size_t>(e)])};
}

// ---------------------------------------------------------------------------
// Build

class ControllerBuilder {
 public:
  ControllerBuilder(Controller& c, const BuildProgress& progress) : c_(c), progress_(progress) {}

  Status Run(std::shared_ptr<const Library> library) {
    const auto t0 = std::chrono::steady_clock::now();
    BuildReport& r = c_.report_;
    threads_ = c_.params_.threads > 0 ? c_.params_.threads
                                      : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    KINEMO_RETURN_IF_ERROR(Progress("segments", 0));
    auto t = std::chrono::steady_clock::now();
    KINEMO_ASSIGN_OR_RETURN(c_.segments_, BuildSegmentLibrary(library, c_.params_.segmentation));
    const SegmentLibrary& L = *c_.segments_;
    N_ = L.num_segments();
    E_ = L.num_end_points();
    S_ = c_.model_.num_states();
    r.segment_s = Seconds(t);
    r.library_s = library->duration_s();
    r.segments = N_;
    r.end_points = E_;
    KINEMO_RETURN_IF_ERROR(Progress("segments", 1));

    KINEMO_RETURN_IF_ERROR(SetUpTones());
    // Per-frame chain and discount.
    const double dt = c_.frame_time_s();
    const double lambda = std::min(1.0, dt / c_.params_.belief_step_s);
    c_.frame_transition_ = (1 - lambda) * RowMatrix::Identity(S_, S_) + lambda * c_.model_.transition;
    eta_ = std::pow(c_.params_.discount, lambda);
    int lmax = 1;
    for (const auto& s : L.segments) lmax = std::max(lmax, s.num_frames + 1);
    pow_.resize(static_cast<size_t>(lmax) + 1);
    cum_.resize(static_cast<size_t>(lmax) + 1);
    eta_pow_.resize(static_cast<size_t>(lmax) + 1);
    pow_[0] = RowMatrix::Identity(S_, S_);
    cum_[0] = RowMatrix::Zero(S_, S_);
    eta_pow_[0] = 1;
    for (int l = 1; l <= lmax; ++l) {
      pow_[static_cast<size_t>(l)] = pow_[static_cast<size_t>(l) - 1] * c_.frame_transition_;
      cum_[static_cast<size_t>(l)] = cum_[static_cast<size_t>(l) - 1] + eta_pow_[static_cast<size_t>(l) - 1] * pow_[static_cast<size_t>(l) - 1];
      eta_pow_[static_cast<size_t>(l)] = eta_pow_[static_cast<size_t>(l) - 1] * eta_;
    }

    t = std::chrono::steady_clock::now();
    KINEMO_RETURN_IF_ERROR(ComputeDeltas());
    r.delta_s = Seconds(t);

    t = std::chrono::steady_clock::now();
    const int W = c_.num_keyword_states(), M = c_.num_tones();
    c_.u_.resize(static_cast<size_t>(M * W));
    c_.vc_.resize(static_cast<size_t>(M * W));
    c_.sem_.assign(static_cast<size_t>(W), {});
    c_.sem_offsets_.assign(static_cast<size_t>(W), std::vector<int>(static_cast<size_t>(E_) + 1, 0));
    c_.sem_values_.resize(static_cast<size_t>(M * W));
    for (int w = 1; w < W; ++w) BuildSemanticEntries(w);
    int done = 0;
    for (int w = 0; w < W; ++w) {
      for (int m = 0; m < M; ++m) {
        KINEMO_RETURN_IF_ERROR(ValueIteration(m, w));
        KINEMO_RETURN_IF_ERROR(Progress("value_iteration", static_cast<double>(++done) / (M * W)));
      }
    }
    r.value_iteration_s = Seconds(t);

    t = std::chrono::steady_clock::now();
    Cull();
    r.culling_s = Seconds(t);
    KINEMO_RETURN_IF_ERROR(Progress("culling", 1));
    r.train_s = Seconds(t0);
    return absl::OkStatus();
  }

 private:
  Status Progress(std::string_view stage, double f) {
    if (progress_ && !progress_(stage, f)) return absl::CancelledError("build cancelled");
    return absl::OkStatus();
  }

  Status SetUpTones() {
    const SegmentLibrary& L = *c_.segments_;
    const auto& transfers = c_.params_.tone_transfers;
    auto transfer_of = [&](const std::string& tone) -> const ToneTransfer* {
      for (const auto& t : transfers)
        if (t.name == tone) return &t;
      return nullptr;
    };
    auto& tones = c_.tones_;
    tones = c_.params_.tones.empty() ? L.tones : c_.params_.tones;
    if (c_.params_.tones.empty()) {
      for (const auto& t : transfers) tones.push_back(t.name);
      // Transferred tones need the neutral one beside them.
      if (!transfers.empty()) tones.push_back(c_.params_.neutral_tone);
    }
    std::sort(tones.begin(), tones.end());
    tones.erase(std::unique(tones.begin(), tones.end()), tones.end());
    for (size_t i = 0; i < tones.size(); ++i) {
      if (!std::binary_search(L.tones.begin(), L.tones.end(), tones[i]) && transfer_of(tones[i]) == nullptr &&
          tones[i] != c_.params_.neutral_tone)
        return InvalidField(kinemo::StrCat("params.tones[", i, "]"), "'", tones[i],
                            "' is not a tone of the library nor of params.tone_transforms");
      if (Controller::IsEmphasisTone(tones[i]))
        return InvalidField(kinemo::StrCat("params.tones[", i, "]"), "'", tones[i],
                            "': ':' is reserved for the gesture-emphasis tables (rename the library's tone)");
    }
    auto rows_of = [&](const std::string& tone) {
      const int ti = static_cast<int>(std::lower_bound(L.tones.begin(), L.tones.end(), tone) - L.tones.begin());
      std::vector<int> idx;
      for (int a = 0; a < N_; ++a)
        if (ti < static_cast<int>(L.tones.size()) && L.tones[static_cast<size_t>(ti)] == tone &&
            L.segments[static_cast<size_t>(a)].tone == ti)
          idx.push_back(a);
      Eigen::MatrixXd x(static_cast<Eigen::Index>(idx.size()), 6);
      for (size_t k = 0; k < idx.size(); ++k)
        x.row(static_cast<Eigen::Index>(k)) = L.segments[static_cast<size_t>(idx[k])].params.transpose();
      return x;
    };
    const Eigen::MatrixXd neutral = rows_of(c_.params_.neutral_tone);
    // The library's neutral mean (every segment's if none is tagged neutral):
    // where transferred tones are applied.
    Vector6 target_mean = Vector6::Zero();
    if (neutral.rows() > 0) {
      target_mean = neutral.colwise().mean().transpose();
    } else if (N_ > 0) {
      for (const auto& s : L.segments) target_mean += s.params;
      target_mean /= N_;
    }
    for (const auto& tone : tones) {
      StyleTransform tr;
      if (const ToneTransfer* t = transfer_of(tone); t != nullptr) {
        tr = ApplyTransfer(*t, target_mean);
      } else if (tone != c_.params_.neutral_tone) {
        if (neutral.rows() < 2) {
          c_.report_.warnings.push_back(kinemo::StrCat("tone '", tone, "': no neutral ('", c_.params_.neutral_tone,
                                                       "') segments to fit T_m against; identity used"));
        } else {
          auto fit = FitStyleTransform(neutral, rows_of(tone));
          if (fit.ok()) {
            tr = *fit;
          } else {
            c_.report_.warnings.push_back(kinemo::StrCat("tone '", tone, "': ", fit.status().message(), "; identity used"));
          }
        }
      }
      c_.transforms_.push_back(tr);
    }
    // Gesture emphasis (header comment): each tone's target shifted by ±σ of
    // the library's neutral segments (all segments without neutral ones) on
    // D V A C H.
    const Eigen::MatrixXd base = neutral.rows() >= 2 ? neutral : AllParams();
    Vector6 shift = Vector6::Zero();
    if (base.rows() >= 2) {
      const Eigen::RowVectorXd mean = base.colwise().mean();
      for (int j = 1; j < 6; ++j)
        shift(j) = std::sqrt((base.col(j).array() - mean(j)).square().sum() / static_cast<double>(base.rows() - 1));
    }
    const size_t style_tones = tones.size();
    for (size_t m = 0; m < style_tones; ++m) {
      for (const double sign : {1.0, -1.0}) {
        tones.push_back(kinemo::StrCat(tones[m], sign > 0 ? ":+" : ":-"));
        StyleTransform tr = c_.transforms_[m];
        tr.b += sign * shift;
        c_.transforms_.push_back(tr);
      }
    }
    return absl::OkStatus();
  }

  Eigen::MatrixXd AllParams() const {
    const SegmentLibrary& L = *c_.segments_;
    Eigen::MatrixXd x(N_, 6);
    for (int a = 0; a < N_; ++a) x.row(a) = L.segments[static_cast<size_t>(a)].params.transpose();
    return x;
  }

  Status ComputeDeltas() {
    const SegmentLibrary& L = *c_.segments_;
    const int M = c_.num_tones();
    c_.delta_.assign(static_cast<size_t>(M), RowMatrix(N_, S_));
    for (int m = 0; m < M; ++m) {
      const StyleTransform& tr = c_.transforms_[static_cast<size_t>(m)];
      std::vector<ExpectedNorm> norms;
      for (int i = 0; i < S_; ++i) {
        const Vector6 mu = tr.A * c_.model_.means[static_cast<size_t>(i)] + tr.b;
        Matrix6 cov = tr.A * c_.model_.covariances[static_cast<size_t>(i)] * tr.A.transpose();
        cov = 0.5 * (cov + cov.transpose()).eval();
        auto n = ExpectedNorm::Create(mu, cov);
        if (!n.ok()) return Annotate(n.status(), kinemo::StrCat("state_model.states[", i, "]"));
        norms.push_back(*std::move(n));
      }
      RowMatrix& d = c_.delta_[static_cast<size_t>(m)];
      parallel::ParallelForRanges(N_, threads_, [&](int lo, int hi, int) {
        for (int a = lo; a < hi; ++a)
          for (int i = 0; i < S_; ++i) d(a, i) = norms[static_cast<size_t>(i)].Of(L.segments[static_cast<size_t>(a)].params);
      });
      KINEMO_RETURN_IF_ERROR(Progress("delta", static_cast<double>(m + 1) / M));
    }
    return absl::OkStatus();
  }

  // Semantic entries of keyword state w (values filled in ValueIteration(·, w)).
  void BuildSemanticEntries(int w) {
    const SegmentLibrary& L = *c_.segments_;
    std::vector<int> strokes;
    for (int b = 0; b < N_; ++b)
      if (c_.Matches(b, w)) strokes.push_back(b);
    auto& list = c_.sem_[static_cast<size_t>(w)];
    auto& off = c_.sem_offsets_[static_cast<size_t>(w)];
    for (int e = 0; e < E_; ++e) {
      off[static_cast<size_t>(e)] = static_cast<int>(list.size());
      for (int b : strokes) {
        const auto& sb = L.segments[static_cast<size_t>(b)];
        const int fmax = static_cast<int>(std::floor(c_.params_.semantic_start_max_fraction * (sb.num_frames - 1)));
        const auto& ep = L.end_points[static_cast<size_t>(e)];
        int best_f = 0;
        double best = kInf;
        for (int f = 0; f <= fmax; ++f) {
          const double d = L.PoseDistance(ep.segment, ep.frame, b, f);
          if (d < best) {
            best = d;
            best_f = f;
          }
        }
        Controller::SemanticEntry s;
        s.e = e;
        s.segment = b;
        s.start = best_f;
        s.h = static_cast<int>(std::lower_bound(sb.ends.begin(), sb.ends.end(), best_f) - sb.ends.begin());
        s.cost = L.InterruptCost(e, b, best_f);
        list.push_back(s);
      }
    }
    off[static_cast<size_t>(E_)] = static_cast<int>(list.size());
  }

  // F_L(e', ·) in table (m, 0) for a block of L frames into e' (semantic entries).
  void FutureNone(int m, int ep, int l, const RowMatrix& ml, double* f) const {
    const SegmentLibrary& L = *c_.segments_;
    const RowMatrix& U = c_.u_[c_.Index(m, 0)];
    const RowMatrix& Vc = c_.vc_[c_.Index(m, 0)];
    (void)U;
    for (int i = 0; i < S_; ++i) f[i] = kInf;
    if (!L.end_points[static_cast<size_t>(ep)].last) {
      const Eigen::VectorXd pv = pow_[static_cast<size_t>(l)] * Vc.row(ep).transpose();
      for (int i = 0; i < S_; ++i) f[i] = pv(i);
    }
    const float* srow = L.transition.data() + static_cast<size_t>(ep) * N_;
    for (int b = 0; b < N_; ++b) {
      const double s = srow[b];
      const double* mr = ml.data() + static_cast<Eigen::Index>(b) * S_;
      for (int i = 0; i < S_; ++i) f[i] = std::min(f[i], s + mr[i]);
    }
  }

  Status ValueIteration(int m, int w) {
    const SegmentLibrary& L = *c_.segments_;
    const RowMatrix& delta = c_.delta_[static_cast<size_t>(m)];
    const double csem = c_.params_.semantic_cost;
    std::vector<char> match(static_cast<size_t>(N_), 0);
    for (int b = 0; b < N_; ++b) match[static_cast<size_t>(b)] = c_.Matches(b, w) ? 1 : 0;
    // Immediate block costs.
    RowMatrix u_imm(N_, S_), vc_imm = RowMatrix::Zero(E_, S_);
    for (int a = 0; a < N_; ++a) {
      const auto& sa = L.segments[static_cast<size_t>(a)];
      const double extra = (w > 0 && !match[static_cast<size_t>(a)]) ? csem : 0.0;
      u_imm.row(a) = ((cum_[static_cast<size_t>(sa.ends[0]) + 1] * delta.row(a).transpose()).transpose().array() + extra).matrix();
      for (size_t k = 0; k + 1 < sa.ends.size(); ++k) {
        const int l = sa.ends[k + 1] - sa.ends[k];
        vc_imm.row(sa.first_end + static_cast<int>(k)) =
            ((cum_[static_cast<size_t>(l)] * delta.row(a).transpose()).transpose().array() + extra).matrix();
      }
    }
    RowMatrix& U = c_.u_[c_.Index(m, w)];
    RowMatrix& Vc = c_.vc_[c_.Index(m, w)];
    const RowMatrix* vc_none = w > 0 ? &c_.vc_[c_.Index(m, 0)] : nullptr;
    if (w == 0) {
      U = u_imm;
      Vc = vc_imm;
    } else {
      U = (c_.u_[c_.Index(m, 0)].array() + csem).matrix();
      Vc = (c_.vc_[c_.Index(m, 0)].array() + csem).matrix();
      for (int a = 0; a < N_; ++a)
        if (match[static_cast<size_t>(a)]) {
          const auto& sa = L.segments[static_cast<size_t>(a)];
          for (size_t k = 0; k < sa.ends.size(); ++k) Vc.row(sa.first_end + static_cast<int>(k)) = vc_none->row(sa.first_end + static_cast<int>(k));
        }
    }
    // Semantic entry values (future in table w = 0, which is final) and their
    // propagation by the block into their origin end point.
    const auto& sem = c_.sem_[static_cast<size_t>(std::max(0, w))];
    RowMatrix& sv = c_.sem_values_[c_.Index(m, w)];
    RowMatrix psv;
    if (w > 0) {
      sv.resize(static_cast<Eigen::Index>(sem.size()), S_);
      std::map<int, RowMatrix> ml_cache;
      const RowMatrix& U0 = c_.u_[c_.Index(m, 0)];
      for (const auto& s : sem) {
        const auto& sb = L.segments[static_cast<size_t>(s.segment)];
        const int l = sb.ends[static_cast<size_t>(s.h)] - s.start + 1;
        if (!ml_cache.count(l)) ml_cache[l] = U0 * pow_[static_cast<size_t>(l)].transpose();
      }
      // The block and future after a semantic entry depend only on (b, start):
      // computed once per distinct pair.
      std::map<std::pair<int, int>, int> tail_index;
      std::vector<std::pair<int, int>> tails;
      for (const auto& s : sem) {
        if (tail_index.emplace(std::make_pair(s.segment, s.start), static_cast<int>(tails.size())).second)
          tails.emplace_back(s.segment, s.start);
      }
      RowMatrix tail(static_cast<Eigen::Index>(tails.size()), S_);
      parallel::ParallelForRanges(static_cast<int>(tails.size()), threads_, [&](int lo, int hi, int) {
        std::vector<double> f(static_cast<size_t>(S_));
        for (int k = lo; k < hi; ++k) {
          const auto [b, start] = tails[static_cast<size_t>(k)];
          const auto& sb = L.segments[static_cast<size_t>(b)];
          const int h = static_cast<int>(std::lower_bound(sb.ends.begin(), sb.ends.end(), start) - sb.ends.begin());
          const int l = sb.ends[static_cast<size_t>(h)] - start + 1;
          FutureNone(m, sb.first_end + h, l, ml_cache.at(l), f.data());
          const Eigen::VectorXd block = cum_[static_cast<size_t>(l)] * delta.row(b).transpose();
          for (int i = 0; i < S_; ++i) tail(k, i) = block(i) + eta_pow_[static_cast<size_t>(l)] * f[static_cast<size_t>(i)];
        }
      });
      for (size_t k = 0; k < sem.size(); ++k) {
        const int ti = tail_index.at({sem[k].segment, sem[k].start});
        sv.row(static_cast<Eigen::Index>(k)) = (tail.row(ti).array() + sem[k].cost).matrix();
      }
      psv.resize(sv.rows(), S_);
      for (Eigen::Index k = 0; k < sv.rows(); ++k) {
        const int l = L.end_points[static_cast<size_t>(sem[static_cast<size_t>(k)].e)].block_in;
        psv.row(k) = (pow_[static_cast<size_t>(l)] * sv.row(k).transpose()).transpose();
      }
    }
    // Distinct incoming block lengths.
    std::vector<int> ls;
    for (const auto& ep : L.end_points) ls.push_back(ep.block_in);
    std::sort(ls.begin(), ls.end());
    ls.erase(std::unique(ls.begin(), ls.end()), ls.end());
    std::vector<int> l_index(pow_.size(), -1);
    for (size_t k = 0; k < ls.size(); ++k) l_index[static_cast<size_t>(ls[k])] = static_cast<int>(k);
    std::vector<RowMatrix> ml(ls.size(), RowMatrix(N_, S_));
    const auto& sem_off = c_.sem_offsets_[static_cast<size_t>(std::max(0, w))];

    double change = kInf;
    int it = 0;
    std::vector<double> thread_change(static_cast<size_t>(threads_));
    while (change >= c_.params_.tolerance && it < c_.params_.max_iterations) {
      ++it;
      parallel::ParallelForRanges(static_cast<int>(ls.size()), threads_, [&](int lo, int hi, int) {
        for (int k = lo; k < hi; ++k) ml[static_cast<size_t>(k)].noalias() = U * pow_[static_cast<size_t>(ls[static_cast<size_t>(k)])].transpose();
      });
      std::fill(thread_change.begin(), thread_change.end(), 0.0);
      parallel::ParallelForRanges(N_, threads_, [&](int lo, int hi, int th) {
        std::vector<double> f(static_cast<size_t>(S_));
        Eigen::VectorXd pv(S_);
        double ch = 0;
        for (int a = lo; a < hi; ++a) {
          const auto& sa = L.segments[static_cast<size_t>(a)];
          const bool fixed = w > 0 && match[static_cast<size_t>(a)];
          for (int k = static_cast<int>(sa.ends.size()) - 1; k >= 0; --k) {
            const int e = sa.first_end + k;
            const auto& ep = L.end_points[static_cast<size_t>(e)];
            const int l = ep.block_in;
            const RowMatrix& M = ml[static_cast<size_t>(l_index[static_cast<size_t>(l)])];
            for (int i = 0; i < S_; ++i) f[static_cast<size_t>(i)] = kInf;
            if (!ep.last) {
              pv.noalias() = pow_[static_cast<size_t>(l)] * Vc.row(e).transpose();
              for (int i = 0; i < S_; ++i) f[static_cast<size_t>(i)] = pv(i);
            }
            const float* srow = L.transition.data() + static_cast<size_t>(e) * N_;
            for (int b = 0; b < N_; ++b) {
              if (w > 0 && match[static_cast<size_t>(b)]) continue;
              const double s = srow[b];
              const double* mr = M.data() + static_cast<Eigen::Index>(b) * S_;
              for (int i = 0; i < S_; ++i) f[static_cast<size_t>(i)] = std::min(f[static_cast<size_t>(i)], s + mr[i]);
            }
            if (w > 0) {
              for (int q = sem_off[static_cast<size_t>(e)]; q < sem_off[static_cast<size_t>(e) + 1]; ++q)
                for (int i = 0; i < S_; ++i) f[static_cast<size_t>(i)] = std::min(f[static_cast<size_t>(i)], psv(q, i));
            }
            const double g = eta_pow_[static_cast<size_t>(l)];
            if (k > 0) {
              if (fixed) continue;
              for (int i = 0; i < S_; ++i) {
                const double v = vc_imm(e - 1, i) + g * f[static_cast<size_t>(i)];
                ch = std::max(ch, std::abs(v - Vc(e - 1, i)));
                Vc(e - 1, i) = v;
              }
            } else {
              for (int i = 0; i < S_; ++i) {
                const double v = u_imm(a, i) + g * f[static_cast<size_t>(i)];
                if (!fixed) ch = std::max(ch, std::abs(v - U(a, i)));
                U(a, i) = v;
              }
            }
          }
        }
        thread_change[static_cast<size_t>(th)] = ch;
      });
      change = *std::max_element(thread_change.begin(), thread_change.end());
    }
    c_.report_.iterations += it;
    c_.report_.final_change = std::max(c_.report_.final_change, change);
    if (change >= c_.params_.tolerance) {
      c_.report_.warnings.push_back(kinemo::StrCat("value iteration (tone ", c_.tones_[static_cast<size_t>(m)], ", keyword state ", w,
                                                   ") stopped at max_iterations with change ", change));
    }
    return absl::OkStatus();
  }

  void Cull() {
    const SegmentLibrary& L = *c_.segments_;
    const int W = c_.num_keyword_states(), M = c_.num_tones();
    const int D = M * S_;
    BuildReport& r = c_.report_;
    c_.kept_offsets_.assign(static_cast<size_t>(W), {});
    c_.kept_.assign(static_cast<size_t>(W), {});
    std::uint64_t total = 0, kept_normal = 0, extra = 0;
    for (int w = 0; w < W; ++w) {
      std::vector<char> allowed(static_cast<size_t>(N_), 1);
      for (int b = 0; b < N_; ++b) allowed[static_cast<size_t>(b)] = !(w > 0 && c_.Matches(b, w));
      std::vector<std::vector<int>> kept(static_cast<size_t>(E_));
      parallel::ParallelForRanges(E_, threads_, [&](int lo, int hi, int) {
        std::vector<double> front;     // rows of D values
        std::vector<double> cand;      // N × D
        std::vector<std::pair<double, int>> order;
        cand.resize(static_cast<size_t>(N_) * D);
        for (int e = lo; e < hi; ++e) {
          auto& out = kept[static_cast<size_t>(e)];
          const float* srow = L.transition.data() + static_cast<size_t>(e) * N_;
          if (c_.params_.disable_culling) {
            for (int b = 0; b < N_; ++b)
              if (allowed[static_cast<size_t>(b)]) out.push_back(b);
            continue;
          }
          front.clear();
          order.clear();
          if (!L.end_points[static_cast<size_t>(e)].last) {
            for (int m = 0; m < M; ++m)
              for (int i = 0; i < S_; ++i) front.push_back(c_.vc_[c_.Index(m, w)](e, i));
          }
          if (w > 0) {
            const auto& off = c_.sem_offsets_[static_cast<size_t>(w)];
            for (int q = off[static_cast<size_t>(e)]; q < off[static_cast<size_t>(e) + 1]; ++q)
              for (int m = 0; m < M; ++m)
                for (int i = 0; i < S_; ++i) front.push_back(c_.sem_values_[c_.Index(m, w)](q, i));
          }
          for (int b = 0; b < N_; ++b) {
            if (!allowed[static_cast<size_t>(b)]) continue;
            double* v = &cand[static_cast<size_t>(b) * D];
            double sum = 0;
            for (int m = 0; m < M; ++m) {
              const double* u = c_.u_[c_.Index(m, w)].data() + static_cast<Eigen::Index>(b) * S_;
              for (int i = 0; i < S_; ++i) {
                v[m * S_ + i] = srow[b] + u[i];
                sum += v[m * S_ + i];
              }
            }
            order.emplace_back(sum, b);
          }
          std::sort(order.begin(), order.end());
          for (const auto& [sum, b] : order) {
            const double* v = &cand[static_cast<size_t>(b) * D];
            bool dominated = false;
            for (size_t fr = 0; fr < front.size() && !dominated; fr += static_cast<size_t>(D)) {
              int k = 0;
              while (k < D && front[fr + static_cast<size_t>(k)] <= v[k]) ++k;
              dominated = k == D;
            }
            if (!dominated) {
              out.push_back(b);
              front.insert(front.end(), v, v + D);
            }
          }
          std::sort(out.begin(), out.end());
        }
      });
      auto& off = c_.kept_offsets_[static_cast<size_t>(w)];
      auto& flat = c_.kept_[static_cast<size_t>(w)];
      off.assign(static_cast<size_t>(E_) + 1, 0);
      for (int e = 0; e < E_; ++e) {
        off[static_cast<size_t>(e)] = static_cast<int>(flat.size());
        flat.insert(flat.end(), kept[static_cast<size_t>(e)].begin(), kept[static_cast<size_t>(e)].end());
        if (!L.end_points[static_cast<size_t>(e)].last) ++extra;
      }
      off[static_cast<size_t>(E_)] = static_cast<int>(flat.size());
      const std::uint64_t allowed_n = static_cast<std::uint64_t>(std::count(allowed.begin(), allowed.end(), 1));
      total += allowed_n * static_cast<std::uint64_t>(E_);
      kept_normal += flat.size();
      extra += c_.sem_[static_cast<size_t>(w)].size();
    }
    r.entries_total = total;
    r.entries = kept_normal + extra;
    r.culled_fraction = total > 0 ? 1.0 - static_cast<double>(kept_normal) / static_cast<double>(total) : 0.0;
  }

  Controller& c_;
  const BuildProgress& progress_;
  int threads_ = 1, N_ = 0, E_ = 0, S_ = 0;
  double eta_ = 0.9;
  std::vector<RowMatrix> pow_, cum_;
  std::vector<double> eta_pow_;
};

StatusOr<std::shared_ptr<const Controller>> Controller::Build(std::shared_ptr<const Library> library,
                                                              const StateModel& model, const ControllerParams& params,
                                                              const BuildProgress& progress, BuildReport* report) {
  KINEMO_RETURN_IF_ERROR(ValidateControllerParams(params));
  KINEMO_RETURN_IF_ERROR(ValidateStateModel(model));
  if (library == nullptr || library->clips.empty()) return InvalidField("library", "has no clips");
  auto c = std::shared_ptr<Controller>(new Controller());
  c->params_ = params;
  c->model_ = model;
  ControllerBuilder builder(*c, progress);
  KINEMO_RETURN_IF_ERROR(builder.Run(std::move(library)));
  if (report != nullptr) *report = c->report_;
  return std::shared_ptr<const Controller>(std::move(c));
}

}  // namespace kinemo::planner::controller

#include "services/planner/controller/controller.h"

#include <algorithm>
#include <numbers>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <thread>

#include <Eigen/Geometry>

#include "common/motion/body_regions.h"
#include "common/parallel/parallel.h"
#include "common/motion/kinematics.h"
#include "services/planner/library/feet.h"

namespace kinemo::planner::controller {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

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

// ---------------------------------------------------------------------------
// Policy

Policy::Policy(const Controller& controller, double min_play_s)
    : c_(controller),
      alpha_(controller.state_model().initial),
      tmp_(controller.num_states()),
      style_(Eigen::VectorXd::Zero(controller.num_tones())),
      min_play_frames_(std::max(0, static_cast<int>(std::lround(min_play_s / controller.frame_time_s())))) {
  const int neutral = c_.ToneIndex(c_.params().neutral_tone);
  style_(neutral >= 0 ? neutral : 0) = 1;
}

Status Policy::SetBelief(std::span<const double> p) {
  if (static_cast<int>(p.size()) != c_.num_states())
    return InvalidField("probabilities", "has ", p.size(), " values, the controller has ", c_.num_states(), " states");
  double sum = 0;
  for (double v : p) {
    if (!std::isfinite(v) || v < 0) return InvalidField("probabilities", "must be finite and non-negative");
    sum += v;
  }
  if (!(sum > 0)) return InvalidField("probabilities", "sum to 0");
  for (size_t i = 0; i < p.size(); ++i) alpha_(static_cast<Eigen::Index>(i)) = p[i] / sum;
  return absl::OkStatus();
}

void Policy::Advance() {
  tmp_.noalias() = c_.frame_transition().transpose() * alpha_;
  alpha_.swap(tmp_);
}

Status Policy::SetStyle(std::span<const double> weights) {
  if (static_cast<int>(weights.size()) != c_.num_tones())
    return InvalidField("style", "has ", weights.size(), " weights, the controller has ", c_.num_tones(), " tones");
  double sum = 0;
  for (double v : weights) {
    if (!std::isfinite(v) || v < 0) return InvalidField("style", "weights must be finite and non-negative");
    sum += v;
  }
  if (!(sum > 0)) return InvalidField("style", "weights sum to 0");
  for (size_t i = 0; i < weights.size(); ++i) style_(static_cast<Eigen::Index>(i)) = weights[i] / sum;
  return absl::OkStatus();
}

Status Policy::SetKeyword(int keyword) {
  if (keyword < -1 || keyword >= static_cast<int>(c_.keywords().size()))
    return InvalidField("keyword", keyword, " is out of range");
  keyword_ = keyword;
  return absl::OkStatus();
}

Decision Policy::Start() {
  const int w = keyword_ + 1;
  const int S = c_.num_states(), M = c_.num_tones();
  Decision best;
  best.expected_cost = kInf;
  for (int b = 0; b < c_.segments().num_segments(); ++b) {
    if (w > 0 && c_.Matches(b, w)) continue;
    double v = 0;
    for (int m = 0; m < M; ++m) {
      if (style_(m) == 0) continue;
      const double* u = c_.U(m, w).data() + static_cast<Eigen::Index>(b) * S;
      double dot = 0;
      for (int i = 0; i < S; ++i) dot += alpha_(i) * u[i];
      v += style_(m) * dot;
    }
    if (v < best.expected_cost) {
      best.expected_cost = v;
      best.segment = b;
    }
  }
  best.end_point = c_.segments().segments[static_cast<size_t>(best.segment)].first_end;
  play_segment_ = best.segment;
  play_start_ = best.start;
  return best;
}

Decision Policy::Decide(int e) {
  const SegmentLibrary& L = c_.segments();
  const EndPoint& ep = L.end_points[static_cast<size_t>(e)];
  const auto& sa = L.segments[static_cast<size_t>(ep.segment)];
  const int w = keyword_ + 1;
  const int S = c_.num_states(), M = c_.num_tones();
  auto dot_row = [&](auto&& row_of) {
    double v = 0;
    for (int m = 0; m < M; ++m) {
      if (style_(m) == 0) continue;
      const double* r = row_of(m);
      double d = 0;
      for (int i = 0; i < S; ++i) d += alpha_(i) * r[i];
      v += style_(m) * d;
    }
    return v;
  };
  Decision best;
  best.expected_cost = kInf;
  if (!ep.last) {
    best.expected_cost = dot_row([&](int m) { return c_.Vc(m, w).data() + static_cast<Eigen::Index>(e) * S; });
    best.segment = ep.segment;
    best.start = ep.frame + 1;
    best.end_point = e + 1;
    best.continuation = true;
    if (w > 0 && c_.Matches(ep.segment, w)) best.keyword = keyword_;
    // A young play continues (no pending keyword): see kDefaultMinPlaySeconds.
    if (w == 0 && ep.segment == play_segment_ && ep.frame + 1 - play_start_ < min_play_frames_) return best;
  }
  const float* srow = L.transition.data() + static_cast<size_t>(e) * L.num_segments();
  for (int b : c_.Kept(w, e)) {
    const double v = srow[b] + dot_row([&](int m) { return c_.U(m, w).data() + static_cast<Eigen::Index>(b) * S; });
    if (v < best.expected_cost) {
      best = Decision{};
      best.expected_cost = v;
      best.segment = b;
      best.end_point = L.segments[static_cast<size_t>(b)].first_end;
      best.interrupted = !ep.last;
    }
  }
  if (w > 0) {
    const auto entries = c_.SemanticEntries(w, e);
    const int base = c_.SemanticBase(w, e);
    for (size_t q = 0; q < entries.size(); ++q) {
      const double v = dot_row([&](int m) { return c_.SemanticValues(m, w, base + static_cast<int>(q)).data(); });
      if (v < best.expected_cost) {
        const auto& s = entries[q];
        best = Decision{};
        best.expected_cost = v;
        best.segment = s.segment;
        best.start = s.start;
        best.end_point = L.segments[static_cast<size_t>(s.segment)].first_end + s.h;
        best.interrupted = !ep.last;
        best.keyword = keyword_;
      }
    }
  }
  (void)sa;
  if (best.keyword >= 0) keyword_ = -1;
  if (!best.continuation) {
    play_segment_ = best.segment;
    play_start_ = best.start;
  }
  return best;
}

// ---------------------------------------------------------------------------
// Frame assembly

FrameAssembler::FrameAssembler(const SegmentLibrary& segments, int blend_frames, const motion::FootPlantParams& feet)
    : s_(segments),
      skel_(segments.library->skeleton),
      blend_frames_(std::max(0, blend_frames)),
      stance_(*segments.library) {
  const size_t n = static_cast<size_t>(skel_.num_channels());
  prev_.resize(n);
  prev_rot_.resize(static_cast<size_t>(skel_.num_joints()));
  cur_rot_.resize(prev_rot_.size());
  if (StatusOr<motion::KeyJoints> key = motion::FindKeyJoints(skel_, segments.library->regions); key.ok()) {
    const int ends[] = {key->head, key->left_hand, key->right_hand, key->left_foot, key->right_foot};
    gap_joints_ = motion::JointsWithAncestors(skel_, ends);
  } else {
    for (int j = 0; j < skel_.num_joints(); ++j) gap_joints_.push_back(j);
  }
  hold_.resize(n);
  a_.resize(n);
  b_.resize(n);
  if (feet.enabled) {
    const Library& lib = *segments.library;
    const double dt = lib.frame_rate_hz > 0 ? 1.0 / lib.frame_rate_hz : 1.0 / 30;
    auto planter = [&]() -> StatusOr<std::unique_ptr<motion::FootPlanter>> {
      KINEMO_ASSIGN_OR_RETURN(motion::FootPlantParams p, LibraryFootPlantParams(lib, feet));
      return motion::FootPlanter::Create(skel_, lib.regions, dt, p);
    }();
    if (planter.ok()) {
      planter_ = *std::move(planter);
    } else {
      feet_status_ = Annotate(planter.status(), "feet");
    }
  }
}

FrameAssembler::~FrameAssembler() = default;

namespace {

void CopyFrame(const motion::Clip& clip, int f, const Eigen::Vector3d& offset, const motion::Joint& root,
               std::span<double> out) {
  const auto src = clip.frame(f);
  std::copy(src.begin(), src.end(), out.begin());
  for (int k : {0, 2})
    if (root.position_column[static_cast<size_t>(k)] >= 0) out[static_cast<size_t>(root.position_column[static_cast<size_t>(k)])] += offset(k);
}

// out = from (w = 0) → to (w = 1), per joint.
void BlendFrames(const motion::Skeleton& skel, std::span<const double> from, std::span<const double> to, double w,
                 std::span<double> out) {
  for (const auto& j : skel.joints()) {
    for (int c = j.first_channel; c < j.first_channel + j.num_channels(); ++c)
      out[static_cast<size_t>(c)] = (1 - w) * from[static_cast<size_t>(c)] + w * to[static_cast<size_t>(c)];
    if (j.num_rotations == 3 && j.has_euler_rotation()) {
      const Eigen::Quaterniond qa(motion::LocalRotation(j, from)), qb(motion::LocalRotation(j, to));
      const Eigen::Matrix3d r = qa.slerp(w, qb).toRotationMatrix();
      Eigen::Vector3d ref;
      for (int k = 0; k < 3; ++k) ref(k) = to[static_cast<size_t>(j.rotation_column[static_cast<size_t>(k)])];
      const Eigen::Vector3d ang = motion::MatrixToEuler(r, j.rotation_axis, ref);
      for (int k = 0; k < 3; ++k) out[static_cast<size_t>(j.rotation_column[static_cast<size_t>(k)])] = ang(k);
    }
  }
}

}  // namespace

void FrameAssembler::Next(int segment, int f, std::span<double> out) {
  const auto& seg = s_.segments[static_cast<size_t>(segment)];
  const auto& clips = s_.library->clips;
  const motion::Joint& root = skel_.joint(0);
  const int c = seg.clip, g = std::min(seg.first_frame + f, clips[static_cast<size_t>(c)].clip.num_frames() - 1);
  bool jumped = false;
  if (frames_out_ > 0 && !(c == cur_clip_ && g == cur_frame_ + 1)) {
    jumped = true;
    ++transitions_;
    const motion::Clip& old = clips[static_cast<size_t>(cur_clip_)].clip;
    // A jump inside a running blend fades from the pose last shown (held).
    hold_source_ = src_clip_ >= 0 && blend_k_ < cur_blend_;
    if (hold_source_) std::copy(prev_.begin(), prev_.end(), hold_.begin());
    src_clip_ = cur_clip_;
    src_frame_ = cur_frame_;
    src_offset_ = offset_;
    // The new segment stands where the old one would have stood next.
    const Eigen::Vector2d next_stance =
        stance_.At(cur_clip_, std::min(cur_frame_ + 1, old.num_frames() - 1)) + Eigen::Vector2d(offset_(0), offset_(2));
    const Eigen::Vector2d new_stance = stance_.At(c, g);
    offset_ = Eigen::Vector3d(next_stance.x() - new_stance.x(), 0, next_stance.y() - new_stance.y());
    blend_k_ = 0;
  }
  CopyFrame(clips[static_cast<size_t>(c)].clip, g, offset_, root, a_);
  if (jumped && blend_frames_ > 0) {
    // Long enough that the fade itself (peak rate 1.5/blend of the largest
    // joint angle between the two poses) stays under 0.4 x the library's
    // 99th-percentile joint speed; at most 4x the nominal length.
    const motion::Clip& old = clips[static_cast<size_t>(src_clip_)].clip;
    if (hold_source_) {
      std::copy(hold_.begin(), hold_.end(), b_.begin());
    } else {
      CopyFrame(old, std::min(src_frame_ + 1, old.num_frames() - 1), src_offset_, root, b_);
    }
    const double dt = 1.0 / s_.library->frame_rate_hz;
    double gap_deg = 0;
    for (int j : gap_joints_) {
      gap_deg = std::max(gap_deg, motion::JointAngularSpeedDps(skel_.joint(j), b_, a_, 1.0));
    }
    const double limit_dps = std::max(30.0, 0.4 * s_.angular_speed_p99_dps);
    const int need = static_cast<int>(std::ceil(1.5 * gap_deg / (limit_dps * dt)));
    cur_blend_ = std::clamp(need, blend_frames_, 4 * blend_frames_);
  }
  const bool blending = src_clip_ >= 0 && blend_k_ < cur_blend_;
  if (blending) {
    const motion::Clip& old = clips[static_cast<size_t>(src_clip_)].clip;
    src_frame_ = std::min(src_frame_ + 1, old.num_frames() - 1);
    if (hold_source_) {
      std::copy(hold_.begin(), hold_.end(), b_.begin());
    } else {
      CopyFrame(old, src_frame_, src_offset_, root, b_);
    }
    const double x = static_cast<double>(blend_k_ + 1) / (cur_blend_ + 1);
    const double w = x * x * (3 - 2 * x);
    BlendFrames(skel_, b_, a_, w, out);
    ++blend_k_;
  } else {
    std::copy(a_.begin(), a_.end(), out.begin());
  }
  // Largest joint angular speed into this frame (as MaxJointAngularSpeedDps).
  double max_cos = 1.0;
  for (size_t j = 0; j < cur_rot_.size(); ++j) {
    const motion::Joint& joint = skel_.joint(static_cast<int>(j));
    if (joint.num_rotations == 0) continue;
    cur_rot_[j] = motion::LocalRotation(joint, out);
    if (frames_out_ > 0) max_cos = std::min(max_cos, ((prev_rot_[j].transpose() * cur_rot_[j]).trace() - 1.0) / 2.0);
  }
  if (frames_out_ > 0) {
    const double s = std::acos(std::clamp(max_cos, -1.0, 1.0)) * (180.0 / std::numbers::pi) * s_.library->frame_rate_hz;
    if (jumped || blending) {
      max_transition_dps_ = std::max(max_transition_dps_, s);
    } else {
      max_inside_dps_ = std::max(max_inside_dps_, s);
    }
  }
  std::swap(prev_rot_, cur_rot_);
  std::copy(out.begin(), out.end(), prev_.begin());
  cur_clip_ = c;
  cur_frame_ = g;
  ++frames_out_;
  if (planter_) planter_->Apply(out);
}

// ---------------------------------------------------------------------------
// Offline synthesis and online runs

namespace {

Status ValidateBeliefs(const Controller& c, const std::vector<BeliefSpan>& beliefs) {
  if (beliefs.empty()) return InvalidField("beliefs", "empty");
  for (size_t t = 0; t < beliefs.size(); ++t) {
    const auto& b = beliefs[t];
    const std::string f = kinemo::StrCat("beliefs[", t, "]");
    if (static_cast<int>(b.probabilities.size()) != c.num_states())
      return InvalidField(f, "has ", b.probabilities.size(), " probabilities, the controller has ", c.num_states(), " states");
    double sum = 0;
    for (double v : b.probabilities) {
      if (!std::isfinite(v) || v < 0) return InvalidField(f, "probabilities must be finite and non-negative");
      sum += v;
    }
    if (std::abs(sum - 1) > 1e-6) return InvalidField(f, "probabilities sum to ", sum, ", not 1");
    if (!std::isfinite(b.start_s) || !std::isfinite(b.end_s) || b.end_s < b.start_s || b.start_s < 0)
      return InvalidField(f, "times must be finite with 0 <= start_s <= end_s");
    if (t > 0 && b.start_s < beliefs[t - 1].start_s) return InvalidField(f, "times out of order");
  }
  return absl::OkStatus();
}

struct Prepared {
  int frames = 0;
  std::vector<double> style;
  std::vector<std::pair<int, KeywordEvent>> keywords;  // (keyword index, event), sorted by end
  int blend = 0;
};

StatusOr<Prepared> Prepare(const Controller& c, const std::vector<BeliefSpan>& beliefs, const SynthesisOptions& o) {
  KINEMO_RETURN_IF_ERROR(ValidateBeliefs(c, beliefs));
  if (o.feet.enabled) KINEMO_RETURN_IF_ERROR(motion::ValidateFootPlantParams(o.feet));
  Prepared p;
  const double duration = o.duration_s > 0 ? o.duration_s : beliefs.back().end_s;
  if (!std::isfinite(duration) || duration <= 0) return InvalidField("duration_s", "must be > 0");
  if (duration > o.max_duration_s) return InvalidField("duration_s", duration, " exceeds the limit of ", o.max_duration_s, " s");
  const double dt = c.frame_time_s();
  // BVH frame times are rounded (0.0333333): a few ppm over an integer is that integer.
  p.frames = std::max(1, static_cast<int>(std::ceil(duration / dt * (1 - 1e-5))));
  if (o.style.empty()) {
    p.style.assign(static_cast<size_t>(c.num_tones()), 0.0);
    const int n = c.ToneIndex(c.params().neutral_tone);
    p.style[static_cast<size_t>(n >= 0 ? n : 0)] = 1;
  } else {
    if (static_cast<int>(o.style.size()) != c.num_tones()) return InvalidField("style", "needs one weight per tone");
    double sum = 0;
    for (double v : o.style) {
      if (!std::isfinite(v) || v < 0) return InvalidField("style", "weights must be finite and non-negative");
      sum += v;
    }
    if (!(sum > 0)) return InvalidField("style", "weights sum to 0");
    for (double v : o.style) p.style.push_back(v / sum);
  }
  for (size_t k = 0; k < o.keywords.size(); ++k) {
    const auto& kw = o.keywords[k];
    if (!std::isfinite(kw.start_s) || !std::isfinite(kw.end_s) || kw.end_s < kw.start_s)
      return InvalidField(kinemo::StrCat("keywords[", k, "]"), "times must be finite with start_s <= end_s");
    const int idx = c.KeywordIndex(kw.word);
    if (idx >= 0) p.keywords.emplace_back(idx, kw);
  }
  std::sort(p.keywords.begin(), p.keywords.end(),
            [](const auto& a, const auto& b) { return a.second.end_s < b.second.end_s; });
  p.blend = o.blend_frames > 0 ? o.blend_frames : std::max(1, static_cast<int>(std::lround(0.2 / dt)));
  return p;
}

// Plays (segment, offsets) → motion, with angular-speed statistics.
Status Assemble(const Controller& c, const std::vector<std::pair<int, int>>& path, int blend,
                const motion::FootPlantParams& feet, SynthesisResult* r) {
  const SegmentLibrary& L = c.segments();
  r->clip.skeleton = L.library->skeleton;
  r->clip.frame_time_s = c.frame_time_s();
  r->clip.frames.resize(static_cast<Eigen::Index>(path.size()), L.library->skeleton.num_channels());
  FrameAssembler fa(L, blend, feet);
  // A skeleton without legs has no feet to plant; anything else is an error.
  if (!fa.feet_status().ok() && !absl::IsFailedPrecondition(fa.feet_status())) return fa.feet_status();
  r->feet_planted = fa.plants_feet();
  r->feet_note = std::string(fa.feet_status().message());
  for (size_t t = 0; t < path.size(); ++t) {
    std::span<double> out(r->clip.frames.data() + static_cast<Eigen::Index>(t) * r->clip.frames.cols(),
                          static_cast<size_t>(r->clip.frames.cols()));
    fa.Next(path[t].first, path[t].second, out);
  }
  r->max_transition_dps = fa.max_transition_dps();
  r->max_inside_dps = fa.max_inside_dps();
  r->library_p99_dps = L.angular_speed_p99_dps;
  return absl::OkStatus();
}

std::vector<SegmentPlayOut> PlaysOf(const Controller& c, const std::vector<std::pair<int, int>>& path,
                                    const std::vector<std::pair<int, std::string>>& served_at) {
  const SegmentLibrary& L = c.segments();
  const double dt = c.frame_time_s();
  std::vector<SegmentPlayOut> plays;
  size_t sk = 0;
  for (size_t t = 0; t < path.size(); ++t) {
    const auto [a, f] = path[t];
    if (plays.empty() || plays.back().segment != a || f != plays.back().last + 1) {
      if (!plays.empty()) {
        auto& p = plays.back();
        p.interrupted = p.last != L.segments[static_cast<size_t>(p.segment)].num_frames - 1;
      }
      SegmentPlayOut p;
      p.segment = a;
      p.first = p.last = f;
      p.start_s = static_cast<double>(t) * dt;
      while (sk < served_at.size() && served_at[sk].first < static_cast<int>(t)) ++sk;
      if (sk < served_at.size() && served_at[sk].first == static_cast<int>(t)) p.keyword = served_at[sk].second;
      plays.push_back(p);
    } else {
      plays.back().last = f;
    }
    plays.back().end_s = static_cast<double>(t + 1) * dt;
  }
  return plays;
}

}  // namespace

StatusOr<SynthesisResult> Synthesize(const Controller& c, const std::vector<BeliefSpan>& beliefs,
                                     const SynthesisOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_ASSIGN_OR_RETURN(Prepared p, Prepare(c, beliefs, o));
  const SegmentLibrary& L = c.segments();
  const int N = L.num_segments(), E = L.num_end_points(), S = c.num_states(), M = c.num_tones(), T = p.frames;
  const double dt = c.frame_time_s();
  std::vector<int> base(static_cast<size_t>(N) + 1, 0);
  for (int a = 0; a < N; ++a) base[static_cast<size_t>(a) + 1] = base[static_cast<size_t>(a)] + L.segments[static_cast<size_t>(a)].num_frames;
  const int F = base[static_cast<size_t>(N)];
  std::vector<double> q(static_cast<size_t>(F), kInf), qn(static_cast<size_t>(F));
  std::vector<double> cost(static_cast<size_t>(N));
  std::vector<int> bp0(static_cast<size_t>(T) * N, -1);
  struct SemBp {
    int t, segment, f, e, keyword;
  };
  std::vector<SemBp> sem_bp;
  std::vector<double> best_in(static_cast<size_t>(N));
  std::vector<int> arg_in(static_cast<size_t>(N));
  size_t step = 0;
  // Constraint frames: word end + deadline, per keyword event.
  std::vector<std::pair<int, int>> constraints;  // (frame, w)
  for (const auto& [k, ev] : p.keywords)
    constraints.emplace_back(std::min(T - 1, static_cast<int>(std::floor((ev.end_s + o.keyword_deadline_s) / dt))), k + 1);
  const double kHard = 1e6;
  for (int t = 0; t < T; ++t) {
    // A long recording's synthesis takes a while: the caller may stop it (every 10 s of motion).
    if (t % 300 == 0) KINEMO_RETURN_IF_ERROR(CheckCancel(o.cancel, "synthesis"));
    const double time = (t + 0.5) * dt;
    while (step + 1 < beliefs.size() && beliefs[step + 1].start_s <= time) ++step;
    const auto& g = beliefs[step].probabilities;
    for (int a = 0; a < N; ++a) {
      double v = 0;
      for (int m = 0; m < M; ++m) {
        if (p.style[static_cast<size_t>(m)] == 0) continue;
        const double* d = c.delta(m).data() + static_cast<Eigen::Index>(a) * S;
        double s = 0;
        for (int i = 0; i < S; ++i) s += g[static_cast<size_t>(i)] * d[i];
        v += p.style[static_cast<size_t>(m)] * s;
      }
      cost[static_cast<size_t>(a)] = v;
    }
    if (t == 0) {
      for (int a = 0; a < N; ++a) qn[static_cast<size_t>(base[static_cast<size_t>(a)])] = cost[static_cast<size_t>(a)];
    } else {
      std::fill(qn.begin(), qn.end(), kInf);
      for (int a = 0; a < N; ++a)
        for (int f = 1; f < L.segments[static_cast<size_t>(a)].num_frames; ++f)
          qn[static_cast<size_t>(base[static_cast<size_t>(a)] + f)] = q[static_cast<size_t>(base[static_cast<size_t>(a)] + f - 1)] + cost[static_cast<size_t>(a)];
      // Entries at frame 0: best[a] = min_e Q(e) + S(e, a), one contiguous
      // row of S per source end point.
      std::fill(best_in.begin(), best_in.end(), kInf);
      std::fill(arg_in.begin(), arg_in.end(), -1);
      for (int e = 0; e < E; ++e) {
        const auto& ep = L.end_points[static_cast<size_t>(e)];
        const double v = q[static_cast<size_t>(base[static_cast<size_t>(ep.segment)] + ep.frame)];
        if (!(v < kInf)) continue;
        const float* row = L.transition.data() + static_cast<size_t>(e) * N;
        for (int a = 0; a < N; ++a) {
          const double x = v + row[a];
          if (x < best_in[static_cast<size_t>(a)]) {
            best_in[static_cast<size_t>(a)] = x;
            arg_in[static_cast<size_t>(a)] = e;
          }
        }
      }
      for (int a = 0; a < N; ++a) {
        qn[static_cast<size_t>(base[static_cast<size_t>(a)])] = best_in[static_cast<size_t>(a)] + cost[static_cast<size_t>(a)];
        bp0[static_cast<size_t>(t) * N + a] = arg_in[static_cast<size_t>(a)];
      }
      // Semantic entries (at f'_start(e, b), as the online table) in the
      // second before each keyword's deadline.
      for (const auto& [tc, w] : constraints) {
        if (t > tc || t < tc - static_cast<int>(1.0 / dt)) continue;
        for (int e = 0; e < E; ++e) {
          const auto& ep = L.end_points[static_cast<size_t>(e)];
          const double v = q[static_cast<size_t>(base[static_cast<size_t>(ep.segment)] + ep.frame)];
          if (!(v < kInf)) continue;
          for (const auto& se : c.SemanticEntries(w, e)) {
            if (se.start == 0) continue;  // a normal entry
            const size_t idx = static_cast<size_t>(base[static_cast<size_t>(se.segment)] + se.start);
            const double x = v + se.cost + cost[static_cast<size_t>(se.segment)];
            if (x < qn[idx]) {
              qn[idx] = x;
              sem_bp.push_back({t, se.segment, se.start, e, w - 1});
            }
          }
        }
      }
    }
    for (const auto& [tc, w] : constraints) {
      if (tc != t) continue;
      for (int a = 0; a < N; ++a)
        if (!c.Matches(a, w))
          for (int f = 0; f < L.segments[static_cast<size_t>(a)].num_frames; ++f) qn[static_cast<size_t>(base[static_cast<size_t>(a)] + f)] += kHard;
    }
    q.swap(qn);
  }
  // Backtrack.
  int cur = static_cast<int>(std::min_element(q.begin(), q.end()) - q.begin());
  SynthesisResult r;
  r.total_cost = q[static_cast<size_t>(cur)];
  int a = static_cast<int>(std::upper_bound(base.begin(), base.end(), cur) - base.begin()) - 1;
  int f = cur - base[static_cast<size_t>(a)];
  std::vector<std::pair<int, int>> path(static_cast<size_t>(T));
  std::vector<std::pair<int, std::string>> served;
  for (int t = T - 1; t >= 0; --t) {
    path[static_cast<size_t>(t)] = {a, f};
    if (t == 0) break;
    int src = -1;
    if (f > 0) {
      // The last semantic record for (t, a, f) is the one that won.
      for (auto it = sem_bp.rbegin(); it != sem_bp.rend() && it->t >= t; ++it) {
        if (it->t == t && it->segment == a && it->f == f) {
          src = it->e;
          served.emplace_back(t, c.keywords()[static_cast<size_t>(it->keyword)]);
          break;
        }
      }
      if (src < 0) {
        --f;
        continue;
      }
    } else {
      src = bp0[static_cast<size_t>(t) * N + a];
      if (src < 0) break;
    }
    const auto& ep = L.end_points[static_cast<size_t>(src)];
    a = ep.segment;
    f = ep.frame;
  }
  std::sort(served.begin(), served.end());
  r.plays = PlaysOf(c, path, served);
  // Entries at frame 0 of a matching stroke inside a keyword window also serve it.
  for (auto& play : r.plays) {
    if (!play.keyword.empty()) continue;
    for (const auto& [k, ev] : p.keywords) {
      if (c.Matches(play.segment, k + 1) && play.end_s > ev.start_s && play.start_s <= ev.end_s + o.keyword_deadline_s + dt) {
        play.keyword = c.keywords()[static_cast<size_t>(k)];
        break;
      }
    }
  }
  KINEMO_RETURN_IF_ERROR(Assemble(c, path, p.blend, o.feet, &r));
  r.compute_s = Seconds(t0);
  return r;
}

StatusOr<SynthesisResult> RunOnline(const Controller& c, const std::vector<BeliefSpan>& beliefs,
                                    const SynthesisOptions& o, std::vector<double>* decide_us) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_ASSIGN_OR_RETURN(Prepared p, Prepare(c, beliefs, o));
  const SegmentLibrary& L = c.segments();
  const double dt = c.frame_time_s();
  if (!(o.min_play_s >= 0 && o.min_play_s <= 10)) return InvalidField("min_play_s", o.min_play_s, " is outside [0, 10] s");
  Policy policy(c, o.min_play_s);
  KINEMO_RETURN_IF_ERROR(policy.SetStyle(p.style));
  size_t next_belief = 0, next_kw = 0;
  std::vector<std::pair<int, int>> path;
  std::vector<std::pair<int, std::string>> served;
  path.reserve(static_cast<size_t>(p.frames));
  int seg = -1, frame = 0, end_point = 0;
  for (int t = 0; t < p.frames; ++t) {
    const double time = t * dt;
    bool got = false;
    while (next_belief < beliefs.size() && beliefs[next_belief].start_s <= time + 1e-9) {
      KINEMO_RETURN_IF_ERROR(policy.SetBelief(beliefs[next_belief].probabilities));
      ++next_belief;
      got = true;
    }
    if (!got && t > 0) policy.Advance();
    while (next_kw < p.keywords.size() && p.keywords[next_kw].second.end_s <= time + 1e-9) {
      KINEMO_RETURN_IF_ERROR(policy.SetKeyword(p.keywords[next_kw].first));
      ++next_kw;
    }
    const int pending = policy.pending_keyword();
    Decision d;
    bool decided = false;
    const auto td = std::chrono::steady_clock::now();
    if (seg < 0) {
      d = policy.Start();
      decided = true;
    } else if (frame == L.segments[static_cast<size_t>(seg)].ends[static_cast<size_t>(L.end_points[static_cast<size_t>(end_point)].k)]) {
      d = policy.Decide(end_point);
      decided = true;
    } else {
      ++frame;
    }
    if (decided) {
      const double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - td).count();
      if (decide_us) decide_us->push_back(us);
      seg = d.segment;
      frame = d.start;
      end_point = d.end_point;
      if (d.keyword >= 0 && pending >= 0 && !d.continuation) served.emplace_back(t, c.keywords()[static_cast<size_t>(d.keyword)]);
    }
    path.emplace_back(seg, frame);
  }
  SynthesisResult r;
  r.plays = PlaysOf(c, path, served);
  KINEMO_RETURN_IF_ERROR(Assemble(c, path, p.blend, o.feet, &r));
  r.compute_s = Seconds(t0);
  return r;
}

StatusOr<SynthesisResult> SynthesizeRandom(const Controller& c, const std::vector<BeliefSpan>& beliefs,
                                           const SynthesisOptions& o, std::uint64_t seed) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_ASSIGN_OR_RETURN(Prepared p, Prepare(c, beliefs, o));
  const SegmentLibrary& L = c.segments();
  const int n = L.num_segments();
  if (n < 1) return absl::FailedPreconditionError("controller: the library has no segments");
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pick(0, n - 1);
  std::vector<std::pair<int, int>> path;
  path.reserve(static_cast<size_t>(p.frames));
  int seg = pick(rng), frame = 0;
  for (int t = 0; t < p.frames; ++t) {
    if (frame >= L.segments[static_cast<size_t>(seg)].num_frames) {
      int next = pick(rng);
      if (n > 1)
        while (next == seg) next = pick(rng);
      seg = next;
      frame = 0;
    }
    path.emplace_back(seg, frame++);
  }
  SynthesisResult r;
  r.plays = PlaysOf(c, path, {});
  KINEMO_RETURN_IF_ERROR(Assemble(c, path, p.blend, o.feet, &r));
  r.compute_s = Seconds(t0);
  return r;
}

StatusOr<std::vector<double>> StyleFromWeights(const Controller& c,
                                               const std::vector<std::pair<std::string, double>>& weights,
                                               double gesture_emphasis) {
  const double e = gesture_emphasis;
  if (!std::isfinite(e) || e < -1 || e > 1) return InvalidField("style.gesture_emphasis", e, " must be in [-1, 1]");
  std::vector<double> out(static_cast<size_t>(c.num_tones()), 0.0);
  if (weights.empty()) {
    const int n = c.ToneIndex(c.params().neutral_tone);
    out[static_cast<size_t>(n >= 0 ? n : 0)] = 1;
  } else {
    double sum = 0;
    for (const auto& [tone, w] : weights) {
      const int i = Controller::IsEmphasisTone(tone) ? -1 : c.ToneIndex(tone);
      if (i < 0) return InvalidField("style.tone_weights", "unknown tone '", tone, "'");
      if (!std::isfinite(w) || w < 0) return InvalidField("style.tone_weights", "'", tone, "' must be finite and >= 0");
      out[static_cast<size_t>(i)] += w;
      sum += w;
    }
    if (!(sum > 0)) return InvalidField("style.tone_weights", "sum to 0");
    for (double& v : out) v /= sum;
  }
  if (e == 0) return out;
  for (int m = 0; m < c.num_tones(); ++m) {
    const double d = out[static_cast<size_t>(m)];
    if (d == 0 || Controller::IsEmphasisTone(c.tones()[static_cast<size_t>(m)])) continue;
    const int x = c.EmphasisIndex(m, e);
    if (x < 0) continue;  // built before emphasis existed: the tone mix as it is
    out[static_cast<size_t>(m)] = (1 - std::abs(e)) * d;
    out[static_cast<size_t>(x)] = std::abs(e) * d;
  }
  return out;
}

}  // namespace kinemo::planner::controller

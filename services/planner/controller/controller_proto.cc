#include "services/planner/controller/controller_proto.h"

#include <cmath>

namespace kinemo::planner::controller {
namespace {

template <typename Gaussians>
StatusOr<StateModel> FromParts(uint32_t num_states, const google::protobuf::RepeatedField<double>& initial,
                               const google::protobuf::RepeatedField<double>& transition, const Gaussians& states) {
  const int s = static_cast<int>(num_states);
  if (s < 1 || s > 1000) return InvalidField("state_model.num_states", "must be in [1, 1000]");
  StateModel m;
  if (initial.size() != s) return InvalidField("state_model.initial_probabilities", "must have num_states values");
  m.initial = Eigen::Map<const Eigen::VectorXd>(initial.data(), s);
  if (transition.size() != s * s)
    return InvalidField("state_model.transition_probabilities", "must have num_states² values");
  m.transition = Eigen::Map<const RowMatrix>(transition.data(), s, s);
  if (states.size() != s) return InvalidField("state_model.states", "must have num_states entries");
  for (int i = 0; i < s; ++i) {
    const auto& g = states.Get(i);
    const std::string f = kinemo::StrCat("state_model.states[", i, "]");
    if (g.mean_size() != 6) return InvalidField(f, ".mean must have 6 values");
    Vector6 mu;
    for (int k = 0; k < 6; ++k) mu(k) = g.mean(k);
    Matrix6 cov = Matrix6::Zero();
    if (g.covariance_size() == 6) {
      for (int k = 0; k < 6; ++k) cov(k, k) = g.covariance(k);
    } else if (g.covariance_size() == 36) {
      for (int k = 0; k < 36; ++k) cov(k / 6, k % 6) = g.covariance(k);
    } else {
      return InvalidField(f, ".covariance must have 6 or 36 values");
    }
    m.means.push_back(mu);
    m.covariances.push_back(cov);
  }
  KINEMO_RETURN_IF_ERROR(ValidateStateModel(m));
  return m;
}

}  // namespace

v1::ToneTransform ToneTransformToProto(const ToneTransfer& t) {
  v1::ToneTransform o;
  o.set_name(t.name);
  o.set_source(t.source);
  for (int k = 0; k < 36; ++k) o.add_a(t.A(k / 6, k % 6));
  for (int k = 0; k < 6; ++k) o.add_shift(t.shift(k));
  return o;
}

ControllerParams FromProto(const v1::ControllerParams& p, const v1::ControllerParams& d) {
  ControllerParams o;
  auto pick = [](double a, double b, double c) { return a != 0 ? a : (b != 0 ? b : c); };
  o.discount = pick(p.discount(), d.discount(), o.discount);
  o.segmentation.interruption_penalty = pick(p.interruption_penalty(), d.interruption_penalty(), o.segmentation.interruption_penalty);
  o.tolerance = pick(p.tolerance(), d.tolerance(), o.tolerance);
  o.max_iterations = static_cast<int>(p.max_iterations() != 0 ? p.max_iterations() : (d.max_iterations() != 0 ? d.max_iterations() : static_cast<uint32_t>(o.max_iterations)));
  o.disable_culling = p.disable_culling() || d.disable_culling();
  o.semantic_cost = pick(p.semantic_cost(), d.semantic_cost(), o.semantic_cost);
  o.semantic_start_max_fraction = pick(p.semantic_start_max_fraction(), d.semantic_start_max_fraction(), o.semantic_start_max_fraction);
  const auto& tones = p.tones_size() > 0 ? p.tones() : d.tones();
  o.tones.assign(tones.begin(), tones.end());
  o.neutral_tone = !p.neutral_tone().empty() ? p.neutral_tone() : (!d.neutral_tone().empty() ? d.neutral_tone() : o.neutral_tone);
  o.threads = static_cast<int>(p.threads() != 0 ? p.threads() : d.threads());
  for (const auto& t : p.tone_transforms_size() > 0 ? p.tone_transforms() : d.tone_transforms()) {
    ToneTransfer x;
    x.name = t.name();
    x.source = t.source();
    // Wrong sizes leave NaN, which ValidateControllerParams refuses (naming the field).
    x.A.setConstant(std::nan(""));
    x.shift.setConstant(std::nan(""));
    if (t.a_size() == 36)
      for (int k = 0; k < 36; ++k) x.A(k / 6, k % 6) = t.a(k);
    if (t.shift_size() == 6)
      for (int k = 0; k < 6; ++k) x.shift(k) = t.shift(k);
    o.tone_transfers.push_back(std::move(x));
  }
  o.belief_step_s = pick(p.belief_step_s(), d.belief_step_s(), o.belief_step_s);
  o.segmentation.transition_weight = pick(p.transition_weight(), d.transition_weight(), o.segmentation.transition_weight);
  o.segmentation.speed_threshold_heights_per_s =
      pick(p.hand_speed_threshold_heights_per_s(), d.hand_speed_threshold_heights_per_s(), o.segmentation.speed_threshold_heights_per_s);
  o.segmentation.min_segment_s = pick(p.min_segment_s(), d.min_segment_s(), o.segmentation.min_segment_s);
  o.segmentation.interruption_frames = static_cast<int>(
      p.interruption_frames() != 0 ? p.interruption_frames()
                                   : (d.interruption_frames() != 0 ? d.interruption_frames() : static_cast<uint32_t>(o.segmentation.interruption_frames)));
  return o;
}

v1::ControllerParams ToProto(const ControllerParams& p) {
  v1::ControllerParams o;
  o.set_discount(p.discount);
  o.set_interruption_penalty(p.segmentation.interruption_penalty);
  o.set_tolerance(p.tolerance);
  o.set_max_iterations(static_cast<uint32_t>(p.max_iterations));
  o.set_disable_culling(p.disable_culling);
  o.set_semantic_cost(p.semantic_cost);
  o.set_semantic_start_max_fraction(p.semantic_start_max_fraction);
  for (const auto& t : p.tones) o.add_tones(t);
  o.set_neutral_tone(p.neutral_tone);
  o.set_threads(static_cast<uint32_t>(p.threads));
  for (const auto& t : p.tone_transfers) *o.add_tone_transforms() = ToneTransformToProto(t);
  o.set_belief_step_s(p.belief_step_s);
  o.set_transition_weight(p.segmentation.transition_weight);
  o.set_hand_speed_threshold_heights_per_s(p.segmentation.speed_threshold_heights_per_s);
  o.set_min_segment_s(p.segmentation.min_segment_s);
  o.set_interruption_frames(static_cast<uint32_t>(p.segmentation.interruption_frames));
  return o;
}

StatusOr<StateModel> FromProto(const v1::StateModel& m) {
  return FromParts(m.num_states(), m.initial_probabilities(), m.transition_probabilities(), m.states());
}

StatusOr<StateModel> FromProto(const ::kinemo::inference::v1::ModelParameters& m) {
  return FromParts(m.num_states(), m.initial_probabilities(), m.transition_probabilities(), m.states());
}

void ToProto(const Controller& c, v1::ControllerInfo* out) {
  const BuildReport& r = c.report();
  out->set_library_id(c.library().id);
  out->set_library_version(static_cast<uint32_t>(c.library().version));
  out->set_library_s(r.library_s);
  out->set_segments(static_cast<uint32_t>(r.segments));
  out->set_entries(r.entries);
  out->set_culled_fraction(r.culled_fraction);
  out->set_train_s(r.train_s);
  out->set_num_states(static_cast<uint32_t>(c.num_states()));
  for (const auto& t : c.style_tones()) out->add_tones(t);
  *out->mutable_params() = ToProto(c.params());
}

}  // namespace kinemo::planner::controller

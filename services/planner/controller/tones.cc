#include "services/planner/controller/tones.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <regex>
#include <set>

#include <Eigen/Eigenvalues>

#include "common/gesture/kinematics.h"
#include "common/motion/bvh.h"

namespace kinemo::planner::controller {
namespace {

namespace fs = std::filesystem;

struct Take {
  std::string path, action, style;
};

// `<prefix>_<action>_<style>_<take>.bvh` -> action, style.
bool ParseName(const std::string& path, Take* take) {
  static const std::regex re(R"(^[^_]+_([^_]+)_([^_]+)_[0-9]+\.bvh$)");
  std::smatch m;
  const std::string name = fs::path(path).filename().string();
  if (!std::regex_match(name, m, re)) return false;
  take->path = path;
  take->action = m[1];
  take->style = m[2];
  return true;
}

Eigen::MatrixXd Stack(const std::vector<Vector6>& rows) {
  Eigen::MatrixXd x(static_cast<Eigen::Index>(rows.size()), 6);
  for (size_t i = 0; i < rows.size(); ++i) x.row(static_cast<Eigen::Index>(i)) = rows[i].transpose();
  return x;
}

}  // namespace

ToneEstimationOptions DefaultToneEstimationOptions() {
  ToneEstimationOptions o;
  o.style_tones = {{"angry", "angry"}, {"happy", "happy"}, {"sad", "subdued"}, {"active", "energetic"}};
  return o;
}

Status ValidateToneTransfer(const ToneTransfer& t, const std::string& field) {
  static const std::regex name_re("^[a-z0-9_-]{1,32}$");
  if (!std::regex_match(t.name, name_re)) return InvalidField(field + ".name", "'", t.name, "' must match [a-z0-9_-]{1,32}");
  if (!t.A.allFinite()) return InvalidField(field + ".a", "has NaN or infinite values");
  if (!t.A.isApprox(t.A.transpose(), 1e-6)) return InvalidField(field + ".a", "must be symmetric");
  Eigen::SelfAdjointEigenSolver<Matrix6> es(t.A);
  if (es.eigenvalues().minCoeff() < 0.05 || es.eigenvalues().maxCoeff() > 20)
    return InvalidField(field + ".a", "eigenvalues must lie in [0.05, 20], got [", es.eigenvalues().minCoeff(), ", ",
                        es.eigenvalues().maxCoeff(), "]");
  if (!t.shift.allFinite() || t.shift.cwiseAbs().maxCoeff() > 10)
    return InvalidField(field + ".shift", "values must be finite and within [-10, 10]");
  return absl::OkStatus();
}

StyleTransform ApplyTransfer(const ToneTransfer& t, const Vector6& target_mean) {
  StyleTransform out;
  out.A = t.A;
  out.b = target_mean + t.shift - t.A * target_mean;
  return out;
}

StatusOr<std::vector<ToneTransfer>> EstimateTones(const std::vector<std::string>& paths,
                                                  const ToneEstimationOptions& options,
                                                  const std::string& field) {
  if (paths.empty()) return InvalidField(field, "no path given");
  std::vector<Take> takes;
  for (size_t i = 0; i < paths.size(); ++i) {
    const std::string f = kinemo::StrCat(field, "[", i, "]");
    std::error_code ec;
    if (fs::is_directory(paths[i], ec)) {
      std::vector<std::string> files;
      for (const auto& e : fs::directory_iterator(paths[i], ec))
        if (e.path().extension() == ".bvh") files.push_back(e.path().string());
      std::sort(files.begin(), files.end());
      for (const auto& file : files) {
        Take t;
        if (ParseName(file, &t)) takes.push_back(t);
      }
    } else if (fs::is_regular_file(paths[i], ec)) {
      Take t;
      if (!ParseName(paths[i], &t))
        return InvalidField(f, "'", paths[i], "' is not named <prefix>_<action>_<style>_<take>.bvh");
      takes.push_back(t);
    } else {
      return InvalidField(f, "'", paths[i], "' is neither a file nor a directory");
    }
  }
  const std::set<std::string> wanted(options.actions.begin(), options.actions.end());
  // Segment parameters per (style, action), only for the styles we use.
  std::map<std::string, std::map<std::string, std::vector<Vector6>>> by_style;
  for (const Take& t : takes) {
    if (t.style != options.neutral_style && !options.style_tones.count(t.style)) continue;
    if (!wanted.empty() && !wanted.count(t.action)) continue;
    auto clip = motion::ReadBvhFile(t.path);
    if (!clip.ok()) return Annotate(clip.status(), kinemo::StrCat(field, ": ", t.path));
    auto segs = gesture::ComputeKinematicSegments(*clip);
    if (!segs.ok()) return Annotate(segs.status(), kinemo::StrCat(field, ": ", t.path));
    auto& rows = by_style[t.style][t.action];
    for (const auto& s : *segs) rows.push_back(s.params);
  }
  const auto& neutral = by_style[options.neutral_style];
  std::vector<ToneTransfer> out;
  for (const auto& [style, tone] : options.style_tones) {
    const auto it = by_style.find(style);
    if (it == by_style.end()) continue;  // no takes of this style
    ToneTransfer t;
    t.name = tone;
    t.source = kinemo::StrCat("style '", style, "' vs '", options.neutral_style, "'");
    std::vector<Vector6> n_rows, m_rows;
    for (const auto& [action, rows] : it->second) {
      const auto n = neutral.find(action);
      if (n == neutral.end()) continue;
      t.actions.push_back(action);
      n_rows.insert(n_rows.end(), n->second.begin(), n->second.end());
      m_rows.insert(m_rows.end(), rows.begin(), rows.end());
    }
    if (t.actions.empty())
      return absl::FailedPreconditionError(kinemo::StrCat(field, ": style '", style, "' has no action with a '",
                                                          options.neutral_style, "' take"));
    auto fit = FitStyleTransform(Stack(n_rows), Stack(m_rows));
    if (!fit.ok())
      return absl::FailedPreconditionError(kinemo::StrCat(field, ": style '", style, "': ", fit.status().message()));
    t.A = fit->A;
    t.source_neutral_mean = Stack(n_rows).colwise().mean().transpose();
    t.source_tone_mean = Stack(m_rows).colwise().mean().transpose();
    t.shift = t.source_tone_mean - t.source_neutral_mean;
    t.neutral_segments = static_cast<int>(n_rows.size());
    t.tone_segments = static_cast<int>(m_rows.size());
    KINEMO_RETURN_IF_ERROR(ValidateToneTransfer(t, kinemo::StrCat(field, " tone '", tone, "'")));
    out.push_back(std::move(t));
  }
  if (out.empty())
    return absl::FailedPreconditionError(kinemo::StrCat(field, ": no styled take of a mapped style (",
                                                        options.style_tones.size(), " styles mapped)"));
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  return out;
}

}  // namespace kinemo::planner::controller

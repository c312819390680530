// Controller files: "KCTRL001", a JSON header (library sources, parameters,
// state model, tones, keywords, report), then the tables as little-endian
// binary arrays. The library itself is not copied: Load reloads it from the
// recorded sources (or takes one already loaded, e.g. from the planner's
// artifact store) and checks that it segments to the same segments.
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <nlohmann/json.hpp>

#include "services/planner/controller/controller.h"

namespace kinemo::planner::controller {
namespace {

constexpr char kMagic[8] = {'K', 'C', 'T', 'R', 'L', '0', '0', '1'};

class Writer {
 public:
  explicit Writer(std::ofstream& out) : out_(out) {}
  void U64(std::uint64_t v) { out_.write(reinterpret_cast<const char*>(&v), sizeof v); }
  void Doubles(const double* p, size_t n) {
    U64(n);
    out_.write(reinterpret_cast<const char*>(p), static_cast<std::streamsize>(n * sizeof(double)));
  }
  void Matrix(const RowMatrix& m) {
    U64(static_cast<std::uint64_t>(m.rows()));
    U64(static_cast<std::uint64_t>(m.cols()));
    out_.write(reinterpret_cast<const char*>(m.data()), static_cast<std::streamsize>(m.size() * sizeof(double)));
  }
  void Ints(const std::vector<int>& v) {
    U64(v.size());
    out_.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(int)));
  }

 private:
  std::ofstream& out_;
};

class Reader {
 public:
  Reader(std::ifstream& in, std::string path) : in_(in), path_(std::move(path)) {}
  StatusOr<std::uint64_t> U64() {
    std::uint64_t v = 0;
    if (!in_.read(reinterpret_cast<char*>(&v), sizeof v)) return Truncated();
    return v;
  }
  Status Matrix(RowMatrix* m, std::uint64_t max_elems) {
    KINEMO_ASSIGN_OR_RETURN(std::uint64_t r, U64());
    KINEMO_ASSIGN_OR_RETURN(std::uint64_t c, U64());
    if (r * c > max_elems) return InvalidField(path_, "table larger than expected (corrupt file)");
    m->resize(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c));
    if (!in_.read(reinterpret_cast<char*>(m->data()), static_cast<std::streamsize>(m->size() * sizeof(double)))) return Truncated();
    return absl::OkStatus();
  }
  Status Ints(std::vector<int>* v, std::uint64_t max_elems) {
    KINEMO_ASSIGN_OR_RETURN(std::uint64_t n, U64());
    if (n > max_elems) return InvalidField(path_, "list larger than expected (corrupt file)");
    v->resize(n);
    if (!in_.read(reinterpret_cast<char*>(v->data()), static_cast<std::streamsize>(n * sizeof(int)))) return Truncated();
    return absl::OkStatus();
  }

 private:
  Status Truncated() { return InvalidField(path_, "truncated controller file"); }
  std::ifstream& in_;
  std::string path_;
};

nlohmann::json ParamsToJson(const ControllerParams& p) {
  nlohmann::json transfers = nlohmann::json::array();
  for (const auto& t : p.tone_transfers) {
    std::vector<double> a(t.A.data(), t.A.data() + 36), shift(t.shift.data(), t.shift.data() + 6);
    transfers.push_back({{"name", t.name}, {"source", t.source}, {"a", a}, {"shift", shift}});
  }
  return {{"discount", p.discount},
          {"tone_transforms", transfers},
          {"belief_step_s", p.belief_step_s},
          {"tolerance", p.tolerance},
          {"max_iterations", p.max_iterations},
          {"disable_culling", p.disable_culling},
          {"semantic_cost", p.semantic_cost},
          {"semantic_start_max_fraction", p.semantic_start_max_fraction},
          {"tones", p.tones},
          {"neutral_tone", p.neutral_tone},
          {"threads", p.threads},
          {"speed_threshold_heights_per_s", p.segmentation.speed_threshold_heights_per_s},
          {"min_segment_s", p.segmentation.min_segment_s},
          {"interruption_frames", p.segmentation.interruption_frames},
          {"transition_weight", p.segmentation.transition_weight},
          {"interruption_penalty", p.segmentation.interruption_penalty}};
}

ControllerParams ParamsFromJson(const nlohmann::json& j) {
  ControllerParams p;
  p.discount = j.at("discount");
  p.belief_step_s = j.at("belief_step_s");
  p.tolerance = j.at("tolerance");
  p.max_iterations = j.at("max_iterations");
  p.disable_culling = j.at("disable_culling");
  p.semantic_cost = j.at("semantic_cost");
  p.semantic_start_max_fraction = j.at("semantic_start_max_fraction");
  p.tones = j.at("tones").get<std::vector<std::string>>();
  p.neutral_tone = j.at("neutral_tone");
  p.threads = j.at("threads");
  p.segmentation.speed_threshold_heights_per_s = j.at("speed_threshold_heights_per_s");
  p.segmentation.min_segment_s = j.at("min_segment_s");
  p.segmentation.interruption_frames = j.at("interruption_frames");
  p.segmentation.transition_weight = j.at("transition_weight");
  p.segmentation.interruption_penalty = j.at("interruption_penalty");
  if (j.contains("tone_transforms")) {  // files before tones from styled capture have none
    for (const auto& t : j.at("tone_transforms")) {
      ToneTransfer x;
      x.name = t.at("name");
      x.source = t.at("source");
      const auto a = t.at("a").get<std::vector<double>>();
      const auto shift = t.at("shift").get<std::vector<double>>();
      if (a.size() != 36 || shift.size() != 6) throw std::runtime_error("params.tone_transforms: a needs 36 values, shift 6");
      x.A = Eigen::Map<const Matrix6>(a.data());
      x.shift = Eigen::Map<const Vector6>(shift.data());
      p.tone_transfers.push_back(std::move(x));
    }
  }
  return p;
}

}  // namespace

struct ControllerFile {
  static Status Save(const Controller& c, const std::string& path, const std::vector<std::string>& sources,
                     const std::string& model_path) {
    if (sources.empty()) return InvalidField("library_sources", "empty (the library must be reloadable from paths)");
    nlohmann::json h;
    h["library_sources"] = sources;
    h["inference_model_path"] = model_path;
    h["library_id"] = c.library().id;
    h["meters_per_unit"] = c.library().meters_per_unit;
    h["frame_rate_hz"] = c.library().frame_rate_hz;
    h["params"] = ParamsToJson(c.params_);
    h["tones"] = c.tones_;
    h["keywords"] = c.keywords();
    h["segments"] = c.segments().num_segments();
    h["end_points"] = c.segments().num_end_points();
    const BuildReport& r = c.report_;
    h["report"] = {{"library_s", r.library_s}, {"segments", r.segments}, {"end_points", r.end_points},
                   {"entries_total", r.entries_total}, {"entries", r.entries}, {"culled_fraction", r.culled_fraction},
                   {"train_s", r.train_s}, {"iterations", r.iterations}, {"final_change", r.final_change}};
    std::vector<double> first;
    for (const auto& s : c.segments().segments) first.push_back(s.params(0) + s.params(2));
    const std::string header = h.dump();
    const std::string tmp = path + ".tmp";
    {
      std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
      if (!out) return absl::FailedPreconditionError(kinemo::StrCat(path, ": cannot write"));
      out.write(kMagic, sizeof kMagic);
      Writer w(out);
      w.U64(header.size());
      out.write(header.data(), static_cast<std::streamsize>(header.size()));
      w.Doubles(first.data(), first.size());
      const StateModel& m = c.model_;
      w.Doubles(m.initial.data(), static_cast<size_t>(m.initial.size()));
      w.Matrix(m.transition);
      for (int i = 0; i < m.num_states(); ++i) {
        w.Doubles(m.means[static_cast<size_t>(i)].data(), 6);
        w.Doubles(m.covariances[static_cast<size_t>(i)].data(), 36);
      }
      for (const auto& t : c.transforms_) {
        w.Doubles(t.A.data(), 36);
        w.Doubles(t.b.data(), 6);
      }
      w.Matrix(c.frame_transition_);
      for (const auto& d : c.delta_) w.Matrix(d);
      for (const auto& u : c.u_) w.Matrix(u);
      for (const auto& v : c.vc_) w.Matrix(v);
      for (size_t k = 0; k < c.sem_.size(); ++k) {
        std::vector<int> flat;
        for (const auto& s : c.sem_[k]) {
          flat.insert(flat.end(), {s.e, s.segment, s.start, s.h});
        }
        w.Ints(flat);
        std::vector<double> costs;
        for (const auto& s : c.sem_[k]) costs.push_back(s.cost);
        w.Doubles(costs.data(), costs.size());
        w.Ints(c.sem_offsets_[k]);
      }
      for (const auto& sv : c.sem_values_) w.Matrix(sv);
      for (size_t k = 0; k < c.kept_.size(); ++k) {
        w.Ints(c.kept_offsets_[k]);
        w.Ints(c.kept_[k]);
      }
      if (!out) return absl::FailedPreconditionError(kinemo::StrCat(path, ": write failed"));
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) return absl::FailedPreconditionError(kinemo::StrCat(path, ": ", ec.message()));
    return absl::OkStatus();
  }

  static StatusOr<std::shared_ptr<const Controller>> Load(const std::string& path,
                                                          std::shared_ptr<const Library> library) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return absl::NotFoundError(kinemo::StrCat(path, ": cannot open"));
    char magic[8];
    if (!in.read(magic, 8) || std::memcmp(magic, kMagic, 8) != 0)
      return InvalidField(path, "not a kinemo controller file");
    Reader r(in, path);
    KINEMO_ASSIGN_OR_RETURN(std::uint64_t hn, r.U64());
    if (hn > (64u << 20)) return InvalidField(path, "header too large");
    std::string header(hn, '\0');
    if (!in.read(header.data(), static_cast<std::streamsize>(hn))) return InvalidField(path, "truncated header");
    auto c = std::shared_ptr<Controller>(new Controller());
    nlohmann::json h;
    try {
      h = nlohmann::json::parse(header);
      c->params_ = ParamsFromJson(h.at("params"));
      c->tones_ = h.at("tones").get<std::vector<std::string>>();
      c->inference_model_path_ = h.value("inference_model_path", std::string());
      const auto& rep = h.at("report");
      c->report_.library_s = rep.at("library_s");
      c->report_.segments = rep.at("segments");
      c->report_.end_points = rep.at("end_points");
      c->report_.entries_total = rep.at("entries_total");
      c->report_.entries = rep.at("entries");
      c->report_.culled_fraction = rep.at("culled_fraction");
      c->report_.train_s = rep.at("train_s");
      c->report_.iterations = rep.at("iterations");
      c->report_.final_change = rep.at("final_change");
    } catch (const std::exception& e) {
      return InvalidField(path, "bad header: ", e.what());
    }
    std::string library_name;
    try {
      if (library == nullptr) {
        LibrarySources src;
        src.paths = h.at("library_sources").get<std::vector<std::string>>();
        src.meters_per_unit = h.at("meters_per_unit").get<double>();
        src.frame_rate_hz = h.at("frame_rate_hz").get<double>();
        if (src.paths.empty()) return InvalidField(path, "no library sources recorded");
        auto lib = LoadLibrary(h.at("library_id").get<std::string>(), src);
        if (!lib.ok()) return Annotate(lib.status(), kinemo::StrCat(path, ": reloading the library"));
        library = *std::move(lib);
        library_name = kinemo::StrCat("the library at ", src.paths[0]);
      } else {
        library_name = kinemo::StrCat("library '", library->id, "' version ", library->version);
        const double rate = h.at("frame_rate_hz").get<double>();
        if (std::abs(library->frame_rate_hz - rate) > 1e-6 * rate) {
          return absl::FailedPreconditionError(kinemo::StrCat(path, ": built on clips at ", rate, " fps, ",
                                                              library_name, " is at ", library->frame_rate_hz,
                                                              " fps"));
        }
      }
    } catch (const std::exception& e) {
      return InvalidField(path, "bad header: ", e.what());
    }
    KINEMO_ASSIGN_OR_RETURN(c->segments_, BuildSegmentLibrary(std::move(library), c->params_.segmentation));
    const int N = c->segments_->num_segments(), E = c->segments_->num_end_points();
    bool same = false;
    try {
      same = N == h.at("segments").get<int>() && E == h.at("end_points").get<int>() &&
             c->segments_->keywords == h.at("keywords").get<std::vector<std::string>>();
    } catch (const std::exception& e) {
      return InvalidField(path, "bad header: ", e.what());
    }
    if (!same) {
      return absl::FailedPreconditionError(kinemo::StrCat(path, ": built on other clips than ", library_name, " (",
                                                          h.value("segments", 0), " segments, ", library_name,
                                                          " has ", N, ")"));
    }
    const std::uint64_t big = 1ull << 34;
    {
      KINEMO_ASSIGN_OR_RETURN(std::uint64_t n, r.U64());
      if (n != static_cast<std::uint64_t>(N)) return InvalidField(path, "segment table size mismatch");
      std::vector<double> v(n);
      in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(double)));
      for (int a = 0; a < N; ++a) {
        const auto& s = c->segments_->segments[static_cast<size_t>(a)];
        if (std::abs(v[static_cast<size_t>(a)] - (s.params(0) + s.params(2))) > 1e-9)
          return absl::FailedPreconditionError(kinemo::StrCat(path, ": built on other clips than ", library_name,
                                                              " (segment ", a, " differs)"));
      }
    }
    auto doubles = [&](double* p, size_t n) -> Status {
      KINEMO_ASSIGN_OR_RETURN(std::uint64_t got, r.U64());
      if (got != n) return InvalidField(path, "array size mismatch");
      if (!in.read(reinterpret_cast<char*>(p), static_cast<std::streamsize>(n * sizeof(double))))
        return InvalidField(path, "truncated controller file");
      return absl::OkStatus();
    };
    StateModel& m = c->model_;
    {
      KINEMO_ASSIGN_OR_RETURN(std::uint64_t s, r.U64());
      if (s == 0 || s > 1000) return InvalidField(path, "bad state count");
      m.initial.resize(static_cast<Eigen::Index>(s));
      if (!in.read(reinterpret_cast<char*>(m.initial.data()), static_cast<std::streamsize>(s * sizeof(double))))
        return InvalidField(path, "truncated controller file");
      KINEMO_RETURN_IF_ERROR(r.Matrix(&m.transition, s * s));
      m.means.resize(s);
      m.covariances.resize(s);
      for (size_t i = 0; i < s; ++i) {
        KINEMO_RETURN_IF_ERROR(doubles(m.means[i].data(), 6));
        KINEMO_RETURN_IF_ERROR(doubles(m.covariances[i].data(), 36));
      }
    }
    c->transforms_.resize(c->tones_.size());
    for (auto& t : c->transforms_) {
      KINEMO_RETURN_IF_ERROR(doubles(t.A.data(), 36));
      KINEMO_RETURN_IF_ERROR(doubles(t.b.data(), 6));
    }
    KINEMO_RETURN_IF_ERROR(r.Matrix(&c->frame_transition_, big));
    const size_t M = c->tones_.size(), W = static_cast<size_t>(c->num_keyword_states());
    c->delta_.resize(M);
    for (auto& d : c->delta_) KINEMO_RETURN_IF_ERROR(r.Matrix(&d, big));
    c->u_.resize(M * W);
    c->vc_.resize(M * W);
    for (auto& u : c->u_) KINEMO_RETURN_IF_ERROR(r.Matrix(&u, big));
    for (auto& v : c->vc_) KINEMO_RETURN_IF_ERROR(r.Matrix(&v, big));
    c->sem_.resize(W);
    c->sem_offsets_.resize(W);
    for (size_t k = 0; k < W; ++k) {
      std::vector<int> flat;
      KINEMO_RETURN_IF_ERROR(r.Ints(&flat, big));
      KINEMO_ASSIGN_OR_RETURN(std::uint64_t nc, r.U64());
      if (nc * 4 != flat.size()) return InvalidField(path, "semantic table mismatch");
      std::vector<double> costs(nc);
      in.read(reinterpret_cast<char*>(costs.data()), static_cast<std::streamsize>(nc * sizeof(double)));
      for (size_t q = 0; q < nc; ++q) {
        Controller::SemanticEntry s{flat[4 * q], flat[4 * q + 1], flat[4 * q + 2], flat[4 * q + 3], costs[q]};
        if (s.e < 0 || s.e >= E || s.segment < 0 || s.segment >= N) return InvalidField(path, "semantic entry out of range");
        c->sem_[k].push_back(s);
      }
      KINEMO_RETURN_IF_ERROR(r.Ints(&c->sem_offsets_[k], static_cast<std::uint64_t>(E) + 1));
    }
    c->sem_values_.resize(M * W);
    for (auto& sv : c->sem_values_) KINEMO_RETURN_IF_ERROR(r.Matrix(&sv, big));
    c->kept_offsets_.resize(W);
    c->kept_.resize(W);
    for (size_t k = 0; k < W; ++k) {
      KINEMO_RETURN_IF_ERROR(r.Ints(&c->kept_offsets_[k], static_cast<std::uint64_t>(E) + 1));
      KINEMO_RETURN_IF_ERROR(r.Ints(&c->kept_[k], big));
      for (int b : c->kept_[k])
        if (b < 0 || b >= N) return InvalidField(path, "kept entry out of range");
    }
    // Shape checks.
    const int S = m.num_states();
    for (const auto& d : c->delta_)
      if (d.rows() != N || d.cols() != S) return InvalidField(path, "delta table shape mismatch");
    for (size_t k = 0; k < M * W; ++k)
      if (c->u_[k].rows() != N || c->vc_[k].rows() != E || c->u_[k].cols() != S || c->vc_[k].cols() != S)
        return InvalidField(path, "value table shape mismatch");
    for (size_t k = 0; k < W; ++k)
      if (c->sem_offsets_[k].size() != static_cast<size_t>(E) + 1 || c->kept_offsets_[k].size() != static_cast<size_t>(E) + 1)
        return InvalidField(path, "offset table shape mismatch");
    return std::shared_ptr<const Controller>(std::move(c));
  }
};

Status Controller::Save(const std::string& path, const std::vector<std::string>& library_sources,
                        const std::string& inference_model_path) const {
  return ControllerFile::Save(*this, path, library_sources, inference_model_path);
}

StatusOr<std::shared_ptr<const Controller>> Controller::Load(const std::string& path) {
  return ControllerFile::Load(path, nullptr);
}

StatusOr<std::shared_ptr<const Controller>> Controller::Load(const std::string& path,
                                                             std::shared_ptr<const Library> library) {
  if (library == nullptr) return InvalidField("library", "null");
  return ControllerFile::Load(path, std::move(library));
}

}  // namespace kinemo::planner::controller

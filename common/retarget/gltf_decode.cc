#include "common/retarget/gltf_decode.h"

#include <draco/compression/decode.h>
#include <meshoptimizer.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>

#include "common/json/json_fields.h"

namespace kinemo::retarget {
namespace {

using nlohmann::json;

constexpr std::uint32_t kGlbMagic = 0x46546C67;  // "glTF"
constexpr std::uint32_t kChunkJson = 0x4E4F534A;  // "JSON"
constexpr std::uint32_t kChunkBin = 0x004E4942;   // "BIN\0"
// A Draco mesh's points and faces, each (a character has ~10^5).
const std::string kMeshopt(kMeshoptExtension), kDraco(kDracoExtension);
constexpr std::uint64_t kMaxDracoElements = std::uint64_t{1} << 26;

std::uint32_t ReadU32(const char* p) {
  std::uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

// The decoder's working state: the document, what each buffer holds, and
// what each buffer view will hold in the output.
class GltfDecoder {
 public:
  GltfDecoder(const std::string& name, std::string base_dir, const GltfDecodeLimits& limits)
      : name_(name), base_dir_(std::move(base_dir)), limits_(limits) {}

  Status Fail(std::string_view part, std::string_view message) const {
    return absl::InvalidArgumentError(kinemo::StrCat(name_, ": ", part, ": ", message));
  }
  template <typename... Args>
  Status Failf(std::string_view part, const Args&... parts) const {
    return Fail(part, kinemo::StrCat(parts...));
  }
  // A json_fields.h error ("bufferViews[2].byteLength: ...") under the file's name.
  Status Named(const Status& s) const { return Annotate(s, name_); }

  StatusOr<std::optional<DecodedGlb>> Run(json doc, std::string_view bin, bool has_bin);

 private:
  Status LoadBuffers(std::string_view bin, bool has_bin);
  Status LoadViews();
  Status DecodeMeshopt(size_t v, const json& ext);
  Status DecodeDraco();
  Status DecodeDracoPrimitive(json& prim, const std::string& part);
  StatusOr<std::string> ReadUri(const std::string& uri, std::uint64_t length, const std::string& part);
  Status Charge(std::uint64_t bytes, const std::string& part);
  StatusOr<std::string> WriteGlb();

  const std::string& name_;
  std::string base_dir_;
  GltfDecodeLimits limits_;
  json doc_;
  std::vector<std::optional<std::string>> buffers_;  // nullopt: a fallback buffer without data
  std::vector<std::string> views_;                   // the output bytes of every view
  std::uint64_t decoded_bytes_ = 0;
  std::vector<std::string> used_;
};

Status GltfDecoder::Charge(std::uint64_t bytes, const std::string& part) {
  if (bytes > limits_.max_decoded_bytes || decoded_bytes_ > limits_.max_decoded_bytes - bytes) {
    return Failf(part, "decoding it would exceed ", limits_.max_decoded_bytes, " bytes in all");
  }
  decoded_bytes_ += bytes;
  return absl::OkStatus();
}

// RFC 4648 base64 (padding optional), bounded by `max` decoded bytes.
bool DecodeBase64(std::string_view in, size_t max, std::string* out) {
  static constexpr auto kTable = [] {
    std::array<int, 256> t{};
    t.fill(-1);
    const char* a = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    for (int i = 0; i < 64; ++i) t[static_cast<unsigned char>(a[i])] = i;
    return t;
  }();
  while (!in.empty() && in.back() == '=') in.remove_suffix(1);
  if (in.size() / 4 * 3 > max + 3) return false;
  out->clear();
  out->reserve(in.size() / 4 * 3 + 3);
  std::uint32_t acc = 0;
  int bits = 0;
  for (char c : in) {
    const int v = kTable[static_cast<unsigned char>(c)];
    if (v < 0) return false;
    acc = (acc << 6) | static_cast<std::uint32_t>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out->push_back(static_cast<char>((acc >> bits) & 0xff));
    }
  }
  return true;
}

std::string PercentDecoded(const std::string& uri) {
  std::string out;
  for (size_t i = 0; i < uri.size(); ++i) {
    if (uri[i] == '%' && i + 2 < uri.size() && std::isxdigit(static_cast<unsigned char>(uri[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(uri[i + 2]))) {
      out.push_back(static_cast<char>(std::stoi(uri.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    } else {
      out.push_back(uri[i]);
    }
  }
  return out;
}

StatusOr<std::string> GltfDecoder::ReadUri(const std::string& uri, std::uint64_t length, const std::string& part) {
  std::string data;
  if (uri.rfind("data:", 0) == 0) {
    const size_t comma = uri.find(',');
    if (comma == std::string::npos || uri.substr(0, comma).find(";base64") == std::string::npos) {
      return Fail(part + ".uri", "a data: URI must be base64");
    }
    if (!DecodeBase64(std::string_view(uri).substr(comma + 1), length, &data)) {
      return Fail(part + ".uri", "not valid base64");
    }
  } else {
    if (base_dir_.empty()) return Fail(part + ".uri", "an external file is not allowed here (a GLB must hold its data)");
    const std::filesystem::path path = std::filesystem::path(base_dir_) / PercentDecoded(uri);
    std::error_code ec;
    const auto size = std::filesystem::file_size(path, ec);
    if (ec) return Failf(part + ".uri", "cannot read ", path.string());
    if (size < length) return Failf(part + ".uri", path.string(), " has ", size, " bytes, fewer than byteLength ", length);
    std::ifstream in(path, std::ios::binary);
    data.resize(static_cast<size_t>(length));
    if (!in.read(data.data(), static_cast<std::streamsize>(length))) return Failf(part + ".uri", "cannot read ", path.string());
  }
  if (data.size() < length) return Failf(part, "holds ", data.size(), " bytes, fewer than byteLength ", length);
  data.resize(static_cast<size_t>(length));
  return data;
}

Status GltfDecoder::LoadBuffers(std::string_view bin, bool has_bin) {
  const json& buffers = doc_["buffers"];
  if (!buffers.is_array()) return Fail("buffers", "missing or not an array");
  for (size_t b = 0; b < buffers.size(); ++b) {
    const std::string part = kinemo::StrCat("buffers[", b, "]");
    const json& buf = buffers[b];
    if (!buf.is_object()) return Fail(part, "not an object");
    auto length = JsonInteger<std::uint64_t>(buf, "byteLength", std::nullopt, part + ".", 1, std::uint64_t{1} << 32);
    if (!length.ok()) return Named(length.status());
    const auto uri = buf.find("uri");
    bool fallback = false;
    if (auto e = buf.find("extensions"); e != buf.end() && e->is_object()) {
      if (auto m = e->find(kMeshopt); m != e->end() && m->is_object()) {
        fallback = m->value("fallback", false) == true;
      }
    }
    if (uri != buf.end()) {
      if (!uri->is_string()) return Fail(part + ".uri", "not a string");
      KINEMO_ASSIGN_OR_RETURN(std::string data, ReadUri(uri->get<std::string>(), *length, part));
      buffers_.emplace_back(std::move(data));
    } else if (b == 0 && has_bin) {
      if (*length > bin.size()) return Failf(part + ".byteLength", *length, " is larger than the GLB's BIN chunk (", bin.size(), " bytes)");
      buffers_.emplace_back(std::string(bin.substr(0, static_cast<size_t>(*length))));
    } else if (fallback) {
      buffers_.emplace_back(std::nullopt);  // its views must all be compressed
    } else {
      return Fail(part, "has no data (no uri, and not the GLB's BIN chunk)");
    }
  }
  return absl::OkStatus();
}

Status GltfDecoder::DecodeMeshopt(size_t v, const json& ext) {
  const std::string part = kinemo::StrCat("bufferViews[", v, "].extensions.", kMeshopt);
  const std::string prefix = part + ".";
  const json& view = doc_["bufferViews"][v];
  auto view_length = JsonInteger<std::uint64_t>(view, "byteLength", std::nullopt, kinemo::StrCat("bufferViews[", v, "]."), 1,
                                                std::uint64_t{1} << 32);
  if (!view_length.ok()) return Named(view_length.status());
  auto buffer = JsonInteger<std::int64_t>(ext, "buffer", std::nullopt, prefix, 0, static_cast<std::int64_t>(buffers_.size()) - 1);
  auto offset = JsonInteger<std::uint64_t>(ext, "byteOffset", std::uint64_t{0}, prefix);
  auto length = JsonInteger<std::uint64_t>(ext, "byteLength", std::nullopt, prefix, 1, std::uint64_t{1} << 32);
  auto stride = JsonInteger<std::uint32_t>(ext, "byteStride", std::nullopt, prefix, 1, 256);
  auto count = JsonInteger<std::uint64_t>(ext, "count", std::nullopt, prefix, 1, std::uint64_t{1} << 32);
  for (const Status& s : {buffer.status(), offset.status(), length.status(), stride.status(), count.status()}) {
    if (!s.ok()) return Named(s);
  }
  const auto mode_it = ext.find("mode");
  if (mode_it == ext.end() || !mode_it->is_string()) return Fail(prefix + "mode", "missing (ATTRIBUTES, TRIANGLES or INDICES)");
  const std::string mode = mode_it->get<std::string>();
  std::string filter = "NONE";
  if (auto f = ext.find("filter"); f != ext.end()) {
    if (!f->is_string()) return Fail(prefix + "filter", "not a string");
    filter = f->get<std::string>();
  }
  const std::optional<std::string>& src_buffer = buffers_[static_cast<size_t>(*buffer)];
  if (!src_buffer) return Fail(prefix + "buffer", "names a fallback buffer, which has no data");
  if (*offset > src_buffer->size() || *length > src_buffer->size() - *offset) {
    return Failf(prefix + "byteLength", "bytes ", *offset, "..", *offset + *length, " run past buffer ", *buffer, " (",
                 src_buffer->size(), " bytes)");
  }
  const std::uint64_t size = *count * *stride;  // both bounded: no overflow
  if (size > *view_length) {
    return Failf(part, "count ", *count, " x byteStride ", *stride, " = ", size, " bytes is more than the bufferView's byteLength ",
                 *view_length);
  }
  KINEMO_RETURN_IF_ERROR(Charge(*view_length, part));
  std::string out(static_cast<size_t>(*view_length), '\0');
  const auto* src = reinterpret_cast<const unsigned char*>(src_buffer->data() + *offset);
  int rc = 0;
  // The library asserts on these; check them first.
  if (mode == "ATTRIBUTES") {
    if (*stride % 4 != 0) return Failf(prefix + "byteStride", "must be a multiple of 4 for ATTRIBUTES, got ", *stride);
    rc = meshopt_decodeVertexBuffer(out.data(), *count, *stride, src, *length);
  } else if (mode == "TRIANGLES" || mode == "INDICES") {
    if (*stride != 2 && *stride != 4) return Failf(prefix + "byteStride", "must be 2 or 4 for ", mode, ", got ", *stride);
    if (mode == "TRIANGLES") {
      if (*count % 3 != 0) return Failf(prefix + "count", "must be a multiple of 3 for TRIANGLES, got ", *count);
      rc = meshopt_decodeIndexBuffer(out.data(), *count, *stride, src, *length);
    } else {
      rc = meshopt_decodeIndexSequence(out.data(), *count, *stride, src, *length);
    }
  } else {
    return Failf(prefix + "mode", "'", mode, "' is not ATTRIBUTES, TRIANGLES or INDICES");
  }
  if (rc != 0) return Failf(part, "the compressed data is malformed (meshoptimizer error ", rc, ")");
  if (filter != "NONE") {
    if (mode != "ATTRIBUTES") return Failf(prefix + "filter", filter, " needs mode ATTRIBUTES");
    if (filter == "OCTAHEDRAL") {
      if (*stride != 4 && *stride != 8) return Failf(prefix + "byteStride", "must be 4 or 8 for OCTAHEDRAL, got ", *stride);
      meshopt_decodeFilterOct(out.data(), *count, *stride);
    } else if (filter == "QUATERNION") {
      if (*stride != 8) return Failf(prefix + "byteStride", "must be 8 for QUATERNION, got ", *stride);
      meshopt_decodeFilterQuat(out.data(), *count, *stride);
    } else if (filter == "EXPONENTIAL") {
      meshopt_decodeFilterExp(out.data(), *count, *stride);
    } else {
      return Failf(prefix + "filter", "'", filter, "' is not NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL");
    }
  }
  views_[v] = std::move(out);
  return absl::OkStatus();
}

Status GltfDecoder::LoadViews() {
  json& views = doc_["bufferViews"];
  if (views.is_null()) views = json::array();
  if (!views.is_array()) return Fail("bufferViews", "not an array");
  views_.assign(views.size(), std::string());
  for (size_t v = 0; v < views.size(); ++v) {
    const std::string part = kinemo::StrCat("bufferViews[", v, "]");
    json& view = views[v];
    if (!view.is_object()) return Fail(part, "not an object");
    if (auto e = view.find("extensions"); e != view.end() && e->is_object()) {
      if (auto m = e->find(kMeshopt); m != e->end()) {
        if (!m->is_object()) return Fail(part + ".extensions." + kMeshopt, "not an object");
        KINEMO_RETURN_IF_ERROR(DecodeMeshopt(v, *m));
        e->erase(m);
        if (e->empty()) view.erase("extensions");
        continue;
      }
    }
    auto buffer = JsonInteger<std::int64_t>(view, "buffer", std::nullopt, part + ".", 0,
                                            static_cast<std::int64_t>(buffers_.size()) - 1);
    auto offset = JsonInteger<std::uint64_t>(view, "byteOffset", std::uint64_t{0}, part + ".");
    auto length = JsonInteger<std::uint64_t>(view, "byteLength", std::nullopt, part + ".", 1, std::uint64_t{1} << 32);
    for (const Status& s : {buffer.status(), offset.status(), length.status()}) {
      if (!s.ok()) return Named(s);
    }
    const std::optional<std::string>& data = buffers_[static_cast<size_t>(*buffer)];
    if (!data) return Fail(part + ".buffer", "names a fallback buffer but the view is not compressed");
    if (*offset > data->size() || *length > data->size() - *offset) {
      return Failf(part + ".byteLength", "bytes ", *offset, "..", *offset + *length, " run past buffer ", *buffer, " (",
                   data->size(), " bytes)");
    }
    views_[v] = data->substr(static_cast<size_t>(*offset), static_cast<size_t>(*length));
  }
  return absl::OkStatus();
}

int ComponentBytes(int type) {
  switch (type) {
    case 5120: case 5121: return 1;  // BYTE, UNSIGNED_BYTE
    case 5122: case 5123: return 2;  // SHORT, UNSIGNED_SHORT
    case 5125: case 5126: return 4;  // UNSIGNED_INT, FLOAT
    default: return 0;
  }
}

int TypeComponents(const std::string& type) {
  if (type == "SCALAR") return 1;
  if (type == "VEC2") return 2;
  if (type == "VEC3") return 3;
  if (type == "VEC4") return 4;
  return 0;
}

// One point's attribute value, converted to the accessor's component type.
template <typename T>
bool ConvertPoint(const draco::PointAttribute& att, draco::PointIndex p, int components, char* out) {
  T v[4] = {};
  if (!att.ConvertValue<T>(att.mapped_index(p), static_cast<int8_t>(components), v)) return false;
  std::memcpy(out, v, sizeof(T) * static_cast<size_t>(components));
  return true;
}

Status GltfDecoder::DecodeDracoPrimitive(json& prim, const std::string& part) {
  const std::string ext_part = part + ".extensions." + kDraco;
  json& ext = prim["extensions"][kDraco];
  if (!ext.is_object()) return Fail(ext_part, "not an object");
  auto view = JsonInteger<std::int64_t>(ext, "bufferView", std::nullopt, ext_part + ".", 0,
                                        static_cast<std::int64_t>(views_.size()) - 1);
  if (!view.ok()) return Named(view.status());
  const json& names = ext["attributes"];
  if (!names.is_object()) return Fail(ext_part + ".attributes", "missing or not an object");
  const std::string& bytes = views_[static_cast<size_t>(*view)];
  draco::DecoderBuffer buffer;
  buffer.Init(bytes.data(), bytes.size());
  auto type = draco::Decoder::GetEncodedGeometryType(&buffer);
  if (!type.ok() || type.value() != draco::TRIANGULAR_MESH) return Fail(ext_part, "not a Draco triangle mesh");
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) return Failf(ext_part, "Draco could not decode it: ", decoded.status().error_msg_string());
  const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
  const std::uint64_t points = mesh->num_points(), faces = mesh->num_faces();
  if (points > kMaxDracoElements || faces > kMaxDracoElements) return Failf(ext_part, points, " points, ", faces, " faces: too many");
  json& accessors = doc_["accessors"];
  if (!accessors.is_array()) return Fail("accessors", "missing or not an array");
  json& views = doc_["bufferViews"];
  // Gives accessor `a` a new view with `data`.
  auto attach = [&](std::int64_t a, std::string data, std::uint32_t stride) {
    json v = {{"buffer", 0}, {"byteLength", data.size()}};
    if (stride) v["byteStride"] = stride;
    views.push_back(std::move(v));
    views_.push_back(std::move(data));
    json& acc = accessors[static_cast<size_t>(a)];
    acc["bufferView"] = views.size() - 1;
    acc["byteOffset"] = 0;
  };
  auto accessor_of = [&](const json& index, const std::string& field) -> StatusOr<std::int64_t> {
    if (!index.is_number_integer() || index.get<std::int64_t>() < 0 ||
        index.get<std::int64_t>() >= static_cast<std::int64_t>(accessors.size())) {
      return Fail(field, "accessor out of range");
    }
    if (!accessors[index.get<size_t>()].is_object()) return Fail(field, "accessor is not an object");
    return index.get<std::int64_t>();
  };
  const json& attributes = prim["attributes"];
  if (!attributes.is_object()) return Fail(part + ".attributes", "missing or not an object");
  for (auto it = names.begin(); it != names.end(); ++it) {
    const std::string field = part + ".attributes." + it.key();
    if (!attributes.contains(it.key())) return Failf(ext_part + ".attributes." + it.key(), "the primitive has no such attribute");
    if (!it->is_number_unsigned() && !it->is_number_integer()) return Fail(ext_part + ".attributes." + it.key(), "not an id");
    KINEMO_ASSIGN_OR_RETURN(const std::int64_t a, accessor_of(attributes[it.key()], field));
    const json& acc = accessors[static_cast<size_t>(a)];
    const draco::PointAttribute* att =
        it->get<std::int64_t>() < 0 || it->get<std::int64_t>() > std::numeric_limits<std::int32_t>::max()
            ? nullptr
            : mesh->GetAttributeByUniqueId(static_cast<std::uint32_t>(it->get<std::int64_t>()));
    if (att == nullptr) return Failf(ext_part + ".attributes." + it.key(), "no Draco attribute with id ", it->dump());
    auto count = JsonInteger<std::uint64_t>(acc, "count", std::nullopt, kinemo::StrCat("accessors[", a, "]."), 1);
    auto ctype = JsonInteger<int>(acc, "componentType", std::nullopt, kinemo::StrCat("accessors[", a, "]."));
    if (!count.ok()) return Named(count.status());
    if (!ctype.ok()) return Named(ctype.status());
    const int csize = ComponentBytes(*ctype);
    const int ncomp = acc.contains("type") && acc["type"].is_string() ? TypeComponents(acc["type"].get<std::string>()) : 0;
    if (csize == 0 || ncomp == 0) return Failf(kinemo::StrCat("accessors[", a, "]"), "type/componentType not a vertex attribute's");
    if (*count != points) {
      return Failf(kinemo::StrCat("accessors[", a, "].count"), *count, " but the Draco mesh has ", points, " points");
    }
    const std::uint32_t element = static_cast<std::uint32_t>(csize * ncomp);
    const std::uint32_t stride = (element + 3) / 4 * 4;
    KINEMO_RETURN_IF_ERROR(Charge(points * stride, field));
    std::string data(static_cast<size_t>(points * stride), '\0');
    for (std::uint64_t p = 0; p < points; ++p) {
      char* out = data.data() + p * stride;
      const draco::PointIndex pi(static_cast<std::uint32_t>(p));
      bool ok = false;
      switch (*ctype) {
        case 5120: ok = ConvertPoint<std::int8_t>(*att, pi, ncomp, out); break;
        case 5121: ok = ConvertPoint<std::uint8_t>(*att, pi, ncomp, out); break;
        case 5122: ok = ConvertPoint<std::int16_t>(*att, pi, ncomp, out); break;
        case 5123: ok = ConvertPoint<std::uint16_t>(*att, pi, ncomp, out); break;
        case 5125: ok = ConvertPoint<std::uint32_t>(*att, pi, ncomp, out); break;
        default: ok = ConvertPoint<float>(*att, pi, ncomp, out); break;
      }
      if (!ok) return Failf(ext_part + ".attributes." + it.key(), "value of point ", p, " cannot be converted");
    }
    if (*ctype == 5126) {
      // Draco quantizes: the float skin weights are made to sum to 1 again
      // (WEIGHTS_0 alone), and min / max are those of the decoded values.
      const bool weights = it.key() == "WEIGHTS_0" && !attributes.contains("WEIGHTS_1");
      std::vector<double> lo(static_cast<size_t>(ncomp), std::numeric_limits<double>::infinity()),
          hi(static_cast<size_t>(ncomp), -std::numeric_limits<double>::infinity());
      for (std::uint64_t p = 0; p < points; ++p) {
        float v[4];
        std::memcpy(v, data.data() + p * stride, sizeof(float) * static_cast<size_t>(ncomp));
        if (weights) {
          float sum = 0;
          for (int c = 0; c < ncomp; ++c) sum += v[c] > 0 ? v[c] : 0;
          for (int c = 0; c < ncomp; ++c) v[c] = sum > 0 ? (v[c] > 0 ? v[c] / sum : 0) : (c == 0 ? 1.0f : 0.0f);
          std::memcpy(data.data() + p * stride, v, sizeof(float) * static_cast<size_t>(ncomp));
        }
        for (int c = 0; c < ncomp; ++c) {
          lo[static_cast<size_t>(c)] = std::min(lo[static_cast<size_t>(c)], static_cast<double>(v[c]));
          hi[static_cast<size_t>(c)] = std::max(hi[static_cast<size_t>(c)], static_cast<double>(v[c]));
        }
      }
      json& acc_out = accessors[static_cast<size_t>(a)];
      if (acc_out.contains("min") || it.key() == "POSITION") acc_out["min"] = lo;
      if (acc_out.contains("max") || it.key() == "POSITION") acc_out["max"] = hi;
    }
    attach(a, std::move(data), stride != element ? stride : 0);
  }
  if (auto idx = prim.find("indices"); idx != prim.end()) {
    KINEMO_ASSIGN_OR_RETURN(const std::int64_t a, accessor_of(*idx, part + ".indices"));
    const json& acc = accessors[static_cast<size_t>(a)];
    auto count = JsonInteger<std::uint64_t>(acc, "count", std::nullopt, kinemo::StrCat("accessors[", a, "]."), 1);
    auto ctype = JsonInteger<int>(acc, "componentType", std::nullopt, kinemo::StrCat("accessors[", a, "]."));
    if (!count.ok()) return Named(count.status());
    if (!ctype.ok()) return Named(ctype.status());
    if (*count != faces * 3) return Failf(kinemo::StrCat("accessors[", a, "].count"), *count, " but the Draco mesh has ", faces, " triangles");
    const int csize = *ctype == 5121 ? 1 : *ctype == 5123 ? 2 : *ctype == 5125 ? 4 : 0;
    if (csize == 0) return Failf(kinemo::StrCat("accessors[", a, "].componentType"), "not an index type");
    const std::uint64_t max_index = csize == 4 ? 0xffffffffu : (std::uint64_t{1} << (8 * csize)) - 1;
    KINEMO_RETURN_IF_ERROR(Charge(*count * static_cast<std::uint64_t>(csize), part + ".indices"));
    std::string data(static_cast<size_t>(*count) * static_cast<size_t>(csize), '\0');
    for (std::uint64_t f = 0; f < faces; ++f) {
      const draco::Mesh::Face& face = mesh->face(draco::FaceIndex(static_cast<std::uint32_t>(f)));
      for (int c = 0; c < 3; ++c) {
        const std::uint32_t i = face[c].value();
        if (i >= points || i > max_index) return Failf(ext_part, "triangle ", f, " names point ", i, " of ", points);
        std::memcpy(data.data() + (f * 3 + static_cast<std::uint64_t>(c)) * static_cast<std::uint64_t>(csize), &i,
                    static_cast<size_t>(csize));  // little-endian: the low bytes
      }
    }
    attach(a, std::move(data), 0);
  }
  json& exts = prim["extensions"];
  exts.erase(kDraco);
  if (exts.empty()) prim.erase("extensions");
  return absl::OkStatus();
}

Status GltfDecoder::DecodeDraco() {
  json& meshes = doc_["meshes"];
  if (!meshes.is_array()) return absl::OkStatus();
  for (size_t m = 0; m < meshes.size(); ++m) {
    json& prims = meshes[m]["primitives"];
    if (!prims.is_array()) continue;
    for (size_t p = 0; p < prims.size(); ++p) {
      json& prim = prims[p];
      if (!prim.is_object()) continue;
      auto e = prim.find("extensions");
      if (e == prim.end() || !e->is_object() || !e->contains(kDraco)) continue;
      KINEMO_RETURN_IF_ERROR(DecodeDracoPrimitive(prim, kinemo::StrCat("meshes[", m, "].primitives[", p, "]")));
    }
  }
  return absl::OkStatus();
}

StatusOr<std::string> GltfDecoder::WriteGlb() {
  std::string bin;
  json& views = doc_["bufferViews"];
  for (size_t v = 0; v < views_.size(); ++v) {
    while (bin.size() % 4 != 0) bin.push_back('\0');
    json& view = views[v];
    view["buffer"] = 0;
    view["byteOffset"] = bin.size();
    view["byteLength"] = views_[v].size();
    bin += views_[v];
  }
  while (bin.size() % 4 != 0) bin.push_back('\0');
  doc_["buffers"] = json::array({json{{"byteLength", bin.size()}}});
  if (bin.empty()) doc_.erase("buffers");
  for (const char* key : {"extensionsUsed", "extensionsRequired"}) {
    auto it = doc_.find(key);
    if (it == doc_.end() || !it->is_array()) continue;
    json kept = json::array();
    for (const json& e : *it) {
      if (!(e.is_string() && (e.get_ref<const std::string&>() == kMeshopt || e.get_ref<const std::string&>() == kDraco))) kept.push_back(e);
    }
    if (kept.empty()) {
      doc_.erase(key);
    } else {
      *it = kept;
    }
  }
  std::string text = doc_.dump(-1, ' ', false, json::error_handler_t::replace);
  while (text.size() % 4 != 0) text.push_back(' ');
  const std::uint64_t total = 12 + 8 + text.size() + (bin.empty() ? 0 : 8 + bin.size());
  if (total > std::numeric_limits<std::uint32_t>::max()) return Fail("buffers", "the decoded document is larger than a GLB can hold");
  std::string out;
  out.reserve(static_cast<size_t>(total));
  auto put = [&](std::uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
  put(kGlbMagic);
  put(2);
  put(static_cast<std::uint32_t>(total));
  put(static_cast<std::uint32_t>(text.size()));
  put(kChunkJson);
  out += text;
  if (!bin.empty()) {
    put(static_cast<std::uint32_t>(bin.size()));
    put(kChunkBin);
    out += bin;
  }
  return out;
}

StatusOr<std::optional<DecodedGlb>> GltfDecoder::Run(json doc, std::string_view bin, bool has_bin) {
  doc_ = std::move(doc);
  if (!doc_.is_object()) return Fail("JSON", "not an object");
  // Which compression the document uses.
  bool meshopt = false, draco = false;
  for (const char* key : {"extensionsUsed", "extensionsRequired"}) {
    const auto it = doc_.find(key);
    if (it == doc_.end() || !it->is_array()) continue;
    for (const json& e : *it) {
      meshopt = meshopt || (e.is_string() && e.get_ref<const std::string&>() == kMeshopt);
      draco = draco || (e.is_string() && e.get_ref<const std::string&>() == kDraco);
    }
  }
  if (!meshopt && !draco) return std::optional<DecodedGlb>();
  KINEMO_RETURN_IF_ERROR(LoadBuffers(bin, has_bin));
  KINEMO_RETURN_IF_ERROR(LoadViews());
  if (draco) KINEMO_RETURN_IF_ERROR(DecodeDraco());
  DecodedGlb out;
  if (meshopt) out.decoded.emplace_back(kMeshopt);
  if (draco) out.decoded.emplace_back(kDraco);
  KINEMO_ASSIGN_OR_RETURN(out.glb, WriteGlb());
  return std::optional<DecodedGlb>(std::move(out));
}

StatusOr<json> ParseJson(std::string_view text, const std::string& name, const GltfDecodeLimits& limits) {
  if (text.size() > limits.max_json_bytes) {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": JSON: larger than ", limits.max_json_bytes, " bytes"));
  }
  if (JsonNestingDepth(text, limits.max_json_depth) > limits.max_json_depth) {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": JSON: nested deeper than ", limits.max_json_depth, " levels"));
  }
  json doc = json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) return absl::InvalidArgumentError(kinemo::StrCat(name, ": JSON: not valid JSON"));
  return doc;
}

// Cheap test before any parsing: a document without the names cannot use them.
bool MentionsCompression(std::string_view text) {
  return text.find(kMeshopt) != std::string_view::npos || text.find(kDraco) != std::string_view::npos;
}

}  // namespace

int JsonNestingDepth(std::string_view text, int limit) {
  int depth = 0, deepest = 0;
  bool in_string = false, escaped = false;
  for (char c : text) {
    if (in_string) {
      if (escaped) {
        escaped = false;
      } else if (c == '\\') {
        escaped = true;
      } else if (c == '"') {
        in_string = false;
      }
      continue;
    }
    if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      deepest = std::max(deepest, ++depth);
      if (deepest > limit) return deepest;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return deepest;
}

StatusOr<std::optional<DecodedGlb>> DecodeCompressedGlb(std::string_view glb, const std::string& name,
                                                        const std::string& base_dir, const GltfDecodeLimits& limits) {
  auto fail = [&](std::string_view message) {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": GLB container: ", message));
  };
  if (glb.size() < 20 || ReadU32(glb.data()) != kGlbMagic) return fail("does not start with \"glTF\"");
  if (ReadU32(glb.data() + 4) != 2) return fail(kinemo::StrCat("version ", ReadU32(glb.data() + 4), " (only 2 is glTF 2.0)"));
  const std::uint64_t total = ReadU32(glb.data() + 8);
  if (total > glb.size() || total < 20) return fail(kinemo::StrCat("length ", total, " but ", glb.size(), " bytes are present"));
  const std::uint64_t json_length = ReadU32(glb.data() + 12);
  if (ReadU32(glb.data() + 16) != kChunkJson) return fail("the first chunk is not JSON");
  if (json_length > total - 20) return fail(kinemo::StrCat("JSON chunk of ", json_length, " bytes runs past the file"));
  const std::string_view text = glb.substr(20, static_cast<size_t>(json_length));
  if (!MentionsCompression(text)) return std::optional<DecodedGlb>();
  std::string_view bin;
  bool has_bin = false;
  std::uint64_t at = 20 + json_length;
  at = (at + 3) / 4 * 4;
  if (at + 8 <= total) {
    const std::uint64_t bin_length = ReadU32(glb.data() + at);
    if (ReadU32(glb.data() + at + 4) == kChunkBin) {
      if (bin_length > total - at - 8) return fail(kinemo::StrCat("BIN chunk of ", bin_length, " bytes runs past the file"));
      bin = glb.substr(static_cast<size_t>(at + 8), static_cast<size_t>(bin_length));
      has_bin = true;
    }
  }
  KINEMO_ASSIGN_OR_RETURN(json doc, ParseJson(text, name, limits));
  GltfDecoder decoder(name, base_dir, limits);
  return decoder.Run(std::move(doc), bin, has_bin);
}

StatusOr<std::optional<DecodedGlb>> DecodeCompressedGltf(std::string_view json_text, const std::string& name,
                                                         const std::string& base_dir, const GltfDecodeLimits& limits) {
  if (!MentionsCompression(json_text)) return std::optional<DecodedGlb>();
  KINEMO_ASSIGN_OR_RETURN(json doc, ParseJson(json_text, name, limits));
  GltfDecoder decoder(name, base_dir.empty() ? std::string(".") : base_dir, limits);
  return decoder.Run(std::move(doc), {}, false);
}

}  // namespace kinemo::retarget

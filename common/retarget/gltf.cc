#include "common/retarget/gltf.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>

#include <webp/decode.h>

#include "common/image/png.h"
#include "common/motion/kinematics.h"
#include "common/retarget/fbx.h"
#include "common/retarget/gltf_decode.h"
#include "common/retarget/transform.h"

namespace kinemo::retarget {
namespace {

// Images are carried through untouched: no decoding on load.
bool KeepImage(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
  return true;
}

bool EndsWith(const std::string& s, std::string_view suffix) {
  if (s.size() < suffix.size()) return false;
  for (size_t i = 0; i < suffix.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(s[s.size() - suffix.size() + i])) != suffix[i]) return false;
  }
  return true;
}

// Appends `bytes` to buffer 0 (4-byte aligned) as a new bufferView; returns its index.
int AppendBufferView(tinygltf::Model& model, const void* bytes, size_t size) {
  if (model.buffers.empty()) model.buffers.emplace_back();
  std::vector<unsigned char>& data = model.buffers[0].data;
  while (data.size() % 4 != 0) data.push_back(0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = data.size();
  view.byteLength = size;
  const auto* p = static_cast<const unsigned char*>(bytes);
  data.insert(data.end(), p, p + size);
  model.bufferViews.push_back(view);
  return static_cast<int>(model.bufferViews.size()) - 1;
}

int AppendFloatAccessor(tinygltf::Model& model, const std::vector<float>& values, int type, int count) {
  tinygltf::Accessor acc;
  acc.bufferView = AppendBufferView(model, values.data(), values.size() * sizeof(float));
  acc.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
  acc.type = type;
  acc.count = static_cast<size_t>(count);
  if (type == TINYGLTF_TYPE_SCALAR && !values.empty()) {
    acc.minValues = {*std::min_element(values.begin(), values.end())};
    acc.maxValues = {*std::max_element(values.begin(), values.end())};
  }
  model.accessors.push_back(acc);
  return static_cast<int>(model.accessors.size()) - 1;
}

// Writes `model` as a GLB at `path` (through a temporary file, renamed).
Status WriteGlbFile(tinygltf::Model& model, const std::string& path) {
  tinygltf::TinyGLTF writer;
  const std::string tmp = path + ".tmp";
  if (!writer.WriteGltfSceneToFile(&model, tmp, /*embedImages=*/true, /*embedBuffers=*/true,
                                   /*prettyPrint=*/false, /*writeBinary=*/true)) {
    std::filesystem::remove(tmp);
    return absl::InternalError(kinemo::StrCat(path, ": could not write the GLB"));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) return absl::InternalError(kinemo::StrCat(path, ": ", ec.message()));
  return absl::OkStatus();
}

// A sampler over `input` with `values` (count keys of `type`), and a channel
// moving `node`'s `path_name` with it.
void AddChannel(tinygltf::Model& model, tinygltf::Animation& anim, int input, int count, int node,
                const char* path_name, const std::vector<float>& values, int type) {
  tinygltf::AnimationSampler sampler;
  sampler.input = input;
  sampler.output = AppendFloatAccessor(model, values, type, count);
  sampler.interpolation = "LINEAR";
  anim.samplers.push_back(sampler);
  tinygltf::AnimationChannel channel;
  channel.sampler = static_cast<int>(anim.samplers.size()) - 1;
  channel.target_node = node;
  channel.target_path = path_name;
  anim.channels.push_back(channel);
}

// Appends x y z w of `r` to `out`, on the shorter way from the previous
// key (q and -q are one rotation).
void AppendQuaternion(const Eigen::Matrix3d& r, std::vector<float>& out) {
  Eigen::Quaterniond q(r);
  q.normalize();
  float v[4] = {static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                static_cast<float>(q.w())};
  if (out.size() >= 4) {
    const float* prev = &out[out.size() - 4];
    if (prev[0] * v[0] + prev[1] * v[1] + prev[2] * v[2] + prev[3] * v[3] < 0) {
      for (float& x : v) x = -x;
    }
  }
  out.insert(out.end(), v, v + 4);
}

// EXT_texture_webp textures without a fallback `source` get a PNG of the
// same picture as their source (the WebP image stays, untouched, as the
// extension's source), and the extension is then only "used", not
// "required": readers without WebP (Blender 3.x's glTF importer) take the
// PNG, readers with it the WebP.
Status AddPngFallbacks(tinygltf::Model& model, const std::string& name) {
  std::map<int, int> png_of;  // WebP image -> its PNG image
  bool all = true;
  for (size_t t = 0; t < model.textures.size(); ++t) {
    tinygltf::Texture& tex = model.textures[t];
    const auto it = tex.extensions.find("EXT_texture_webp");
    if (it == tex.extensions.end() || tex.source >= 0) continue;
    const tinygltf::Value& src = Member(it->second, "source");
    const int image = src.IsNumber() ? src.GetNumberAsInt() : -1;
    const std::string part = kinemo::StrCat(name, ": textures[", t, "].extensions.EXT_texture_webp.source");
    if (image < 0 || image >= static_cast<int>(model.images.size())) return absl::InvalidArgumentError(part + ": not an image");
    if (auto done = png_of.find(image); done != png_of.end()) {
      tex.source = done->second;
      continue;
    }
    const tinygltf::Image& img = model.images[static_cast<size_t>(image)];
    if (img.bufferView < 0 || img.bufferView >= static_cast<int>(model.bufferViews.size())) {
      all = false;  // an external file: left to the reader
      continue;
    }
    const tinygltf::BufferView& view = model.bufferViews[static_cast<size_t>(img.bufferView)];
    if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size()) ||
        view.byteOffset > model.buffers[static_cast<size_t>(view.buffer)].data.size() ||
        view.byteLength > model.buffers[static_cast<size_t>(view.buffer)].data.size() - view.byteOffset) {
      return absl::InvalidArgumentError(kinemo::StrCat(name, ": images[", image, "].bufferView: runs past its buffer"));
    }
    const std::uint8_t* bytes = model.buffers[static_cast<size_t>(view.buffer)].data.data() + view.byteOffset;
    int width = 0, height = 0;
    if (!WebPGetInfo(bytes, view.byteLength, &width, &height) || width <= 0 || height <= 0 ||
        static_cast<std::int64_t>(width) * height > (std::int64_t{1} << 26)) {
      return absl::InvalidArgumentError(kinemo::StrCat(name, ": images[", image, "]: not a WebP picture kinemo can decode"));
    }
    std::uint8_t* rgba = WebPDecodeRGBA(bytes, view.byteLength, &width, &height);
    if (rgba == nullptr) return absl::InvalidArgumentError(kinemo::StrCat(name, ": images[", image, "]: WebP data is damaged"));
    auto png = image::EncodePng({.data = rgba, .width = width, .height = height, .channels = 4, .stride = 0, .bgr = false}, 4);
    WebPFree(rgba);
    if (!png.ok()) return png.status();
    tinygltf::Image fallback;
    fallback.name = img.name.empty() ? kinemo::StrCat("image", image, "_png") : img.name + "_png";
    fallback.mimeType = "image/png";
    fallback.bufferView = AppendBufferView(model, png->data(), png->size());
    model.images.push_back(fallback);
    tex.source = static_cast<int>(model.images.size()) - 1;
    png_of[image] = tex.source;
  }
  if (all && !png_of.empty()) {
    auto& req = model.extensionsRequired;
    req.erase(std::remove(req.begin(), req.end(), "EXT_texture_webp"), req.end());
  }
  return absl::OkStatus();
}

}  // namespace

Eigen::Matrix3d Orthonormalized(const Eigen::Matrix3d& m) {
  Eigen::Matrix3d n = m;
  for (int c = 0; c < 3; ++c) {
    const double len = n.col(c).norm();
    if (len > 0) n.col(c) /= len;
  }
  return Eigen::Quaterniond(n).normalized().toRotationMatrix();
}

Eigen::Matrix4d NodeLocalMatrix(const tinygltf::Node& node) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (node.matrix.size() == 16) {
    for (int i = 0; i < 16; ++i) m(i % 4, i / 4) = node.matrix[static_cast<size_t>(i)];
    return m;
  }
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  if (node.rotation.size() == 4) {
    r = Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2])
            .normalized()
            .toRotationMatrix();
  }
  Eigen::Vector3d s(1, 1, 1);
  if (node.scale.size() == 3) s = Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]);
  m.block<3, 3>(0, 0) = r * s.asDiagonal();
  if (node.translation.size() == 3) {
    m.block<3, 1>(0, 3) = Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]);
  }
  return m;
}

StatusOr<NodeTree> BuildNodeTree(const tinygltf::Model& model) {
  const int n = static_cast<int>(model.nodes.size());
  NodeTree tree;
  tree.parent.assign(static_cast<size_t>(n), -1);
  tree.depth.assign(static_cast<size_t>(n), -1);
  tree.global.assign(static_cast<size_t>(n), Eigen::Matrix4d::Identity());
  for (int i = 0; i < n; ++i) {
    for (int c : model.nodes[i].children) {
      if (c < 0 || c >= n) return InvalidField(kinemo::StrCat("nodes[", i, "].children"), "node ", c, " out of range");
      if (tree.parent[c] >= 0) return InvalidField(kinemo::StrCat("nodes[", c, "]"), "has two parents");
      tree.parent[c] = i;
    }
  }
  // Depth-first from the roots; a node never reached is in a cycle.
  std::vector<int> stack;
  for (int i = 0; i < n; ++i) {
    if (tree.parent[i] < 0) {
      tree.depth[i] = 0;
      tree.global[i] = NodeLocalMatrix(model.nodes[i]);
      stack.push_back(i);
    }
  }
  while (!stack.empty()) {
    const int i = stack.back();
    stack.pop_back();
    for (int c : model.nodes[i].children) {
      tree.depth[c] = tree.depth[i] + 1;
      tree.global[c] = tree.global[i] * NodeLocalMatrix(model.nodes[c]);
      stack.push_back(c);
    }
  }
  for (int i = 0; i < n; ++i) {
    if (tree.depth[i] < 0) return InvalidField(kinemo::StrCat("nodes[", i, "]"), "is in a cycle of children");
  }
  return tree;
}

StatusOr<std::vector<Eigen::Matrix4d>> ReadInverseBindMatrices(const tinygltf::Model& model,
                                                               const tinygltf::Skin& skin) {
  std::vector<Eigen::Matrix4d> out;
  if (skin.inverseBindMatrices < 0) return out;
  const std::string field = "skin.inverseBindMatrices";
  if (skin.inverseBindMatrices >= static_cast<int>(model.accessors.size())) return InvalidField(field, "accessor out of range");
  const tinygltf::Accessor& acc = model.accessors[skin.inverseBindMatrices];
  if (acc.type != TINYGLTF_TYPE_MAT4 || acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT ||
      acc.count != skin.joints.size() || acc.bufferView < 0 ||
      acc.bufferView >= static_cast<int>(model.bufferViews.size())) {
    return InvalidField(field, "must be a float MAT4 accessor with one matrix per joint");
  }
  const tinygltf::BufferView& view = model.bufferViews[acc.bufferView];
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size())) return InvalidField(field, "buffer out of range");
  const std::vector<unsigned char>& data = model.buffers[view.buffer].data;
  const size_t stride = view.byteStride ? view.byteStride : 64;
  const size_t start = view.byteOffset + acc.byteOffset;
  if (stride < 64 || start + stride * (acc.count - 1) + 64 > data.size() || acc.byteOffset + stride * (acc.count - 1) + 64 > view.byteLength) {
    return InvalidField(field, "runs past its buffer");
  }
  for (size_t k = 0; k < acc.count; ++k) {
    float f[16];
    std::memcpy(f, data.data() + start + k * stride, sizeof(f));
    Eigen::Matrix4d m;
    for (int i = 0; i < 16; ++i) m(i % 4, i / 4) = f[i];
    if (!m.allFinite() || std::abs(m.determinant()) < 1e-30) return InvalidField(field, "matrix ", k, " is singular");
    out.push_back(m);
  }
  return out;
}

namespace {

// A GLB's bytes (decoded first when compressed) into a document.
StatusOr<std::shared_ptr<GltfSource>> LoadGlbBytes(std::string_view bytes, const std::string& name,
                                                   const std::string& base_dir, const GltfDecodeLimits& limits = {}) {
  KINEMO_ASSIGN_OR_RETURN(std::optional<DecodedGlb> decoded, DecodeCompressedGlb(bytes, name, base_dir, limits));
  const std::string_view plain = decoded ? std::string_view(decoded->glb) : bytes;
  auto src = std::make_shared<GltfSource>();
  src->path = name;
  if (decoded) src->decoded = decoded->decoded;
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&KeepImage, nullptr);
  std::string err, warn;
  if (!loader.LoadBinaryFromMemory(&src->model, &err, &warn, reinterpret_cast<const unsigned char*>(plain.data()),
                                   static_cast<unsigned int>(plain.size()), base_dir)) {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": not a valid glTF/GLB: ", err));
  }
  return src;
}

}  // namespace

StatusOr<std::shared_ptr<GltfSource>> ReadGltf(const std::string& path) {
  if (IsFbxPath(path)) return ReadFbx(path);
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return absl::NotFoundError(kinemo::StrCat(path, ": no such file"));
  constexpr uintmax_t kMaxBytes = uintmax_t{1} << 30;
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec || size > kMaxBytes) return absl::InvalidArgumentError(kinemo::StrCat(path, ": larger than 1 GiB"));
  std::string bytes(static_cast<size_t>(size), '\0');
  {
    std::ifstream in(path, std::ios::binary);
    if (!in.read(bytes.data(), static_cast<std::streamsize>(size))) {
      return absl::NotFoundError(kinemo::StrCat(path, ": cannot read"));
    }
  }
  std::string base_dir = std::filesystem::path(path).parent_path().string();
  if (base_dir.empty()) base_dir = ".";
  if (!EndsWith(path, ".gltf")) return LoadGlbBytes(bytes, path, base_dir);
  KINEMO_ASSIGN_OR_RETURN(std::optional<DecodedGlb> decoded, DecodeCompressedGltf(bytes, path, base_dir));
  if (decoded) {
    KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<GltfSource> src, LoadGlbBytes(decoded->glb, path, base_dir));
    src->decoded = decoded->decoded;
    return src;
  }
  auto src = std::make_shared<GltfSource>();
  src->path = path;
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&KeepImage, nullptr);
  std::string err, warn;
  if (!loader.LoadASCIIFromString(&src->model, &err, &warn, bytes.data(), static_cast<unsigned int>(bytes.size()),
                                  base_dir)) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": not a valid glTF/GLB: ", err));
  }
  return src;
}

StatusOr<std::shared_ptr<GltfSource>> ReadGlbFromMemory(std::string_view bytes, const std::string& name,
                                                        const GltfDecodeLimits& limits) {
  if (bytes.size() < 20 || bytes.substr(0, 4) != "glTF") {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": not a GLB (a GLB starts with the bytes \"glTF\")"));
  }
  if (bytes.size() > (uintmax_t{1} << 30)) return absl::InvalidArgumentError(kinemo::StrCat(name, ": larger than 1 GiB"));
  // An upload holds all its data: no external files ("" base directory).
  return LoadGlbBytes(bytes, name, "", limits);
}

StatusOr<NodePoser> NodePoser::Create(const Rig& rig) {
  if (!rig.gltf) return absl::FailedPreconditionError(kinemo::StrCat(rig.name, ": not a glTF rig"));
  const tinygltf::Model& model = rig.gltf->model;
  KINEMO_ASSIGN_OR_RETURN(NodeTree tree, BuildNodeTree(model));
  NodePoser p;
  p.skeleton_ = rig.skeleton;
  p.bind_rotation_ = rig.bind_rotation;
  const int nj = rig.skeleton.num_joints();
  std::map<int, int> joint_of_node;
  for (int j = 0; j < nj; ++j) joint_of_node[rig.node[j]] = j;
  p.parent_joint_.assign(static_cast<size_t>(nj), -1);
  p.fixed_parent_.assign(static_cast<size_t>(nj), {Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), 1.0});
  p.bind_scale_.assign(static_cast<size_t>(nj), 1.0);
  for (int j = 0; j < nj; ++j) {
    p.bind_scale_[j] = tree.global[rig.node[j]].block<3, 1>(0, 0).norm();
    if (rig.skeleton.joint(j).has_position_channels()) p.translated_.push_back(j);
    const int pn = tree.parent[rig.node[j]];
    if (pn < 0) continue;
    if (auto it = joint_of_node.find(pn); it != joint_of_node.end()) {
      p.parent_joint_[j] = it->second;
    } else {
      const Eigen::Matrix4d& g = tree.global[pn];
      p.fixed_parent_[j] = {Orthonormalized(g.block<3, 3>(0, 0)), g.block<3, 1>(0, 3), g.block<3, 1>(0, 0).norm()};
    }
  }
  // The bind pose: identity rotations at the rest positions.
  p.pos_ = rig.RestPositions();
  p.rot_.assign(static_cast<size_t>(nj), Eigen::Matrix3d::Identity());
  p.bind_translation_.resize(static_cast<size_t>(nj));
  for (int j = 0; j < nj; ++j) {
    const Frame3 par = p.ParentOf(j);
    p.bind_translation_[j] = par.r.transpose() * (p.pos_[j] - par.p) / par.s;
  }
  return p;
}

NodePoser::Frame3 NodePoser::ParentOf(int j) const {
  const int pj = parent_joint_[j];
  if (pj < 0) return fixed_parent_[j];
  return {Eigen::Matrix3d(rot_[pj] * bind_rotation_[pj]), pos_[pj], bind_scale_[pj]};
}

Status NodePoser::Pose(std::span<const double> frame, std::span<float> rotations, std::span<float> translations) {
  const int nj = skeleton_.num_joints();
  if (rotations.size() != static_cast<size_t>(nj) * 4 || translations.size() != translated_.size() * 3) {
    return absl::InvalidArgumentError("NodePoser::Pose: output sizes do not match the rig");
  }
  KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(skeleton_, frame, pos_, rot_));
  size_t t = 0;
  for (int j = 0; j < nj; ++j) {
    const Frame3 par = ParentOf(j);
    Eigen::Quaterniond q(Eigen::Matrix3d(par.r.transpose() * rot_[j] * bind_rotation_[j]));
    q.normalize();
    float* r = &rotations[static_cast<size_t>(j) * 4];
    r[0] = static_cast<float>(q.x());
    r[1] = static_cast<float>(q.y());
    r[2] = static_cast<float>(q.z());
    r[3] = static_cast<float>(q.w());
    if (t < translated_.size() && translated_[t] == j) {
      const Eigen::Vector3d v = par.r.transpose() * (pos_[j] - par.p) / par.s;
      for (int k = 0; k < 3; ++k) translations[t * 3 + static_cast<size_t>(k)] = static_cast<float>(v[k]);
      ++t;
    }
  }
  return absl::OkStatus();
}

Status WriteAnimatedGlb(const Rig& rig, const motion::Clip& clip, const std::string& path,
                        const GlbWriteOptions& options) {
  if (!rig.gltf) return absl::FailedPreconditionError(kinemo::StrCat(rig.name, ": not a glTF rig (write BVH instead)"));
  if (clip.skeleton.num_joints() != rig.skeleton.num_joints() || clip.skeleton.num_channels() != rig.skeleton.num_channels()) {
    return absl::InvalidArgumentError("clip is not on the rig's skeleton");
  }
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  if (clip.num_frames() < 1) return absl::InvalidArgumentError("clip has no frames");
  tinygltf::Model model = rig.gltf->model;
  KINEMO_ASSIGN_OR_RETURN(NodePoser poser, NodePoser::Create(rig));
  const int nj = rig.skeleton.num_joints();
  // Joint nodes get their bind-pose local translation as default.
  for (int j = 0; j < nj; ++j) {
    const Eigen::Vector3d& t = poser.bind_translation()[j];
    tinygltf::Node& node = model.nodes[rig.node[j]];
    node.matrix.clear();
    node.translation = {t.x(), t.y(), t.z()};
    if (node.scale.empty()) node.scale = {1, 1, 1};
    if (node.rotation.empty()) node.rotation = {0, 0, 0, 1};
  }

  const int nf = clip.num_frames();
  const std::vector<int>& moved = poser.translated_joints();
  std::vector<float> times(static_cast<size_t>(nf));
  for (int f = 0; f < nf; ++f) times[f] = static_cast<float>(f * clip.frame_time_s);
  std::vector<std::vector<float>> rotations(static_cast<size_t>(nj)), translations(moved.size());
  std::vector<float> q(static_cast<size_t>(nj) * 4), t(moved.size() * 3);
  for (int f = 0; f < nf; ++f) {
    KINEMO_RETURN_IF_ERROR(poser.Pose(clip.frame(f), q, t));
    for (int j = 0; j < nj; ++j) {
      float* r = &q[static_cast<size_t>(j) * 4];
      std::vector<float>& out = rotations[j];
      // The shorter way from the previous key (q and -q are one rotation).
      if (f > 0) {
        const float* prev = &out[out.size() - 4];
        if (prev[0] * r[0] + prev[1] * r[1] + prev[2] * r[2] + prev[3] * r[3] < 0) {
          for (int k = 0; k < 4; ++k) r[k] = -r[k];
        }
      }
      out.insert(out.end(), r, r + 4);
    }
    for (size_t k = 0; k < moved.size(); ++k) translations[k].insert(translations[k].end(), &t[k * 3], &t[k * 3 + 3]);
  }
  tinygltf::Animation anim;
  anim.name = options.animation_name;
  const int input = AppendFloatAccessor(model, times, TINYGLTF_TYPE_SCALAR, nf);
  auto add_channel = [&](int node, const char* path_name, const std::vector<float>& values, int type) {
    AddChannel(model, anim, input, nf, node, path_name, values, type);
  };
  for (int j = 0; j < nj; ++j) add_channel(rig.node[j], "rotation", rotations[j], TINYGLTF_TYPE_VEC4);
  for (size_t k = 0; k < moved.size(); ++k) {
    add_channel(rig.node[moved[k]], "translation", translations[k], TINYGLTF_TYPE_VEC3);
  }
  // The face: per driven mesh, every target's weight per frame.
  if ((options.face == nullptr) != (options.face_map == nullptr)) {
    return absl::InvalidArgumentError("WriteAnimatedGlb: face and face_map go together");
  }
  if (options.face != nullptr) {
    const FaceAnimation& face = *options.face;
    const int total = options.face_map->num_morph_weights();
    if (face.num_frames != nf || face.morph_weights.size() != static_cast<size_t>(nf) * static_cast<size_t>(total)) {
      return absl::InvalidArgumentError("WriteAnimatedGlb: the face animation does not match the clip");
    }
    int offset = 0;
    for (const MorphMesh& mm : options.face_map->morph_meshes()) {
      std::vector<float> values(static_cast<size_t>(nf) * static_cast<size_t>(mm.num_targets));
      for (int f = 0; f < nf; ++f) {
        std::copy_n(face.morph_weights.begin() + static_cast<std::ptrdiff_t>(f) * total + offset, mm.num_targets,
                    values.begin() + static_cast<std::ptrdiff_t>(f) * mm.num_targets);
      }
      offset += mm.num_targets;
      if (mm.nodes.empty() || mm.num_targets == 0) continue;
      tinygltf::AnimationSampler sampler;
      sampler.input = input;
      sampler.output = AppendFloatAccessor(model, values, TINYGLTF_TYPE_SCALAR, nf * mm.num_targets);
      sampler.interpolation = "LINEAR";
      anim.samplers.push_back(sampler);
      for (int node : mm.nodes) {
        tinygltf::AnimationChannel channel;
        channel.sampler = static_cast<int>(anim.samplers.size()) - 1;
        channel.target_node = node;
        channel.target_path = "weights";
        anim.channels.push_back(channel);
      }
      // The mesh's default weights (all targets, zero where the file has none).
      tinygltf::Mesh& mesh = model.meshes[static_cast<size_t>(mm.mesh)];
      mesh.weights.resize(static_cast<size_t>(mm.num_targets), 0.0);
      // The targets' names where readers look for them (mesh.extras, as
      // Blender and three.js read them; UniVRM writes them on the primitive).
      const bool extras_free = mesh.extras.IsObject() || mesh.extras.Type() == tinygltf::NULL_TYPE;
      if (extras_free && !Member(mesh.extras, "targetNames").IsArray()) {
        bool named = false;
        tinygltf::Value::Array names;
        for (const std::string& n : mm.target_names) {
          names.emplace_back(n);
          named = named || !n.empty();
        }
        if (named) {
          tinygltf::Value::Object extras = mesh.extras.IsObject() ? mesh.extras.Get<tinygltf::Value::Object>()
                                                                  : tinygltf::Value::Object();
          extras["targetNames"] = tinygltf::Value(std::move(names));
          mesh.extras = tinygltf::Value(std::move(extras));
        }
      }
    }
  }
  if (options.png_fallbacks) KINEMO_RETURN_IF_ERROR(AddPngFallbacks(model, rig.name));
  if (!options.keep_animations) model.animations.clear();
  model.animations.insert(model.animations.begin(), anim);
  model.buffers[0].uri.clear();
  if (model.asset.generator.empty()) model.asset.generator = "kinemo retarget";

  return WriteGlbFile(model, path);
}


Status WriteCharacterAnimation(const Rig& rig, const motion::Clip& clip, const std::string& path, bool vrma,
                               const FaceMap* face_map, const FaceAnimation* face) {
  if (vrma) return WriteVrmAnimation(rig, clip, path, {.face_map = face_map, .face = face});
  return WriteAnimatedGlb(rig, clip, path, {.face_map = face_map, .face = face});
}

std::string_view VrmHumanBoneName(Role role) {
  static const std::vector<std::string> kNames = [] {
    std::vector<std::string> names(kNumRoles);
    const char* core[kNumCoreRoles] = {"hips", "spine", "chest", "upperChest", "neck", "head", "jaw"};
    for (int r = 0; r < kNumCoreRoles; ++r) names[static_cast<size_t>(r)] = core[r];
    const char* limbs[] = {"Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"};
    const char* fingers[] = {"Thumb", "Index", "Middle", "Ring", "Little"};
    const char* thumb[] = {"Metacarpal", "Proximal", "Distal"};
    const char* finger[] = {"Proximal", "Intermediate", "Distal"};
    for (int side = 0; side < 2; ++side) {
      const std::string prefix = side == 0 ? "left" : "right";
      for (int b = 0; b < roles::kFirstFinger; ++b) names[static_cast<size_t>(roles::Side(side, b))] = prefix + limbs[b];
      for (int f = 0; f < 5; ++f) {
        for (int b = 0; b < 3; ++b) {
          names[static_cast<size_t>(roles::Finger(side, f, b))] = prefix + fingers[f] + (f == 0 ? thumb[b] : finger[b]);
        }
      }
    }
    return names;
  }();
  if (role < 0 || role >= kNumRoles) return {};
  return kNames[static_cast<size_t>(role)];
}

namespace {

// A VRM expression control's name in VRM 1.0 terms and whether it is a
// preset there; nullopt for the look-at presets, which an animation may not
// carry (VRMC_vrm_animation: they belong to lookAt).
std::optional<std::pair<std::string, bool>> Vrm1ExpressionName(const FaceControl& c) {
  static const std::map<std::string, std::string, std::less<>> kFromVrm0 = {
      {"neutral", "neutral"}, {"a", "aa"},          {"i", "ih"},           {"u", "ou"},         {"e", "ee"},
      {"o", "oh"},            {"blink", "blink"},   {"blink_l", "blinkLeft"}, {"blink_r", "blinkRight"},
      {"joy", "happy"},       {"angry", "angry"},   {"sorrow", "sad"},     {"fun", "relaxed"}};
  static const std::set<std::string, std::less<>> kVrm1 = {
      "happy", "angry", "sad", "relaxed", "surprised", "aa", "ih", "ou", "ee", "oh",
      "blink", "blinkLeft", "blinkRight", "neutral"};
  static const std::set<std::string, std::less<>> kLook = {"lookup",   "lookdown", "lookleft", "lookright",
                                                           "lookUp",   "lookDown", "lookLeft", "lookRight"};
  if (kLook.count(c.name)) return std::nullopt;
  if (c.family == "vrm0") {
    if (auto it = kFromVrm0.find(c.name); it != kFromVrm0.end()) return std::make_pair(it->second, true);
    return std::make_pair(c.name, false);
  }
  return std::make_pair(c.name, kVrm1.count(c.name) > 0);
}

}  // namespace

Status WriteVrmAnimation(const Rig& rig, const motion::Clip& clip, const std::string& path,
                         const VrmaWriteOptions& options) {
  const tinygltf::Model* src = rig.gltf ? &rig.gltf->model : nullptr;
  const bool vrm1 = src != nullptr && src->extensions.count("VRMC_vrm") > 0;
  const bool vrm0 = src != nullptr && !vrm1 && src->extensions.count("VRM") > 0;
  if (!vrm0 && !vrm1) {
    return absl::InvalidArgumentError(kinemo::StrCat(
        rig.name, ": not a VRM: a VRM Animation (.vrma) is written from a VRM character (.vrm), whose rest is the T-pose"));
  }
  if (clip.skeleton.num_joints() != rig.skeleton.num_joints() || clip.skeleton.num_channels() != rig.skeleton.num_channels()) {
    return absl::InvalidArgumentError("clip is not on the rig's skeleton");
  }
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  if (clip.num_frames() < 1) return absl::InvalidArgumentError("clip has no frames");
  if ((options.face == nullptr) != (options.face_map == nullptr)) {
    return absl::InvalidArgumentError("WriteVrmAnimation: face and face_map go together");
  }
  const int nf = clip.num_frames();
  const int nj = rig.skeleton.num_joints();
  const int nc = options.face_map ? static_cast<int>(options.face_map->controls().size()) : 0;
  if (options.face != nullptr &&
      (options.face->num_frames != nf || options.face->control_weights.size() != static_cast<size_t>(nf) * nc)) {
    return absl::InvalidArgumentError("WriteVrmAnimation: the face animation does not match the clip");
  }

  // The humanoid bones, parents before children (joint order), each with
  // the nearest ancestor joint that is a bone as its parent bone.
  struct Bone {
    int joint;
    std::string name;
    int parent = -1;  // index into bones
  };
  std::vector<Bone> bones;
  for (Role r = 0; r < kNumRoles; ++r) {
    const int j = rig.roles.joint[static_cast<size_t>(r)];
    if (j >= 0 && !VrmHumanBoneName(r).empty()) bones.push_back({j, std::string(VrmHumanBoneName(r))});
  }
  std::sort(bones.begin(), bones.end(), [](const Bone& a, const Bone& b) { return a.joint < b.joint; });
  std::vector<int> bone_of(static_cast<size_t>(nj), -1);
  for (size_t b = 0; b < bones.size(); ++b) bone_of[static_cast<size_t>(bones[b].joint)] = static_cast<int>(b);
  const int hips = rig.roles.joint[roles::kHips];
  if (hips < 0) return absl::InvalidArgumentError(kinemo::StrCat(rig.name, ": the humanoid has no hips"));
  for (Bone& bone : bones) {
    for (int a = rig.skeleton.joint(bone.joint).parent; a >= 0; a = rig.skeleton.joint(a).parent) {
      if (bone_of[static_cast<size_t>(a)] >= 0) {
        bone.parent = bone_of[static_cast<size_t>(a)];
        break;
      }
    }
    if (bone.parent < 0 && bone.joint != hips) {
      return absl::InvalidArgumentError(
          kinemo::StrCat(rig.name, ": humanoid bone ", bone.name, " is not below the hips"));
    }
  }

  // VRM 1.0's model space: +Z forward, +Y up, metres. VRM 0.x faces -Z.
  Eigen::Matrix3d turn = Eigen::Matrix3d::Identity();
  if (vrm0) turn.diagonal() << -1, 1, -1;
  const double scale = rig.meters_per_unit;
  const std::vector<Eigen::Vector3d> rest = rig.RestPositions();

  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "kinemo";
  tinygltf::Scene scene;
  for (size_t b = 0; b < bones.size(); ++b) {
    tinygltf::Node node;
    node.name = bones[b].name;
    const Eigen::Vector3d& p = rest[static_cast<size_t>(bones[b].joint)];
    const Eigen::Vector3d t =
        turn * (bones[b].parent < 0 ? p : Eigen::Vector3d(p - rest[static_cast<size_t>(bones[bones[b].parent].joint)])) *
        scale;
    node.translation = {t.x(), t.y(), t.z()};
    model.nodes.push_back(node);
    if (bones[b].parent >= 0) {
      model.nodes[static_cast<size_t>(bones[b].parent)].children.push_back(static_cast<int>(b));
    } else {
      scene.nodes.push_back(static_cast<int>(b));
    }
  }

  // Per frame, per bone: its world rotation (the rig's rest has identity
  // rotations, so this is the turn from the T-pose), in VRM 1.0's space,
  // relative to its parent bone's.
  std::vector<std::vector<float>> rotations(bones.size());
  std::vector<float> hips_path;
  std::vector<Eigen::Vector3d> wp(static_cast<size_t>(nj));
  std::vector<Eigen::Matrix3d> wr(static_cast<size_t>(nj));
  std::vector<Eigen::Matrix3d> turned(bones.size());
  for (int f = 0; f < nf; ++f) {
    KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(rig.skeleton, clip.frame(f), wp, wr));
    for (size_t b = 0; b < bones.size(); ++b) {
      turned[b] = turn * wr[static_cast<size_t>(bones[b].joint)] * turn.transpose();
      const Eigen::Matrix3d local =
          bones[b].parent < 0 ? turned[b] : Eigen::Matrix3d(turned[static_cast<size_t>(bones[b].parent)].transpose() * turned[b]);
      AppendQuaternion(local, rotations[b]);
    }
    const Eigen::Vector3d h = turn * wp[static_cast<size_t>(hips)] * scale;
    hips_path.insert(hips_path.end(), {static_cast<float>(h.x()), static_cast<float>(h.y()), static_cast<float>(h.z())});
  }
  std::vector<float> times(static_cast<size_t>(nf));
  for (int f = 0; f < nf; ++f) times[static_cast<size_t>(f)] = static_cast<float>(f * clip.frame_time_s);
  tinygltf::Animation anim;
  anim.name = options.animation_name;
  const int input = AppendFloatAccessor(model, times, TINYGLTF_TYPE_SCALAR, nf);
  for (size_t b = 0; b < bones.size(); ++b) {
    AddChannel(model, anim, input, nf, static_cast<int>(b), "rotation", rotations[b], TINYGLTF_TYPE_VEC4);
  }
  AddChannel(model, anim, input, nf, bone_of[static_cast<size_t>(hips)], "translation", hips_path, TINYGLTF_TYPE_VEC3);

  tinygltf::Value::Object human_bones;
  for (size_t b = 0; b < bones.size(); ++b) {
    human_bones[bones[b].name] = tinygltf::Value(tinygltf::Value::Object{{"node", tinygltf::Value(static_cast<int>(b))}});
  }
  tinygltf::Value::Object ext{
      {"specVersion", tinygltf::Value(std::string("1.0"))},
      {"humanoid", tinygltf::Value(tinygltf::Value::Object{{"humanBones", tinygltf::Value(std::move(human_bones))}})}};

  // The face: one node per driven expression, its translation x the weight.
  if (options.face != nullptr) {
    tinygltf::Value::Object preset, custom;
    for (int c = 0; c < nc; ++c) {
      const FaceControl& control = options.face_map->controls()[static_cast<size_t>(c)];
      if (control.kind != FaceControlKind::kVrmExpression || !control.driven()) continue;
      const auto name = Vrm1ExpressionName(control);
      if (!name) continue;
      tinygltf::Value::Object& group = name->second ? preset : custom;
      if (group.count(name->first)) continue;
      tinygltf::Node node;
      node.name = kinemo::StrCat("expression:", name->first);
      model.nodes.push_back(node);
      const int index = static_cast<int>(model.nodes.size()) - 1;
      scene.nodes.push_back(index);
      std::vector<float> path_x(static_cast<size_t>(nf) * 3, 0.0f);
      for (int f = 0; f < nf; ++f) {
        path_x[static_cast<size_t>(f) * 3] = options.face->control_weights[static_cast<size_t>(f) * nc + c];
      }
      AddChannel(model, anim, input, nf, index, "translation", path_x, TINYGLTF_TYPE_VEC3);
      group[name->first] = tinygltf::Value(tinygltf::Value::Object{{"node", tinygltf::Value(index)}});
    }
    tinygltf::Value::Object expressions;
    if (!preset.empty()) expressions["preset"] = tinygltf::Value(std::move(preset));
    if (!custom.empty()) expressions["custom"] = tinygltf::Value(std::move(custom));
    if (!expressions.empty()) ext["expressions"] = tinygltf::Value(std::move(expressions));
  }
  model.animations.push_back(std::move(anim));
  model.scenes.push_back(std::move(scene));
  model.defaultScene = 0;
  model.extensions["VRMC_vrm_animation"] = tinygltf::Value(std::move(ext));
  model.extensionsUsed.push_back("VRMC_vrm_animation");
  return WriteGlbFile(model, path);
}

}  // namespace kinemo::retarget

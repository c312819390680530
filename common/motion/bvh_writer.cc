#include <unistd.h>

#include <charconv>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <system_error>
#include <vector>

#include "common/motion/bvh.h"

namespace kinemo::motion {
namespace {

class NumberWriter {
 public:
  explicit NumberWriter(int significant_digits) : digits_(significant_digits) {}

  void Append(double v, std::string* out) const {
    char buf[64];
    std::to_chars_result r =
        digits_ > 0 ? std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::general, digits_)
                    : std::to_chars(buf, buf + sizeof(buf), v);
    out->append(buf, r.ptr);
  }

 private:
  int digits_;
};

void AppendIndent(int depth, std::string_view indent, std::string* out) {
  for (int i = 0; i < depth; ++i) out->append(indent);
}

// Appends joint j and its subtree; `order` receives joints in file order.
void AppendJoint(const Skeleton& sk, int j, int depth, const BvhWriteOptions& options,
                 const NumberWriter& num, std::string* out, std::vector<int>* order) {
  const Joint& joint = sk.joint(j);
  order->push_back(j);
  AppendIndent(depth, options.indent, out);
  out->append(kinemo::StrCat(joint.parent < 0 ? "ROOT " : "JOINT ", joint.name, "\n"));
  AppendIndent(depth, options.indent, out);
  out->append("{\n");
  AppendIndent(depth + 1, options.indent, out);
  out->append("OFFSET");
  for (int a = 0; a < 3; ++a) {
    out->push_back(' ');
    num.Append(joint.offset[a], out);
  }
  out->push_back('\n');
  AppendIndent(depth + 1, options.indent, out);
  out->append(kinemo::StrCat("CHANNELS ", joint.channels.size()));
  for (ChannelType t : joint.channels) out->append(kinemo::StrCat(" ", ChannelTypeName(t)));
  out->push_back('\n');
  for (int child : sk.children(j)) AppendJoint(sk, child, depth + 1, options, num, out, order);
  if (joint.end_site) {
    AppendIndent(depth + 1, options.indent, out);
    out->append("End Site\n");
    AppendIndent(depth + 1, options.indent, out);
    out->append("{\n");
    AppendIndent(depth + 2, options.indent, out);
    out->append("OFFSET");
    for (int a = 0; a < 3; ++a) {
      out->push_back(' ');
      num.Append((*joint.end_site)[a], out);
    }
    out->push_back('\n');
    AppendIndent(depth + 1, options.indent, out);
    out->append("}\n");
  }
  AppendIndent(depth, options.indent, out);
  out->append("}\n");
}

}  // namespace

StatusOr<BvhTextWriter> BvhTextWriter::Create(const Clip& clip, const BvhWriteOptions& options) {
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  if (clip.skeleton.num_joints() == 0) return InvalidField("clip.skeleton", "has no joints");
  if (options.significant_digits < 0 || options.significant_digits > 17) {
    return InvalidField("significant_digits", options.significant_digits, " must be 0..17");
  }
  BvhTextWriter w(&clip, options.significant_digits);
  const NumberWriter num(options.significant_digits);
  const Skeleton& sk = clip.skeleton;
  std::string& out = w.header_;
  out.reserve(static_cast<size_t>(sk.num_joints()) * 96 + 64);
  out.append("HIERARCHY\n");
  std::vector<int> order;
  order.reserve(static_cast<size_t>(sk.num_joints()));
  for (int j = 0; j < sk.num_joints(); ++j) {
    if (sk.joint(j).parent < 0) AppendJoint(sk, j, 0, options, num, &out, &order);
  }
  // Channel columns in file order (joint order in the file may differ from
  // the skeleton's order for skeletons built in code).
  w.columns_.reserve(static_cast<size_t>(sk.num_channels()));
  for (int j : order) {
    const Joint& joint = sk.joint(j);
    for (int c = 0; c < joint.num_channels(); ++c) w.columns_.push_back(joint.first_channel + c);
  }
  out.append(kinemo::StrCat("MOTION\nFrames: ", clip.num_frames(), "\nFrame Time: "));
  num.Append(clip.frame_time_s, &out);
  out.push_back('\n');
  return w;
}

void BvhTextWriter::AppendFrame(int f, std::string* out) const {
  const NumberWriter num(significant_digits_);
  const double* row = clip_->frames.data() + static_cast<Eigen::Index>(f) * clip_->frames.cols();
  for (size_t k = 0; k < columns_.size(); ++k) {
    if (k > 0) out->push_back(' ');
    num.Append(row[columns_[k]], out);
  }
  out->push_back('\n');
}

bool BvhTextWriter::Next(std::size_t max_bytes, std::string* out) {
  if (done()) return false;
  const std::size_t start = out->size();
  if (!header_written_) {
    out->append(header_);
    header_written_ = true;
    header_.clear();
    header_.shrink_to_fit();
  }
  while (next_frame_ < clip_->num_frames() && out->size() - start < max_bytes) AppendFrame(next_frame_++, out);
  return true;
}

StatusOr<std::string> WriteBvh(const Clip& clip, const BvhWriteOptions& options) {
  KINEMO_ASSIGN_OR_RETURN(BvhTextWriter writer, BvhTextWriter::Create(clip, options));
  std::string out;
  const size_t per_value =
      options.significant_digits > 0 ? static_cast<size_t>(options.significant_digits) + 7 : 12;
  out.reserve(static_cast<size_t>(clip.skeleton.num_joints()) * 96 +
              static_cast<size_t>(clip.frames.size()) * per_value + 64);
  while (writer.Next(std::numeric_limits<std::size_t>::max(), &out)) {
  }
  return out;
}

Status WriteBvhFile(const Clip& clip, const std::string& path, const BvhWriteOptions& options) {
  KINEMO_ASSIGN_OR_RETURN(const std::string text, WriteBvh(clip, options));
  const std::string tmp = kinemo::StrCat(path, ".tmp.", ::getpid());
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) return absl::UnavailableError(kinemo::StrCat(path, ": cannot open for writing"));
    f.write(text.data(), static_cast<std::streamsize>(text.size()));
    f.flush();
    if (!f) {
      std::error_code ignored;
      std::filesystem::remove(tmp, ignored);
      return absl::UnavailableError(kinemo::StrCat(path, ": write failed"));
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    return absl::UnavailableError(
        kinemo::StrCat(path, ": cannot rename temporary file: ", ec.message()));
  }
  return absl::OkStatus();
}

}  // namespace kinemo::motion

// BVH reader: a hand-written tokenizer over the whole file held in memory.
// The hierarchy is small and parsed token by token; the motion section is
// parsed line by line with std::from_chars straight into the frame matrix.

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/motion/bvh.h"
#include "common/motion/text_util.h"

namespace kinemo::motion {
namespace {

constexpr int kMaxChannelsPerJoint = 6;
constexpr size_t kMaxNameLength = 1024;
constexpr double kMaxFrameTimeS = 3600.0;

inline bool IsLineSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}
inline bool IsSpace(char c) { return IsLineSpace(c) || c == '\n'; }

// Quotes a token for an error message, shortened and with control bytes
// escaped so that binary garbage cannot mangle the message.
std::string Quote(std::string_view s) {
  constexpr size_t kMax = 40;
  std::string out = "'";
  for (size_t i = 0; i < s.size() && i < kMax; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f) {
      out.push_back(static_cast<char>(c));
    } else {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\x%02x", c);
      out += buf;
    }
  }
  if (s.size() > kMax) out += "...";
  out += "'";
  return out;
}

// Parses a double occupying exactly [first, last). Accepts a leading '+'.
bool ParseDouble(const char* first, const char* last, double* out) {
  if (first < last && *first == '+') ++first;
  if (first == last) return false;
  const auto r = std::from_chars(first, last, *out);
  return r.ec == std::errc() && r.ptr == last;
}

class BvhParser {
 public:
  BvhParser(std::string_view text, std::string_view name, const BvhReadOptions& options)
      : begin_(text.data()),
        p_(text.data()),
        end_(text.data() + text.size()),
        name_(name),
        options_(options) {}

  StatusOr<Clip> Parse();

 private:
  template <typename... Args>
  Status Error(int line, const Args&... parts) const {
    return absl::InvalidArgumentError(kinemo::StrCat(name_, ":", line, ": ", parts...));
  }

  // Skips whitespace including newlines, counting lines.
  void SkipSpace() {
    while (p_ < end_ && IsSpace(*p_)) {
      if (*p_ == '\n') ++line_;
      ++p_;
    }
  }
  // The next whitespace-delimited token (empty at end of file); its line is
  // left in token_line_.
  std::string_view NextToken() {
    SkipSpace();
    token_line_ = line_;
    const char* start = p_;
    while (p_ < end_ && !IsSpace(*p_)) ++p_;
    return {start, static_cast<size_t>(p_ - start)};
  }
  // The rest of the current line, trimmed (the newline is not consumed).
  std::string_view RestOfLine() {
    while (p_ < end_ && IsLineSpace(*p_)) ++p_;
    const char* start = p_;
    while (p_ < end_ && *p_ != '\n') ++p_;
    std::string_view s(start, static_cast<size_t>(p_ - start));
    while (!s.empty() && IsLineSpace(s.back())) s.remove_suffix(1);
    return s;
  }

  Status ExpectToken(std::string_view expected, std::string_view context);
  Status ReadNumber(std::string_view what, double* out);
  Status ReadVector(std::string_view what, Eigen::Vector3d* out);
  Status ParseHierarchy();
  Status ParseJointHeader(bool is_root);
  Status ParseEndSite();
  Status ParseChannels();
  Status ParseMotionHeader();
  Status ParseFrames();
  void DetectPositionChannelMode();

  const char* begin_;
  const char* p_;
  const char* end_;
  std::string_view name_;
  const BvhReadOptions& options_;
  int line_ = 1;
  int token_line_ = 1;

  struct OpenJoint {
    int index;
    int line;
    bool has_offset;
  };
  std::vector<Joint> joints_;
  std::vector<OpenJoint> stack_;
  std::unordered_map<std::string, int> joint_lines_;
  int num_channels_ = 0;
  int64_t num_frames_ = 0;
  int frames_line_ = 0;
  double frame_time_s_ = 0.0;
  FrameMatrix frames_;
};

Status BvhParser::ExpectToken(std::string_view expected, std::string_view context) {
  const std::string_view tok = NextToken();
  if (tok.empty()) {
    return Error(token_line_, "file ends ", context, ": expected ", Quote(expected));
  }
  if (!internal::EqualsIgnoreCase(tok, expected)) {
    return Error(token_line_, "expected ", Quote(expected), " ", context, ", got ", Quote(tok));
  }
  return absl::OkStatus();
}

Status BvhParser::ReadNumber(std::string_view what, double* out) {
  const std::string_view tok = NextToken();
  if (tok.empty()) return Error(token_line_, "file ends while reading ", what);
  if (!ParseDouble(tok.data(), tok.data() + tok.size(), out)) {
    return Error(token_line_, what, ": expected a number, got ", Quote(tok));
  }
  if (!std::isfinite(*out)) return Error(token_line_, what, ": ", Quote(tok), " is not finite");
  return absl::OkStatus();
}

Status BvhParser::ReadVector(std::string_view what, Eigen::Vector3d* out) {
  for (int a = 0; a < 3; ++a) {
    KINEMO_RETURN_IF_ERROR(ReadNumber(what, &(*out)[a]));
  }
  return absl::OkStatus();
}

Status BvhParser::ParseJointHeader(bool is_root) {
  const int line = token_line_;
  const std::string_view keyword = is_root ? "ROOT" : "JOINT";
  if (is_root && !stack_.empty()) {
    return Error(line, "ROOT inside joint '",
                 joints_[static_cast<size_t>(stack_.back().index)].name, "' (missing '}'?)");
  }
  if (!is_root && stack_.empty()) return Error(line, "JOINT outside any ROOT block");
  if (static_cast<int>(joints_.size()) >= options_.max_joints) {
    return Error(line, "more than max_joints=", options_.max_joints, " joints");
  }
  if (static_cast<int>(stack_.size()) >= options_.max_nesting_depth) {
    return Error(line, "joints nested deeper than max_nesting_depth=", options_.max_nesting_depth);
  }
  std::string_view name = RestOfLine();
  bool brace_on_line = false;
  if (!name.empty() && name.back() == '{') {
    brace_on_line = true;
    name.remove_suffix(1);
    while (!name.empty() && IsLineSpace(name.back())) name.remove_suffix(1);
  }
  if (name.empty()) return Error(line, keyword, " without a name");
  if (name.size() > kMaxNameLength) {
    return Error(line, keyword, " name longer than ", kMaxNameLength, " characters");
  }
  for (char c : name) {
    if (static_cast<unsigned char>(c) < 0x20 || c == '{' || c == '}') {
      return Error(line, keyword, " name ", Quote(name), " contains an invalid character");
    }
  }
  auto [it, inserted] = joint_lines_.emplace(std::string(name), line);
  if (!inserted) {
    return Error(line, "duplicate joint name ", Quote(name), " (first at line ", it->second, ")");
  }
  if (!brace_on_line)
    KINEMO_RETURN_IF_ERROR(ExpectToken("{", kinemo::StrCat("after ", keyword, " ", name)));
  Joint j;
  j.name = std::string(name);
  j.parent = stack_.empty() ? -1 : stack_.back().index;
  joints_.push_back(std::move(j));
  stack_.push_back({static_cast<int>(joints_.size()) - 1, line, false});
  return absl::OkStatus();
}

Status BvhParser::ParseEndSite() {
  const int line = token_line_;
  if (stack_.empty()) return Error(line, "End Site outside any joint");
  Joint& parent = joints_[static_cast<size_t>(stack_.back().index)];
  KINEMO_RETURN_IF_ERROR(ExpectToken("Site", "after 'End'"));
  if (parent.end_site.has_value()) {
    return Error(line, "joint '", parent.name, "' has a second End Site");
  }
  KINEMO_RETURN_IF_ERROR(ExpectToken("{", "after End Site"));
  KINEMO_RETURN_IF_ERROR(ExpectToken("OFFSET", "in End Site"));
  Eigen::Vector3d offset;
  KINEMO_RETURN_IF_ERROR(ReadVector("End Site OFFSET", &offset));
  KINEMO_RETURN_IF_ERROR(ExpectToken("}", "to close End Site"));
  parent.end_site = offset;
  return absl::OkStatus();
}

Status BvhParser::ParseChannels() {
  const int line = token_line_;
  if (stack_.empty()) return Error(line, "CHANNELS outside any joint");
  Joint& j = joints_[static_cast<size_t>(stack_.back().index)];
  if (!j.channels.empty()) return Error(line, "second CHANNELS line for joint '", j.name, "'");
  const std::string_view tok = NextToken();
  if (tok.empty()) return Error(token_line_, "file ends after CHANNELS");
  int64_t n = 0;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), n);
  if (r.ec != std::errc() || r.ptr != tok.data() + tok.size()) {
    return Error(token_line_, "CHANNELS: expected a channel count, got ", Quote(tok));
  }
  if (n < 0 || n > kMaxChannelsPerJoint) {
    return Error(token_line_, "CHANNELS ", tok, ": a joint has 0..", kMaxChannelsPerJoint,
                 " channels");
  }
  for (int64_t c = 0; c < n; ++c) {
    const std::string_view name = NextToken();
    if (name.empty()) return Error(token_line_, "file ends in CHANNELS list");
    const std::optional<ChannelType> type = ParseChannelType(name);
    if (!type) {
      return Error(token_line_, "CHANNELS: unknown channel ", Quote(name),
                   " (expected X/Y/Z position/rotation)");
    }
    int rotations = IsRotation(*type) ? 1 : 0;
    for (ChannelType t : j.channels) {
      if (t == *type && IsPosition(t)) {
        return Error(token_line_, "CHANNELS: ", ChannelTypeName(t), " listed twice");
      }
      rotations += IsRotation(t) ? 1 : 0;
    }
    if (rotations > 3) return Error(token_line_, "CHANNELS: more than 3 rotation channels");
    j.channels.push_back(*type);
  }
  num_channels_ += static_cast<int>(n);
  return absl::OkStatus();
}

Status BvhParser::ParseHierarchy() {
  // Skip a UTF-8 byte order mark.
  if (end_ - p_ >= 3 && static_cast<unsigned char>(p_[0]) == 0xEF &&
      static_cast<unsigned char>(p_[1]) == 0xBB && static_cast<unsigned char>(p_[2]) == 0xBF) {
    p_ += 3;
  }
  SkipSpace();
  if (p_ == end_) return Error(line_, "empty file (expected HIERARCHY)");
  KINEMO_RETURN_IF_ERROR(ExpectToken("HIERARCHY", "at the start of the file"));
  while (true) {
    const std::string_view tok = NextToken();
    if (tok.empty()) {
      if (!stack_.empty()) {
        const OpenJoint& open = stack_.back();
        return Error(token_line_, "file ends inside joint '",
                     joints_[static_cast<size_t>(open.index)].name, "' opened at line ", open.line,
                     " (", stack_.size(), " unclosed '{')");
      }
      if (joints_.empty()) return Error(token_line_, "file ends before any ROOT");
      return Error(token_line_, "missing MOTION section");
    }
    if (tok == "ROOT" || tok == "JOINT") {
      KINEMO_RETURN_IF_ERROR(ParseJointHeader(tok == "ROOT"));
    } else if (internal::EqualsIgnoreCase(tok, "End")) {
      KINEMO_RETURN_IF_ERROR(ParseEndSite());
    } else if (tok == "OFFSET") {
      if (stack_.empty()) return Error(token_line_, "OFFSET outside any joint");
      OpenJoint& open = stack_.back();
      if (open.has_offset)
        return Error(token_line_, "second OFFSET for joint '",
                     joints_[static_cast<size_t>(open.index)].name, "'");
      KINEMO_RETURN_IF_ERROR(
          ReadVector("OFFSET", &joints_[static_cast<size_t>(open.index)].offset));
      open.has_offset = true;
    } else if (tok == "CHANNELS") {
      KINEMO_RETURN_IF_ERROR(ParseChannels());
    } else if (tok == "}") {
      if (stack_.empty()) return Error(token_line_, "unbalanced '}' (no joint is open)");
      if (!stack_.back().has_offset) {
        return Error(token_line_, "joint '", joints_[static_cast<size_t>(stack_.back().index)].name,
                     "' (line ", stack_.back().line, ") has no OFFSET");
      }
      stack_.pop_back();
    } else if (tok == "MOTION") {
      if (!stack_.empty()) {
        return Error(token_line_, "MOTION inside joint '",
                     joints_[static_cast<size_t>(stack_.back().index)].name, "' opened at line ",
                     stack_.back().line, " (unbalanced braces)");
      }
      if (joints_.empty()) return Error(token_line_, "MOTION before any ROOT");
      return absl::OkStatus();
    } else if (tok == "{") {
      return Error(token_line_, "unexpected '{' (unbalanced braces)");
    } else {
      return Error(token_line_, "unexpected token ", Quote(tok), " in HIERARCHY");
    }
  }
}

Status BvhParser::ParseMotionHeader() {
  // "Frames:" N   (also tolerates "Frames :" )
  std::string_view tok = NextToken();
  frames_line_ = token_line_;
  if (tok.empty()) return Error(token_line_, "file ends after MOTION (expected Frames:)");
  if (internal::EqualsIgnoreCase(tok, "Frames")) {
    KINEMO_RETURN_IF_ERROR(ExpectToken(":", "after Frames"));
  } else if (!internal::EqualsIgnoreCase(tok, "Frames:")) {
    return Error(token_line_, "expected 'Frames:' after MOTION, got ", Quote(tok));
  }
  tok = NextToken();
  if (tok.empty()) return Error(token_line_, "file ends after Frames:");
  const char* first = tok.data();
  const char* last = tok.data() + tok.size();
  if (*first == '+') ++first;
  const auto r = std::from_chars(first, last, num_frames_);
  if (r.ec == std::errc::result_out_of_range) {
    return Error(token_line_, "Frames: ", Quote(tok), " exceeds max_frames=", options_.max_frames);
  }
  if (r.ec != std::errc() || r.ptr != last) {
    return Error(token_line_, "Frames: expected a frame count, got ", Quote(tok));
  }
  if (num_frames_ < 0) return Error(token_line_, "Frames: ", num_frames_, " is negative");
  if (num_frames_ > options_.max_frames) {
    return Error(token_line_, "Frames: ", num_frames_, " exceeds max_frames=", options_.max_frames);
  }
  // "Frame Time:" t
  tok = NextToken();
  if (tok.empty()) return Error(token_line_, "file ends after Frames: (expected Frame Time:)");
  if (!internal::EqualsIgnoreCase(tok, "Frame")) {
    return Error(token_line_, "expected 'Frame Time:', got ", Quote(tok));
  }
  tok = NextToken();
  if (internal::EqualsIgnoreCase(tok, "Time")) {
    KINEMO_RETURN_IF_ERROR(ExpectToken(":", "after Frame Time"));
  } else if (!internal::EqualsIgnoreCase(tok, "Time:")) {
    return Error(token_line_, "expected 'Frame Time:', got 'Frame ", Quote(tok), "'");
  }
  tok = NextToken();
  const int time_line = token_line_;
  if (tok.empty()) return Error(time_line, "file ends after Frame Time:");
  if (!ParseDouble(tok.data(), tok.data() + tok.size(), &frame_time_s_)) {
    return Error(time_line, "Frame Time: expected a number, got ", Quote(tok));
  }
  if (!(frame_time_s_ > 0.0) || !(frame_time_s_ <= kMaxFrameTimeS)) {
    return Error(time_line, "Frame Time: ", Quote(tok), " must be in (0, ", kMaxFrameTimeS, "] s");
  }
  // Size checks before allocating anything.
  const int64_t values = num_frames_ * num_channels_;  // both bounded: no overflow
  if (values > options_.max_values) {
    return Error(frames_line_, "Frames: ", num_frames_, " × ", num_channels_,
                 " channels exceeds max_values=", options_.max_values);
  }
  // The rest of the Frame Time line must be empty.
  if (!RestOfLine().empty()) return Error(time_line, "unexpected text after Frame Time value");
  return absl::OkStatus();
}

Status BvhParser::ParseFrames() {
  // Allocate no more rows than the rest of the file can hold (every value
  // takes at least one character and one separator), so that an absurd
  // Frames: count in a short file costs nothing; grow if ever needed.
  const int64_t remaining = end_ - p_;
  const int64_t row_bytes = 2 * static_cast<int64_t>(std::max(num_channels_, 1));
  int64_t capacity = std::min<int64_t>(num_frames_, remaining / row_bytes + 1);
  frames_.resize(capacity, num_channels_);
  double* out = frames_.data();
  for (int64_t f = 0; f < num_frames_; ++f) {
    if (f == capacity) {
      capacity = std::min<int64_t>(num_frames_, 2 * capacity + 1);
      frames_.conservativeResize(capacity, Eigen::NoChange);
      out = frames_.data() + f * num_channels_;
    }
    // Skip blank lines (and the end of the previous line).
    SkipSpace();
    if (p_ == end_) {
      return Error(line_, "file ends after ", f, " of ", num_frames_,
                   " frames declared by Frames: at line ", frames_line_);
    }
    for (int c = 0; c < num_channels_; ++c) {
      while (p_ < end_ && IsLineSpace(*p_)) ++p_;
      if (p_ == end_ || *p_ == '\n') {
        return Error(line_, "frame ", f, " has ", c, " values, expected ", num_channels_,
                     p_ == end_ ? " (file ends)" : "");
      }
      const char* first = p_;
      if (*first == '+') ++first;
      double v;
      const auto r = std::from_chars(first, end_, v);
      if (r.ec != std::errc() || (r.ptr < end_ && !IsSpace(*r.ptr)) || !std::isfinite(v)) {
        const char* tok_end = p_;
        while (tok_end < end_ && !IsSpace(*tok_end)) ++tok_end;
        return Error(line_, "frame ", f, " value ", c, ": expected a finite number, got ",
                     Quote(std::string_view(p_, static_cast<size_t>(tok_end - p_))));
      }
      *out++ = v;
      p_ = r.ptr;
    }
    while (p_ < end_ && IsLineSpace(*p_)) ++p_;
    if (p_ < end_ && *p_ != '\n') {
      return Error(line_, "frame ", f, " has more than ", num_channels_, " values");
    }
  }
  SkipSpace();
  if (p_ != end_) {
    return Error(line_, "data after the ", num_frames_, " frames declared by Frames: at line ",
                 frames_line_, " (frame count mismatch)");
  }
  return absl::OkStatus();
}

void BvhParser::DetectPositionChannelMode() {
  int column = 0;
  for (Joint& joint : joints_) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    std::array<bool, 3> has_axis = {false, false, false};
    for (std::size_t c = 0; c < joint.channels.size(); ++c, ++column) {
      int axis = -1;
      switch (joint.channels[c]) {
        case ChannelType::kXPosition: axis = 0; break;
        case ChannelType::kYPosition: axis = 1; break;
        case ChannelType::kZPosition: axis = 2; break;
        default: break;
      }
      if (axis < 0 || frames_.rows() == 0) continue;
      has_axis[static_cast<std::size_t>(axis)] = true;
      mean[axis] = frames_.col(column).mean();
    }
    if (!has_axis[0] && !has_axis[1] && !has_axis[2]) continue;
    switch (options_.position_channels) {
      case PositionChannels::kReplace: joint.position_relative_to_offset = false; break;
      case PositionChannels::kAdd: joint.position_relative_to_offset = true; break;
      case PositionChannels::kAuto: {
        // Relative (added to OFFSET) only if, on every axis where the OFFSET
        // is significant, the channels stay nearer 0 than the OFFSET value.
        // One axis is not enough: Bandai's "tired" takes carry a Hips OFFSET
        // of z = -452 with z channels near 0, but y channels near the OFFSET's
        // y (absolute). Exported relative channels hover near 0 on all axes.
        const double largest = joint.offset.cwiseAbs().maxCoeff();
        bool any = false, all_near_zero = true;
        for (int a = 0; a < 3; ++a) {
          const double off = joint.offset[a];
          if (!has_axis[static_cast<std::size_t>(a)] || std::abs(off) <= 1e-6 || std::abs(off) < 0.1 * largest) continue;
          any = true;
          all_near_zero = all_near_zero && std::abs(mean[a] - off) > std::abs(mean[a]);
        }
        joint.position_relative_to_offset = any && all_near_zero;
        break;
      }
    }
  }
}

StatusOr<Clip> BvhParser::Parse() {
  if (static_cast<int64_t>(end_ - begin_) > options_.max_file_bytes) {
    return Error(1, "size ", end_ - begin_,
                 " bytes exceeds max_file_bytes=", options_.max_file_bytes);
  }
  KINEMO_RETURN_IF_ERROR(ParseHierarchy());
  KINEMO_RETURN_IF_ERROR(ParseMotionHeader());
  KINEMO_RETURN_IF_ERROR(ParseFrames());
  DetectPositionChannelMode();
  StatusOr<Skeleton> skeleton = Skeleton::Create(std::move(joints_));
  if (!skeleton.ok()) return Annotate(skeleton.status(), name_);
  Clip clip;
  clip.skeleton = *std::move(skeleton);
  clip.frame_time_s = frame_time_s_;
  clip.frames = std::move(frames_);
  return clip;
}

}  // namespace

StatusOr<Clip> ParseBvh(std::string_view text, std::string_view name,
                        const BvhReadOptions& options) {
  BvhParser parser(text, name, options);
  return parser.Parse();
}

StatusOr<Clip> ReadBvhFile(const std::string& path, const BvhReadOptions& options) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(st)) {
    return absl::NotFoundError(kinemo::StrCat(path, ": cannot open: no such file"));
  }
  if (!std::filesystem::is_regular_file(st)) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": not a regular file"));
  }
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) return absl::UnavailableError(kinemo::StrCat(path, ": cannot stat: ", ec.message()));
  if (size > static_cast<uintmax_t>(options.max_file_bytes)) {
    return absl::InvalidArgumentError(kinemo::StrCat(
        path, ": size ", size, " bytes exceeds max_file_bytes=", options.max_file_bytes));
  }
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) return absl::UnavailableError(kinemo::StrCat(path, ": cannot open for reading"));
  std::string text(static_cast<size_t>(size), '\0');
  const size_t got = size > 0 ? std::fread(text.data(), 1, text.size(), f.get()) : 0;
  if (got != text.size()) {
    return absl::UnavailableError(kinemo::StrCat(path, ": read ", got, " of ", size, " bytes"));
  }
  return ParseBvh(text, path, options);
}

}  // namespace kinemo::motion

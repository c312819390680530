// FBX at the byte level, around assimp (fbx_bytes.h): the structure check
// that runs before assimp's parser sees a file, and the repair of assimp's
// binary FBX output (null records, GlobalSettings).
#include "common/retarget/fbx_bytes.h"

#include <cstring>
#include <vector>

namespace kinemo::retarget {
namespace {

// What assimp's FBX parser trusts, checked first: in a binary FBX every
// record's end offset inside its parent and the file, the properties inside
// their list, every array's element count × size within the limits (assimp
// allocates count × size before inflating an array), nesting at most 64
// deep; in an ASCII FBX every "*N" array count. INVALID_ARGUMENT naming the
// file and the byte offset.
class StructureCheck {
 public:
  StructureCheck(std::string_view bytes, const std::string& name) : b_(bytes), name_(name) {}

  Status Binary() {
    if (b_.size() < 27) return Fail(0, "truncated header");
    version_ = U32(23);
    wide_ = version_ >= 7500;
    uint64_t at = 27;
    // Top-level records up to the null record that ends them.
    for (;;) {
      uint64_t end = 0;
      KINEMO_RETURN_IF_ERROR(Record(at, b_.size(), 0, &end));
      if (end == 0) return absl::OkStatus();  // the null record
      at = end;
    }
  }

  Status Ascii() {
    uint64_t total = 0;
    for (size_t i = b_.find('*'); i != std::string_view::npos; i = b_.find('*', i + 1)) {
      size_t k = i + 1;
      uint64_t n = 0;
      while (k < b_.size() && k < i + 24 && b_[k] >= '0' && b_[k] <= '9') n = n * 10 + static_cast<uint64_t>(b_[k++] - '0');
      if (k == i + 1) continue;
      if (n > kMaxArrayElements) return Fail(i, kinemo::StrCat("array of ", n, " elements (at most ", kMaxArrayElements, ")"));
      total += n;
      if (total > kMaxTotalElements) return Fail(i, "arrays hold too many elements in all");
    }
    return absl::OkStatus();
  }

 private:
  static constexpr uint64_t kMaxArrayElements = uint64_t{1} << 27;  // 1 GiB of doubles
  static constexpr uint64_t kMaxTotalElements = uint64_t{1} << 28;

  Status Fail(uint64_t at, std::string_view what) const {
    return absl::InvalidArgumentError(kinemo::StrCat(name_, ": FBX structure at byte ", at, ": ", what));
  }
  uint32_t U32(uint64_t at) const {
    uint32_t v;
    std::memcpy(&v, b_.data() + at, 4);
    return v;
  }
  uint64_t U64(uint64_t at) const {
    uint64_t v;
    std::memcpy(&v, b_.data() + at, 8);
    return v;
  }

  // One record at `at` inside [.., limit); *end = its end offset (0 for a null record).
  Status Record(uint64_t at, uint64_t limit, int depth, uint64_t* end) {
    if (depth > 64) return Fail(at, "records nest deeper than 64");
    if (++records_ > (uint64_t{1} << 24)) return Fail(at, "more than 16777216 records");
    const uint64_t head = wide_ ? 25 : 13;
    if (at + head > limit) return Fail(at, "truncated record header");
    const uint64_t rec_end = wide_ ? U64(at) : U32(at);
    const uint64_t num_props = wide_ ? U64(at + 8) : U32(at + 4);
    const uint64_t props_len = wide_ ? U64(at + 16) : U32(at + 8);
    const uint64_t name_len = static_cast<unsigned char>(b_[at + head - 1]);
    if (rec_end == 0 && num_props == 0 && props_len == 0 && name_len == 0) {
      *end = 0;
      return absl::OkStatus();
    }
    if (rec_end <= at || rec_end > limit) return Fail(at, kinemo::StrCat("record ends at ", rec_end, ", outside ", at, "..", limit));
    uint64_t p = at + head + name_len;
    if (p > rec_end || props_len > rec_end - p) return Fail(at, "properties run past the record");
    const uint64_t props_end = p + props_len;
    for (uint64_t k = 0; k < num_props; ++k) {
      if (p >= props_end) return Fail(p, "fewer properties than the record says");
      const char type = b_[p++];
      uint64_t size = 0;
      switch (type) {
        case 'C': size = 1; break;
        case 'Y': size = 2; break;
        case 'I': case 'F': size = 4; break;
        case 'D': case 'L': size = 8; break;
        case 'S': case 'R':
          if (p + 4 > props_end) return Fail(p, "truncated string length");
          size = 4 + uint64_t{U32(p)};
          break;
        case 'f': case 'd': case 'l': case 'i': case 'b': {
          if (p + 12 > props_end) return Fail(p, "truncated array header");
          const uint64_t count = U32(p), encoding = U32(p + 4), stored = U32(p + 8);
          const uint64_t elem = (type == 'd' || type == 'l') ? 8 : (type == 'b' ? 1 : 4);
          if (count > kMaxArrayElements) return Fail(p, kinemo::StrCat("array of ", count, " elements (at most ", kMaxArrayElements, ")"));
          elements_ += count;
          if (elements_ > kMaxTotalElements) return Fail(p, "arrays hold too many elements in all");
          if (encoding > 1) return Fail(p, kinemo::StrCat("array encoding ", encoding, " (0 or 1)"));
          if (encoding == 0 && stored != count * elem) return Fail(p, "array's stored length is not count × element size");
          size = 12 + stored;
          break;
        }
        default:
          return Fail(p - 1, kinemo::StrCat("unknown property type ", static_cast<int>(static_cast<unsigned char>(type))));
      }
      if (size > props_end - p) return Fail(p, "property runs past the list");
      p += size;
    }
    // Nested records up to the record's end (a null record ends them).
    while (p < rec_end) {
      uint64_t child_end = 0;
      KINEMO_RETURN_IF_ERROR(Record(p, rec_end, depth + 1, &child_end));
      if (child_end == 0) break;
      p = child_end;
    }
    *end = rec_end;
    return absl::OkStatus();
  }

  std::string_view b_;
  const std::string& name_;
  uint32_t version_ = 0;
  bool wide_ = false;
  uint64_t records_ = 0, elements_ = 0;
};

}  // namespace

Status CheckFbxStructure(std::string_view bytes, const std::string& name) {
  StructureCheck check(bytes, name);
  static constexpr std::string_view kBinary = "Kaydara FBX Binary  ";
  return bytes.substr(0, kBinary.size()) == kBinary ? check.Binary() : check.Ascii();
}

bool HasFbxHeader(std::string_view bytes) {
  static constexpr std::string_view kBinary = "Kaydara FBX Binary  ";
  if (bytes.substr(0, kBinary.size()) == kBinary) return true;
  // ASCII FBX: the header extension comes first (after comments).
  return bytes.substr(0, 4096).find("FBXHeaderExtension") != std::string_view::npos;
}

namespace {

// assimp 5.2's binary FBX writer ends no nested record list with the null
// record the format puts there, and writes fixed GlobalSettings (y up,
// centimetres, 24 frames/s): Blender's importer refuses the first ("failed
// to read nested block sentinel") and believes the second. The exported
// bytes are read back as a record tree (bounded like the reader's check),
// written again with the null records, and GlobalSettings' axes, unit and
// frame rate set to `settings` (name -> integer or double value).
struct FbxRecord {
  std::string name;
  uint64_t num_props = 0;
  std::string props;
  std::vector<FbxRecord> children;
};

class RecordTree {
 public:
  explicit RecordTree(std::string_view b) : b_(b) {}

  StatusOr<std::vector<FbxRecord>> Parse() {
    if (b_.size() < 27) return Bad("truncated header");
    uint32_t version;
    std::memcpy(&version, b_.data() + 23, 4);
    wide_ = version >= 7500;
    head_ = wide_ ? 25 : 13;
    std::vector<FbxRecord> top;
    uint64_t at = 27;
    KINEMO_RETURN_IF_ERROR(List(&at, b_.size(), 0, &top));
    footer_ = at;
    return top;
  }
  bool wide() const { return wide_; }
  uint64_t footer() const { return footer_; }

  // Records from `base` on, each nested list ended by a null record.
  std::string Write(const std::vector<FbxRecord>& records, uint64_t base) const {
    std::string out;
    for (const FbxRecord& r : records) out += WriteOne(r, base + out.size());
    return out;
  }

 private:
  Status Bad(std::string_view what) const {
    return absl::InternalError(kinemo::StrCat("assimp's FBX output: ", what));
  }
  uint64_t Get(uint64_t at, bool wide) const {
    uint64_t v = 0;
    std::memcpy(&v, b_.data() + at, wide ? 8 : 4);
    return v;
  }
  Status List(uint64_t* at, uint64_t limit, int depth, std::vector<FbxRecord>* out) {
    if (depth > 64) return Bad("nested too deep");
    while (*at < limit) {
      if (*at + head_ > limit) return Bad("truncated record");
      const uint64_t end = Get(*at, wide_), num = Get(*at + (wide_ ? 8 : 4), wide_),
                     len = Get(*at + (wide_ ? 16 : 8), wide_);
      const uint64_t name_len = static_cast<unsigned char>(b_[*at + head_ - 1]);
      if (end == 0) {  // a null record ends the list
        *at += head_;
        return absl::OkStatus();
      }
      const uint64_t props = *at + head_ + name_len;
      if (end <= *at || end > limit || props > end || len > end - props) return Bad("record out of bounds");
      FbxRecord r;
      r.name = std::string(b_.substr(*at + head_, name_len));
      r.num_props = num;
      r.props = std::string(b_.substr(props, len));
      uint64_t inner = props + len;
      KINEMO_RETURN_IF_ERROR(List(&inner, end, depth + 1, &r.children));
      out->push_back(std::move(r));
      *at = end;
    }
    return absl::OkStatus();
  }
  std::string WriteOne(const FbxRecord& r, uint64_t base) const {
    std::string body;
    const uint64_t start = base + head_ + r.name.size() + r.props.size();
    if (!r.children.empty()) {
      body = Write(r.children, start);
      body.append(head_, '\0');
    }
    std::string out;
    auto put = [&](uint64_t v) { out.append(reinterpret_cast<const char*>(&v), wide_ ? 8 : 4); };
    put(start + body.size());
    put(r.num_props);
    put(r.props.size());
    out += static_cast<char>(r.name.size());
    out += r.name;
    out += r.props;
    out += body;
    return out;
  }

  std::string_view b_;
  bool wide_ = false;
  uint64_t head_ = 13;
  uint64_t footer_ = 0;
};

// A Properties70 "P" record's value set when its name is in `settings`
// (the last property, an integer 'I' or a double 'D').
void SetProperty(FbxRecord& p, const std::map<std::string, double>& settings) {
  std::string& b = p.props;
  if (b.size() < 5 || b[0] != 'S') return;
  uint32_t len;
  std::memcpy(&len, b.data() + 1, 4);
  if (5 + uint64_t{len} > b.size()) return;
  auto it = settings.find(b.substr(5, len));
  if (it == settings.end()) return;
  // Walk to the last property.
  size_t at = 0, last = std::string::npos;
  while (at < b.size()) {
    last = at;
    const char t = b[at];
    if (t == 'S' || t == 'R') {
      if (at + 5 > b.size()) return;
      std::memcpy(&len, b.data() + at + 1, 4);
      at += 5 + len;
    } else if (t == 'I' || t == 'F') {
      at += 5;
    } else if (t == 'D' || t == 'L') {
      at += 9;
    } else {
      return;
    }
  }
  if (at != b.size()) return;
  if (b[last] == 'I') {
    const int32_t v = static_cast<int32_t>(it->second);
    std::memcpy(b.data() + last + 1, &v, 4);
  } else if (b[last] == 'D') {
    const double v = it->second;
    std::memcpy(b.data() + last + 1, &v, 8);
  }
}

}  // namespace

StatusOr<std::string> FixExportedFbx(std::string_view bytes, const std::map<std::string, double>& settings) {
  static constexpr std::string_view kBinary = "Kaydara FBX Binary  ";
  if (bytes.substr(0, kBinary.size()) != kBinary) return absl::InternalError("assimp's FBX output is not binary FBX");
  RecordTree tree(bytes);
  KINEMO_ASSIGN_OR_RETURN(std::vector<FbxRecord> top, tree.Parse());
  for (FbxRecord& r : top) {
    if (r.name != "GlobalSettings") continue;
    for (FbxRecord& props : r.children) {
      if (props.name != "Properties70") continue;
      for (FbxRecord& p : props.children) SetProperty(p, settings);
    }
  }
  std::string out(bytes.substr(0, 27));
  out += tree.Write(top, 27);
  out.append(tree.wide() ? 25 : 13, '\0');  // the top level's null record
  out += bytes.substr(std::min<uint64_t>(tree.footer(), bytes.size()));
  return out;
}

}  // namespace kinemo::retarget

#include "common/audio/textgrid.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace kinemo::audio {
namespace {

bool EqualsIgnoreCase(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
         });
}

void AppendUtf8(std::string& out, char32_t c) {
  if (c < 0x80) {
    out += static_cast<char>(c);
  } else if (c < 0x800) {
    out += static_cast<char>(0xC0 | (c >> 6));
    out += static_cast<char>(0x80 | (c & 0x3F));
  } else if (c < 0x10000) {
    out += static_cast<char>(0xE0 | (c >> 12));
    out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (c & 0x3F));
  } else {
    out += static_cast<char>(0xF0 | (c >> 18));
    out += static_cast<char>(0x80 | ((c >> 12) & 0x3F));
    out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (c & 0x3F));
  }
}

// UTF-16 (with its byte-order mark) to UTF-8; unpaired surrogates become U+FFFD.
StatusOr<std::string> Utf16ToUtf8(std::string_view bytes, bool big_endian, std::string_view source) {
  if (bytes.size() % 2 != 0) return InvalidField(source, "UTF-16 text with an odd number of bytes");
  std::string out;
  out.reserve(bytes.size() / 2);
  const auto unit = [&](size_t i) -> char32_t {
    const auto b0 = static_cast<unsigned char>(bytes[i]), b1 = static_cast<unsigned char>(bytes[i + 1]);
    return big_endian ? (b0 << 8 | b1) : (b1 << 8 | b0);
  };
  for (size_t i = 2; i + 1 < bytes.size(); i += 2) {
    char32_t c = unit(i);
    if (c >= 0xD800 && c < 0xDC00 && i + 3 < bytes.size()) {
      const char32_t lo = unit(i + 2);
      if (lo >= 0xDC00 && lo < 0xE000) {
        c = 0x10000 + ((c - 0xD800) << 10) + (lo - 0xDC00);
        i += 2;
      } else {
        c = 0xFFFD;
      }
    } else if (c >= 0xD800 && c < 0xE000) {
      c = 0xFFFD;
    }
    AppendUtf8(out, c);
  }
  return out;
}

struct Token {
  enum Kind { kNumber, kString, kFlag } kind;
  double number = 0;
  std::string text;
  int line = 0;
};

// Praat's reading rule: values are numbers, "strings" and <flags>; labels
// (`xmin =`, `item [1]:`, `intervals: size =`) and `!` comments are skipped.
StatusOr<std::vector<Token>> Tokenize(std::string_view s, std::string_view source) {
  std::vector<Token> tokens;
  int line = 1;
  size_t i = 0;
  while (i < s.size()) {
    const char c = s[i];
    if (c == '\n') {
      ++line;
      ++i;
    } else if (c == '"') {
      Token t{Token::kString, 0, {}, line};
      ++i;
      for (;;) {
        if (i >= s.size()) return InvalidField(kinemo::StrCat(source, ":", t.line), "unterminated string");
        if (s[i] == '"') {
          if (i + 1 < s.size() && s[i + 1] == '"') {
            t.text += '"';
            i += 2;
            continue;
          }
          ++i;
          break;
        }
        if (s[i] == '\n') ++line;
        t.text += s[i++];
      }
      tokens.push_back(std::move(t));
    } else if (c == '<') {
      const size_t end = s.find('>', i);
      if (end == std::string_view::npos) return InvalidField(kinemo::StrCat(source, ":", line), "unterminated <flag>");
      tokens.push_back({Token::kFlag, 0, std::string(s.substr(i + 1, end - i - 1)), line});
      i = end + 1;
    } else if (c == '[') {  // `item [1]:` — an index label, not a value
      const size_t end = s.find_first_of("]\n", i);
      i = end == std::string_view::npos ? s.size() : end + (s[end] == ']' ? 1 : 0);
    } else if (c == '!') {  // comment to the end of the line
      const size_t end = s.find('\n', i);
      i = end == std::string_view::npos ? s.size() : end;
    } else if (std::isdigit(static_cast<unsigned char>(c)) ||
               ((c == '-' || c == '+' || c == '.') && i + 1 < s.size() &&
                (std::isdigit(static_cast<unsigned char>(s[i + 1])) || s[i + 1] == '.'))) {
      size_t end = i + 1;
      while (end < s.size() && (std::isalnum(static_cast<unsigned char>(s[end])) || s[end] == '.' ||
                                ((s[end] == '-' || s[end] == '+') && (s[end - 1] == 'e' || s[end - 1] == 'E'))))
        ++end;
      const std::string text(s.substr(i, end - i));
      char* stop = nullptr;
      errno = 0;
      const double v = std::strtod(text.c_str(), &stop);
      if (stop != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v))
        return InvalidField(kinemo::StrCat(source, ":", line), "'", text, "' is not a finite number");
      tokens.push_back({Token::kNumber, v, text, line});
      i = end;
    } else if (std::isalpha(static_cast<unsigned char>(c)) || c == '_') {
      while (i < s.size() && (std::isalnum(static_cast<unsigned char>(s[i])) || s[i] == '_' || s[i] == '?')) ++i;
    } else {
      ++i;  // '=', ':', white space, '?'
    }
  }
  return tokens;
}

class Reader {
 public:
  Reader(const std::vector<Token>& tokens, std::string_view source) : tokens_(tokens), source_(source) {}

  StatusOr<double> Number(std::string_view field) {
    KINEMO_ASSIGN_OR_RETURN(const Token* t, Next(field));
    if (t->kind != Token::kNumber) return Error(*t, field, "expected a number, got '", t->text, "'");
    return t->number;
  }
  StatusOr<size_t> Count(std::string_view field) {
    KINEMO_ASSIGN_OR_RETURN(const Token* t, Next(field));
    if (t->kind != Token::kNumber || t->number < 0 || t->number != std::floor(t->number))
      return Error(*t, field, "expected a count, got '", t->text, "'");
    // Each item takes at least two more values: a count beyond that is a lie.
    if (t->number > static_cast<double>(tokens_.size() - pos_))
      return Error(*t, field, t->text, " items announced, the file has too few values left");
    return static_cast<size_t>(t->number);
  }
  StatusOr<std::string> String(std::string_view field) {
    KINEMO_ASSIGN_OR_RETURN(const Token* t, Next(field));
    if (t->kind != Token::kString) return Error(*t, field, "expected a \"string\", got '", t->text, "'");
    return t->text;
  }
  StatusOr<std::string> Flag(std::string_view field) {
    KINEMO_ASSIGN_OR_RETURN(const Token* t, Next(field));
    if (t->kind != Token::kFlag) return Error(*t, field, "expected <exists> or <absent>");
    return t->text;
  }
  int line() const { return pos_ < tokens_.size() ? tokens_[pos_].line : (tokens_.empty() ? 1 : tokens_.back().line); }

 private:
  StatusOr<const Token*> Next(std::string_view field) {
    if (pos_ >= tokens_.size())
      return InvalidField(kinemo::StrCat(source_, ":", line()), field, ": the file ends early");
    return &tokens_[pos_++];
  }
  template <typename... Args>
  Status Error(const Token& t, std::string_view field, const Args&... parts) {
    return InvalidField(kinemo::StrCat(source_, ":", t.line), field, ": ", parts...);
  }

  const std::vector<Token>& tokens_;
  std::string_view source_;
  size_t pos_ = 0;
};

std::string_view Trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

}  // namespace

const TextGridTier* TextGrid::FindTier(std::string_view name) const {
  for (const auto& t : tiers)
    if (EqualsIgnoreCase(t.name, name)) return &t;
  return nullptr;
}

StatusOr<TextGrid> ParseTextGrid(std::string_view bytes, std::string_view source) {
  if (bytes.size() > kMaxTextGridBytes) return InvalidField(source, "larger than ", kMaxTextGridBytes >> 20, " MiB");
  std::string utf8;
  if (bytes.size() >= 2 && static_cast<unsigned char>(bytes[0]) == 0xFF &&
      static_cast<unsigned char>(bytes[1]) == 0xFE) {
    KINEMO_ASSIGN_OR_RETURN(utf8, Utf16ToUtf8(bytes, false, source));
  } else if (bytes.size() >= 2 && static_cast<unsigned char>(bytes[0]) == 0xFE &&
             static_cast<unsigned char>(bytes[1]) == 0xFF) {
    KINEMO_ASSIGN_OR_RETURN(utf8, Utf16ToUtf8(bytes, true, source));
  } else {
    if (bytes.starts_with("\xEF\xBB\xBF")) bytes.remove_prefix(3);
    utf8.assign(bytes);
  }
  KINEMO_ASSIGN_OR_RETURN(std::vector<Token> tokens, Tokenize(utf8, source));
  Reader r(tokens, source);
  KINEMO_ASSIGN_OR_RETURN(std::string file_type, r.String("File type"));
  if (!file_type.starts_with("ooTextFile"))
    return InvalidField(source, "File type: \"", file_type, "\" is not a Praat text file (ooTextFile)");
  KINEMO_ASSIGN_OR_RETURN(std::string object_class, r.String("Object class"));
  if (object_class != "TextGrid") return InvalidField(source, "Object class: \"", object_class, "\" is not TextGrid");
  TextGrid grid;
  KINEMO_ASSIGN_OR_RETURN(grid.start_s, r.Number("xmin"));
  KINEMO_ASSIGN_OR_RETURN(grid.end_s, r.Number("xmax"));
  if (grid.end_s < grid.start_s)
    return InvalidField(source, "xmax: ", grid.end_s, " is before xmin ", grid.start_s);
  KINEMO_ASSIGN_OR_RETURN(std::string tiers_flag, r.Flag("tiers?"));
  if (tiers_flag != "exists") return grid;
  KINEMO_ASSIGN_OR_RETURN(size_t num_tiers, r.Count("size"));
  for (size_t k = 0; k < num_tiers; ++k) {
    TextGridTier tier;
    const std::string where = kinemo::StrCat("item[", k + 1, "]");
    KINEMO_ASSIGN_OR_RETURN(std::string cls, r.String(where + ".class"));
    KINEMO_ASSIGN_OR_RETURN(tier.name, r.String(where + ".name"));
    if (cls == "IntervalTier") {
      tier.is_interval = true;
    } else if (cls == "TextTier") {
      tier.is_interval = false;
    } else {
      return InvalidField(source, where, ".class: \"", cls, "\" is neither IntervalTier nor TextTier");
    }
    const std::string tname = tier.name.empty() ? where : tier.name;
    KINEMO_ASSIGN_OR_RETURN(double xmin, r.Number(tname + ".xmin"));
    KINEMO_ASSIGN_OR_RETURN(double xmax, r.Number(tname + ".xmax"));
    if (xmax < xmin) return InvalidField(source, tname, ".xmax: ", xmax, " is before xmin ", xmin);
    if (tier.is_interval) {
      KINEMO_ASSIGN_OR_RETURN(size_t n, r.Count(tname + ".intervals.size"));
      tier.intervals.reserve(n);
      for (size_t i = 0; i < n; ++i) {
        const std::string f = kinemo::StrCat(tname, ".intervals[", i + 1, "]");
        TextGridInterval iv;
        KINEMO_ASSIGN_OR_RETURN(iv.start_s, r.Number(f + ".xmin"));
        KINEMO_ASSIGN_OR_RETURN(iv.end_s, r.Number(f + ".xmax"));
        KINEMO_ASSIGN_OR_RETURN(iv.text, r.String(f + ".text"));
        if (iv.end_s < iv.start_s)
          return InvalidField(source, f, ".xmax: ", iv.end_s, " is before xmin ", iv.start_s);
        if (!tier.intervals.empty() && iv.start_s < tier.intervals.back().start_s)
          return InvalidField(source, f, ".xmin: ", iv.start_s, " goes back in time");
        tier.intervals.push_back(std::move(iv));
      }
    } else {
      KINEMO_ASSIGN_OR_RETURN(size_t n, r.Count(tname + ".points.size"));
      tier.points.reserve(n);
      for (size_t i = 0; i < n; ++i) {
        const std::string f = kinemo::StrCat(tname, ".points[", i + 1, "]");
        TextGridPoint p;
        KINEMO_ASSIGN_OR_RETURN(p.time_s, r.Number(f + ".number"));
        KINEMO_ASSIGN_OR_RETURN(p.mark, r.String(f + ".mark"));
        if (!tier.points.empty() && p.time_s < tier.points.back().time_s)
          return InvalidField(source, f, ".number: ", p.time_s, " goes back in time");
        tier.points.push_back(std::move(p));
      }
    }
    grid.tiers.push_back(std::move(tier));
  }
  return grid;
}

StatusOr<TextGrid> ReadTextGridFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return absl::NotFoundError(kinemo::StrCat(path, ": cannot open"));
  f.seekg(0, std::ios::end);
  const std::streamoff size = f.tellg();
  if (size < 0 || static_cast<size_t>(size) > kMaxTextGridBytes)
    return InvalidField(path, "larger than ", kMaxTextGridBytes >> 20, " MiB");
  f.seekg(0);
  std::string bytes(static_cast<size_t>(size), '\0');
  f.read(bytes.data(), size);
  return ParseTextGrid(bytes, path);
}

std::vector<TextGridInterval> NonEmptyIntervals(const TextGridTier& tier) {
  std::vector<TextGridInterval> out;
  for (const auto& iv : tier.intervals) {
    const std::string_view t = Trim(iv.text);
    if (t.empty()) continue;
    out.push_back({iv.start_s, iv.end_s, std::string(t)});
  }
  return out;
}

}  // namespace kinemo::audio

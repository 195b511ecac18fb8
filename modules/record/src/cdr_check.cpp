#include "cdr_check.hpp"

#include "idl_schemas.hpp"

#include <cctype>
#include <map>
#include <memory>
#include <vector>

namespace reflex::record {

namespace {

/// One IDL type as far as its CDR lengths go.
struct Type {
  enum Kind { kPrimitive, kString, kSequence, kStruct, kUnsupported } kind = kUnsupported;
  std::size_t size = 0;                 ///< kPrimitive: bytes (also the alignment)
  std::uint64_t bound = 0;              ///< kSequence: the IDL bound, 0 for none
  std::shared_ptr<const Type> element;  ///< kSequence
  std::string struct_name;              ///< kStruct: fully qualified ("reflex::msg::Header")
  std::string text;                     ///< as written, for messages ("sequence<string, 64>")
};

struct Field {
  std::string name;
  std::shared_ptr<const Type> type;
  std::uint64_t count = 1;  ///< product of the array dimensions (1: not an array)
};

using Structs = std::map<std::string, std::vector<Field>>;

// ---- the IDL subset -------------------------------------------------------------------------------

std::vector<std::string> tokenize(const std::string& s) {
  std::vector<std::string> out;
  for (std::size_t i = 0; i < s.size();) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (std::isspace(c)) {
      ++i;
    } else if (std::isalnum(c) || c == '_') {
      std::size_t j = i;
      while (j < s.size() && (std::isalnum(static_cast<unsigned char>(s[j])) || s[j] == '_')) ++j;
      out.push_back(s.substr(i, j - i));
      i = j;
    } else if (c == ':' && i + 1 < s.size() && s[i + 1] == ':') {
      out.emplace_back("::");
      i += 2;
    } else {
      out.emplace_back(1, s[i]);
      ++i;
    }
  }
  return out;
}

class Parser {
 public:
  Parser(const std::string& text, Structs& structs, std::map<std::string, bool>& enums)
      : t_(tokenize(text)), structs_(structs), enums_(enums) {}

  void parse() {
    std::vector<std::string> scope;
    parseBody(scope);
  }

 private:
  const std::string& peek(std::size_t ahead = 0) const {
    static const std::string end;
    return i_ + ahead < t_.size() ? t_[i_ + ahead] : end;
  }
  std::string take() { return i_ < t_.size() ? t_[i_++] : std::string(); }
  bool accept(const std::string& s) {
    if (peek() != s) return false;
    ++i_;
    return true;
  }
  static std::string join(const std::vector<std::string>& scope, const std::string& name) {
    std::string q;
    for (const std::string& m : scope) q += m + "::";
    return q + name;
  }
  /// Skips to the `;` that ends the current declaration (nested braces included).
  void skipDeclaration() {
    int depth = 0;
    while (i_ < t_.size()) {
      const std::string s = take();
      if (s == "{") ++depth;
      if (s == "}") --depth;
      if (s == ";" && depth <= 0) return;
    }
  }
  void skipAnnotations() {
    while (accept("@")) {
      take();
      if (accept("(")) {
        int depth = 1;
        while (i_ < t_.size() && depth > 0) {
          const std::string s = take();
          depth += s == "(" ? 1 : s == ")" ? -1 : 0;
        }
      }
    }
  }

  void parseBody(std::vector<std::string>& scope) {
    while (i_ < t_.size() && peek() != "}") {
      skipAnnotations();
      if (accept("module")) {
        scope.push_back(take());
        if (!accept("{")) return;
        parseBody(scope);
        accept("}");
        accept(";");
        scope.pop_back();
      } else if (accept("struct")) {
        const std::string name = join(scope, take());
        if (!accept("{")) {  // a forward declaration
          skipDeclaration();
          continue;
        }
        std::vector<Field> fields;
        bool ok = true;
        while (i_ < t_.size() && peek() != "}") {
          skipAnnotations();
          Field f;
          f.type = parseType(scope);
          f.name = take();
          while (accept("[")) {
            const std::uint64_t n = number(take());
            if (n == 0 || !accept("]")) ok = false;
            f.count *= n;
          }
          if (!accept(";")) {
            ok = false;
            skipDeclaration();
          }
          if (f.type->kind == Type::kUnsupported) ok = false;
          fields.push_back(std::move(f));
        }
        accept("}");
        accept(";");
        if (ok) structs_[name] = std::move(fields);
      } else if (accept("enum")) {
        enums_[join(scope, take())] = true;
        skipDeclaration();
      } else {
        skipDeclaration();  // typedef, const, union, ...: the types using them are not checked
      }
    }
  }

  static std::uint64_t number(const std::string& s) {
    if (s.empty() || s.size() > 9) return 0;
    std::uint64_t v = 0;
    for (char c : s) {
      if (c < '0' || c > '9') return 0;
      v = v * 10 + static_cast<std::uint64_t>(c - '0');
    }
    return v;
  }

  std::shared_ptr<const Type> parseType(const std::vector<std::string>& scope) {
    auto t = std::make_shared<Type>();
    if (accept("sequence")) {
      t->kind = Type::kSequence;
      if (!accept("<")) return unsupported();
      t->element = parseType(scope);
      if (accept(",")) t->bound = number(take());
      if (!accept(">") || t->element->kind == Type::kUnsupported) return unsupported();
      t->text = "sequence<" + t->element->text + (t->bound ? ", " + std::to_string(t->bound) : "") + ">";
      return t;
    }
    if (accept("string")) {
      t->kind = Type::kString;
      t->text = "string";
      if (accept("<")) {  // a string bound: fastcdr does not enforce it, neither is it checked here
        take();
        if (!accept(">")) return unsupported();
      }
      return t;
    }
    static const std::map<std::string, std::size_t> primitives = {
        {"boolean", 1}, {"char", 1},   {"octet", 1},  {"int8", 1},  {"uint8", 1},  {"short", 2},
        {"int16", 2},   {"uint16", 2}, {"long", 4},   {"int32", 4}, {"uint32", 4}, {"float", 4},
        {"int64", 8},   {"uint64", 8}, {"double", 8}, {"wchar", 2}};
    std::string word = take();
    if (word == "unsigned") word = take();  // same size as the signed type
    if (word == "long" && peek() == "long") {
      take();
      word = "int64";
    } else if (word == "long" && peek() == "double") {
      return unsupported();
    }
    if (const auto it = primitives.find(word); it != primitives.end()) {
      t->kind = Type::kPrimitive;
      t->size = it->second;
      t->text = word;
      return t;
    }
    // A scoped name: an enum (a 4-byte value in XCDR1) or a struct, looked up from the innermost scope.
    std::string name = word;
    while (accept("::")) name += "::" + take();
    for (std::size_t k = scope.size() + 1; k-- > 0;) {
      const std::string q = join(std::vector<std::string>(scope.begin(), scope.begin() + static_cast<long>(k)), name);
      if (enums_.count(q)) {
        t->kind = Type::kPrimitive;
        t->size = 4;
        t->text = name;
        return t;
      }
      if (structs_.count(q)) {
        t->kind = Type::kStruct;
        t->struct_name = q;
        t->text = name;
        return t;
      }
    }
    return unsupported();
  }
  static std::shared_ptr<const Type> unsupported() { return std::make_shared<Type>(); }

  std::vector<std::string> t_;
  std::size_t i_ = 0;
  Structs& structs_;
  std::map<std::string, bool>& enums_;
};

const Structs& schemaStructs() {
  static const Structs structs = [] {
    Structs s;
    for (const IdlSchemaFile& f : idlSchemaFiles()) {
      std::map<std::string, bool> enums;
      Parser(f.text, s, enums).parse();
    }
    return s;
  }();
  return structs;
}

// ---- the walk -------------------------------------------------------------------------------------

class Walker {
 public:
  Walker(const Structs& structs, const std::uint8_t* p, std::size_t n, bool little)
      : structs_(structs), p_(p), n_(n), little_(little) {}

  bool walkStruct(const std::string& name, int depth) {
    const auto it = structs_.find(name);
    if (it == structs_.end() || depth > 32) return true;  // not checked here
    for (const Field& f : it->second)
      for (std::uint64_t k = 0; k < f.count; ++k)
        if (!walk(*f.type, f.name, depth)) return false;
    return true;
  }
  const std::string& problem() const { return problem_; }

 private:
  bool fail(const std::string& what) {
    problem_ = what;
    return false;
  }
  std::size_t left() const { return n_ - at_; }
  /// Aligns to `k` bytes (relative to the CDR body after the encapsulation), then takes `len` bytes.
  bool take(std::size_t k, std::uint64_t len, const std::string& field) {
    const std::size_t aligned = (at_ + k - 1) / k * k;
    if (aligned > n_ || len > n_ - aligned)
      return fail(field + ": " + std::to_string(len) + " bytes needed at byte " + std::to_string(4 + aligned) +
                  ", the payload ends at byte " + std::to_string(4 + n_));
    at_ = aligned + static_cast<std::size_t>(len);
    return true;
  }
  bool u32(std::uint32_t& v, const std::string& field) {
    if (!take(4, 4, field)) return false;
    const std::uint8_t* b = p_ + at_ - 4;
    v = little_ ? (b[0] | (b[1] << 8) | (b[2] << 16) | (static_cast<std::uint32_t>(b[3]) << 24))
                : (b[3] | (b[2] << 8) | (b[1] << 16) | (static_cast<std::uint32_t>(b[0]) << 24));
    return true;
  }
  /// The fewest bytes one value of `t` takes in XCDR1 (alignment not counted: a lower bound).
  std::uint64_t minimumSize(const Type& t, int depth) const {
    switch (t.kind) {
      case Type::kPrimitive: return t.size;
      case Type::kString:
      case Type::kSequence: return 4;
      case Type::kStruct: {
        const auto it = structs_.find(t.struct_name);
        if (it == structs_.end() || depth > 32) return 0;
        std::uint64_t sum = 0;
        for (const Field& f : it->second) sum += f.count * minimumSize(*f.type, depth + 1);
        return sum;
      }
      case Type::kUnsupported: return 0;
    }
    return 0;
  }
  bool walk(const Type& t, const std::string& field, int depth) {
    switch (t.kind) {
      case Type::kPrimitive: return take(t.size, t.size, field);
      case Type::kString: {
        std::uint32_t len = 0;
        if (!u32(len, field)) return false;
        if (len > left())
          return fail(field + ": string of " + std::to_string(len) + " bytes claimed at byte " + std::to_string(at_) +
                      ", " + std::to_string(left()) + " bytes left");
        at_ += len;
        return true;
      }
      case Type::kSequence: {
        std::uint32_t count = 0;
        if (!u32(count, field)) return false;
        const std::size_t count_at = at_;  // of the count's end: 4 + (at_ - 4)
        if (t.bound != 0 && count > t.bound)
          return fail(field + ": " + std::to_string(count) + " elements claimed at byte " + std::to_string(count_at) +
                      ", " + t.text);
        const std::uint64_t each = minimumSize(*t.element, depth + 1);
        if (each > 0 && count > left() / each)
          return fail(field + ": " + std::to_string(count) + " elements claimed at byte " + std::to_string(count_at) +
                      " (at least " + std::to_string(each) + " bytes each), " + std::to_string(left()) + " bytes left");
        if (count > 0 && t.element->kind == Type::kPrimitive)
          return take(t.element->size, static_cast<std::uint64_t>(count) * t.element->size, field);
        for (std::uint32_t k = 0; k < count; ++k)
          if (!walk(*t.element, field + "[" + std::to_string(k) + "]", depth + 1)) return false;
        return true;
      }
      case Type::kStruct: return walkStruct(t.struct_name, depth + 1);
      case Type::kUnsupported: return true;
    }
    return true;
  }

  const Structs& structs_;
  const std::uint8_t* p_;
  std::size_t n_, at_ = 0;
  bool little_;
  std::string problem_;
};

}  // namespace

std::string cdrLengthProblem(const std::string& type_name, const std::uint8_t* bytes, std::size_t size) noexcept {
  try {
    const Structs& structs = schemaStructs();
    if (!structs.count(type_name)) return "";
    if (size < 4) return "payload of " + std::to_string(size) + " bytes: no encapsulation header";
    if (bytes[0] != 0 || bytes[1] > 1) return "";  // not plain CDR: the type support decides
    Walker w(structs, bytes + 4, size - 4, bytes[1] == 1);
    return w.walkStruct(type_name, 0) ? "" : w.problem();
  } catch (const std::exception&) {  // bad_alloc building the tables: no check rather than an abort
    return "";
  }
}

}  // namespace reflex::record

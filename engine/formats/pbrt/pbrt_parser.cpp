#include "engine/formats/pbrt/pbrt_parser.h"

#include <algorithm>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <utility>

namespace rf::pbrt {

void fail(const Location& at, const std::string& what) {
  throw SceneError(at.str() + ": " + what + at.chain);
}

std::string warning_text(const Location& at, const std::string& what) {
  return at.str() + ": " + what + at.chain;
}

Lexer::Lexer(std::string text, std::string file, std::string chain)
    : text_(std::move(text)), file_(std::move(file)), chain_(std::move(chain)) {
  // A NUL is never part of a pbrt file, and a message quoting a token with one would end there.
  if (size_t nul = text_.find('\0'); nul != std::string::npos)
    fail(at(int(std::count(text_.begin(), text_.begin() + ptrdiff_t(nul), '\n')) + 1),
         "a NUL byte (pbrt scene files are text)");
}

const Token& Lexer::peek() {
  if (!has_peek_) {
    peeked_ = scan();
    has_peek_ = true;
  }
  return peeked_;
}

Token Lexer::next() {
  if (has_peek_) {
    has_peek_ = false;
    return std::move(peeked_);
  }
  return scan();
}

Token Lexer::scan() {
  const size_t n = text_.size();
  for (;;) {  // skip blanks and comments
    while (pos_ < n && std::isspace(static_cast<unsigned char>(text_[pos_]))) {
      if (text_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ < n && text_[pos_] == '#') {
      while (pos_ < n && text_[pos_] != '\n') ++pos_;
      continue;
    }
    break;
  }
  Token t;
  t.line = line_;
  if (pos_ >= n) return t;  // End
  char c = text_[pos_];
  if (c == '[' || c == ']') {
    ++pos_;
    t.kind = c == '[' ? Token::Open : Token::Close;
    t.text = std::string(1, c);
    return t;
  }
  if (c == '"') {
    ++pos_;
    t.kind = Token::String;
    for (;;) {
      if (pos_ >= n || text_[pos_] == '\n')
        fail(at(t.line), "unterminated string (a '\"' is missing before the end of the line)");
      char d = text_[pos_++];
      if (d == '"') break;
      if (d == '\\' && pos_ < n) {
        char e = text_[pos_++];
        t.text += e == 'n' ? '\n' : e == 't' ? '\t' : e;
        continue;
      }
      t.text += d;
    }
    return t;
  }
  t.kind = Token::Word;
  while (pos_ < n && !std::isspace(static_cast<unsigned char>(text_[pos_])) && text_[pos_] != '"' &&
         text_[pos_] != '[' && text_[pos_] != ']' && text_[pos_] != '#')
    t.text += text_[pos_++];
  return t;
}

double to_number(const Token& t, const Location& at, const std::string& what) {
  if (t.kind != Token::Word)
    fail(at, what + ": expected a number, got " +
                 (t.kind == Token::End ? std::string("the end of the file") : "'" + t.text + "'"));
  const char* s = t.text.c_str();
  char* end = nullptr;
  errno = 0;
  double v = std::strtod(s, &end);
  if (end == s || *end != '\0' || errno == ERANGE || !std::isfinite(v))
    fail(at, what + ": expected a number, got '" + t.text + "'");
  return v;
}

namespace {

enum class Kind { Number, Integer, String, Bool };

// The value kind of each parameter type pbrt-v4 knows, and v3's synonyms.
bool type_kind(const std::string& type, Kind& kind) {
  static const char* numeric[] = {"float",  "point2", "vector2", "point3", "vector3", "normal3",
                                  "normal", "point",  "vector",  "rgb",    "color",   "blackbody"};
  for (const char* t : numeric)
    if (type == t) return kind = Kind::Number, true;
  if (type == "integer") return kind = Kind::Integer, true;
  if (type == "string" || type == "texture") return kind = Kind::String, true;
  if (type == "bool") return kind = Kind::Bool, true;
  if (type == "spectrum") return kind = Kind::Number, true;  // or strings: decided by the values
  return false;
}

void add_value(Param& p, Kind kind, const Token& t, const Location& at) {
  const std::string what = "parameter " + p.decl();
  if (p.type == "spectrum" && t.kind == Token::String) {
    p.strings.push_back(t.text);
    return;
  }
  switch (kind) {
    case Kind::Number:
      p.numbers.push_back(to_number(t, at, what));
      return;
    case Kind::Integer: {
      double v = to_number(t, at, what);
      if (v != std::floor(v) || std::fabs(v) > 2147483647.0)
        fail(at, what + ": expected an integer, got '" + t.text + "'");
      p.numbers.push_back(v);
      return;
    }
    case Kind::String:
      if (t.kind != Token::String)
        fail(at, what + ": expected a quoted string, got '" + t.text + "'");
      p.strings.push_back(t.text);
      return;
    case Kind::Bool:
      if (t.text == "true" || t.text == "false") {
        p.bools.push_back(t.text == "true");
        return;
      }
      fail(at, what + ": expected true or false, got '" + t.text + "'");
  }
}

}  // namespace

ParamList read_params(Lexer& lex) {
  ParamList list;
  while (lex.peek().kind == Token::String) {
    Token decl = lex.next();
    Location at = lex.at(decl.line);
    Param p;
    p.at = at;
    // "type name": two words separated by blanks.
    size_t a = decl.text.find_first_not_of(" \t");
    size_t b = a == std::string::npos ? a : decl.text.find_first_of(" \t", a);
    size_t c = b == std::string::npos ? b : decl.text.find_first_not_of(" \t", b);
    size_t d = c == std::string::npos ? c : decl.text.find_first_of(" \t", c);
    if (c == std::string::npos ||
        (d != std::string::npos && decl.text.find_first_not_of(" \t", d) != std::string::npos))
      fail(at, "expected a parameter declaration \"type name\", got \"" + decl.text + "\"");
    p.type = decl.text.substr(a, b - a);
    p.name = decl.text.substr(c, d == std::string::npos ? std::string::npos : d - c);
    Kind kind;
    if (!type_kind(p.type, kind))
      fail(at, "parameter " + p.decl() + ": unknown parameter type '" + p.type +
                   "' (known: integer, float, point2, vector2, point3, vector3, normal3, rgb, "
                   "spectrum, blackbody, bool, string, texture)");
    Token v = lex.next();
    if (v.kind == Token::Open) {
      for (;;) {
        Token e = lex.next();
        if (e.kind == Token::Close) break;
        if (e.kind == Token::End || e.kind == Token::Open)
          fail(lex.at(e.line), "parameter " + p.decl() + ": ']' expected before " +
                                   (e.kind == Token::End ? std::string("the end of the file")
                                                         : std::string("'['")));
        if (e.kind == Token::String && kind != Kind::String && p.type != "spectrum")
          fail(lex.at(e.line),
               "parameter " + p.decl() + ": ']' expected before \"" + e.text + "\"");
        add_value(p, kind, e, lex.at(e.line));
      }
    } else if (v.kind == Token::Word || v.kind == Token::String) {
      add_value(p, kind, v, lex.at(v.line));
    } else {
      fail(lex.at(v.line),
           "parameter " + p.decl() + ": expected a value or '[', got " +
               (v.kind == Token::End ? std::string("the end of the file") : "'" + v.text + "'"));
    }
    size_t count = p.numbers.size() + p.strings.size() + p.bools.size();
    if (count == 0) fail(at, "parameter " + p.decl() + ": no values");
    if (!p.numbers.empty() && !p.strings.empty())
      fail(at, "parameter " + p.decl() + ": mixes numbers and strings");
    list.items.push_back(std::move(p));
  }
  return list;
}

const Param* ParamList::find(const std::string& name) const {
  for (const Param& p : items)
    if (p.name == name) {
      p.used = true;
      return &p;
    }
  return nullptr;
}

bool ParamList::has(const std::string& name) const {
  for (const Param& p : items)
    if (p.name == name) return true;
  return false;
}

void ParamList::use_all_named(const std::string& name) const {
  for (const Param& p : items)
    if (p.name == name) p.used = true;
}

namespace {
[[noreturn]] void type_error(const Param& p, const std::string& expected) {
  fail(p.at, "parameter " + p.decl() + ": expected " + expected);
}
void expect_one(const Param& p) {
  size_t count = p.numbers.size() + p.strings.size() + p.bools.size();
  if (count != 1)
    fail(p.at, "parameter " + p.decl() + ": expected 1 value, got " + std::to_string(count));
}
}  // namespace

double ParamList::number(const std::string& name, double def) const {
  const Param* p = find(name);
  if (!p) return def;
  if (p->type != "float" && p->type != "integer") type_error(*p, "a \"float " + name + "\"");
  expect_one(*p);
  return p->numbers[0];
}

int ParamList::integer(const std::string& name, int def) const {
  const Param* p = find(name);
  if (!p) return def;
  if (p->type != "integer") type_error(*p, "an \"integer " + name + "\"");
  expect_one(*p);
  return int(p->numbers[0]);
}

bool ParamList::boolean(const std::string& name, bool def) const {
  const Param* p = find(name);
  if (!p) return def;
  if (p->type != "bool") type_error(*p, "a \"bool " + name + "\"");
  expect_one(*p);
  return p->bools[0];
}

std::string ParamList::string(const std::string& name, const std::string& def) const {
  const Param* p = find(name);
  if (!p) return def;
  if (p->type != "string") type_error(*p, "a \"string " + name + "\"");
  expect_one(*p);
  return p->strings[0];
}

std::vector<double> ParamList::numbers(const std::string& name, const char* type,
                                       size_t group) const {
  const Param* p = find(name);
  if (!p) return {};
  if (p->type != type && !(std::string(type) == "point3" && p->type == "point") &&
      !(std::string(type) == "normal3" && p->type == "normal") &&
      !(std::string(type) == "vector3" && p->type == "vector"))
    type_error(*p, "a \"" + std::string(type) + " " + name + "\"");
  if (p->numbers.empty() || p->numbers.size() % group != 0)
    fail(p->at, "parameter " + p->decl() + ": expected a multiple of " + std::to_string(group) +
                    " values, got " + std::to_string(p->numbers.size() + p->strings.size()));
  return p->numbers;
}

std::vector<const Param*> ParamList::unused() const {
  std::vector<const Param*> out;
  for (const Param& p : items)
    if (!p.used) out.push_back(&p);
  return out;
}

}  // namespace rf::pbrt

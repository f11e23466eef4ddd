// The pbrt-v4 scene file's syntax: tokens and parameter lists (pbrt-v4's "file format" page).
//
// A file is a sequence of directives (bare words) with positional arguments and then parameters,
// each a quoted "type name" followed by one value or a bracketed list of values. '#' starts a
// comment to the end of the line. Every token keeps its line, and every error names
// "<file>:<line>: " plus the include chain (" (included from a.pbrt:3)").
#pragma once

#include <string>
#include <vector>

#include "engine/scene_error.h"

namespace rf::pbrt {

// Where a token is: the file as shown in messages, its line, and how the file was reached.
struct Location {
  std::string file;
  int line = 0;
  std::string chain;  // " (included from scene.pbrt:4)", empty for the main file
  std::string str() const { return file + ":" + std::to_string(line); }
};

[[noreturn]] void fail(const Location& at, const std::string& what);
// The text of a warning about `at`.
std::string warning_text(const Location& at, const std::string& what);

struct Token {
  enum Kind { Word, String, Open, Close, End } kind = End;
  std::string text;  // the word, or the string without its quotes (escapes resolved)
  int line = 0;
};

// Splits one file's text into tokens.
class Lexer {
 public:
  Lexer(std::string text, std::string file, std::string chain);
  const Token& peek();
  Token next();
  Location at(int line) const { return {file_, line, chain_}; }
  const std::string& file() const { return file_; }

 private:
  Token scan();
  std::string text_, file_, chain_;
  size_t pos_ = 0;
  int line_ = 1;
  bool has_peek_ = false;
  Token peeked_;
};

// One "type name" [values] parameter.
struct Param {
  std::string type, name;  // "float", "roughness"
  std::vector<double> numbers;
  std::vector<std::string> strings;
  std::vector<bool> bools;
  Location at;
  mutable bool used = false;
  std::string decl() const { return "\"" + type + " " + name + "\""; }
};

// The parameters of one directive, with typed lookups that mark what they read. What is never
// read is reported by unused() so the importer can warn about it.
class ParamList {
 public:
  std::vector<Param> items;

  const Param* find(const std::string& name) const;  // marks it used
  // Typed lookups: a parameter of that name but another type is an error naming it.
  double number(const std::string& name, double def) const;  // float or integer
  int integer(const std::string& name, int def) const;
  bool boolean(const std::string& name, bool def) const;
  std::string string(const std::string& name, const std::string& def) const;
  std::vector<double> numbers(const std::string& name, const char* type, size_t group) const;
  bool has(const std::string& name) const;  // does not mark
  void use_all_named(const std::string& name) const;
  std::vector<const Param*> unused() const;
};

// Reads the parameters following a directive's positional arguments (as many as follow).
ParamList read_params(Lexer& lex);

// Parses a bare word as a number; error naming `what` otherwise.
double to_number(const Token& t, const Location& at, const std::string& what);

}  // namespace rf::pbrt

// Conditional RIB: a recursive-descent parser and evaluator of IfBegin conditions (conditional.h).
// Written by hand: no Debian library parses RenderMan's condition language, and it is small.
#include "rib/conditional.h"

#include <cctype>
#include <charconv>
#include <cmath>
#include <regex>
#include <stdexcept>

#include "common/error.h"

namespace reshutter::rib {

namespace {

struct Val {
  std::string text;
  bool isNumber = false;
  double number = 0;
  bool truth() const { return isNumber ? number != 0 : !text.empty(); }
  static Val num(double d) {
    Val v;
    v.isNumber = true, v.number = d;
    v.text = cat(d);
    return v;
  }
  static Val str(std::string s) {
    Val v;
    v.text = std::move(s);
    return v;
  }
};

}  // namespace

// Recursion is bounded by the condition's length (a request argument), and nesting is capped.
class ConditionParser {
 public:
  ConditionParser(const Conditionals& c, std::string_view s) : c_(c), s_(s) {}

  bool run() {
    const Val v = orExpr();
    space();
    if (i_ != s_.size()) bad(cat("unexpected '", s_.substr(i_, 12), "'"));
    return v.truth();
  }

 private:
  [[noreturn]] void bad(const std::string& what) const { throw std::invalid_argument(what); }
  void space() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  bool take(std::string_view tok) {
    space();
    if (s_.substr(i_, tok.size()) != tok) return false;
    i_ += tok.size();
    return true;
  }
  struct Depth {
    int& d;
    explicit Depth(int& depth) : d(depth) {
      if (++d > 64) throw std::invalid_argument("nested deeper than 64");
    }
    ~Depth() { --d; }
  };

  Val orExpr() {
    Depth guard(depth_);
    Val v = andExpr();
    while (take("||")) {
      const Val r = andExpr();
      v = Val::num(v.truth() || r.truth());
    }
    return v;
  }
  Val andExpr() {
    Val v = comparison();
    while (take("&&")) {
      const Val r = comparison();
      v = Val::num(v.truth() && r.truth());
    }
    return v;
  }
  Val comparison() {
    Val a = unary();
    static const char* const ops[] = {"==", "!=", "<=", ">=", "=~", "<", ">"};
    for (const char* op : ops) {
      if (!take(op)) continue;
      const Val b = unary();
      const std::string_view o(op);
      if (o == "=~") return Val::num(matches(b.text, a.text));
      int cmp;
      if (a.isNumber && b.isNumber) cmp = a.number < b.number ? -1 : a.number > b.number ? 1 : 0;
      else cmp = a.text.compare(b.text) < 0 ? -1 : a.text == b.text ? 0 : 1;
      if (o == "==") return Val::num(cmp == 0);
      if (o == "!=") return Val::num(cmp != 0);
      if (o == "<=") return Val::num(cmp <= 0);
      if (o == ">=") return Val::num(cmp >= 0);
      if (o == "<") return Val::num(cmp < 0);
      return Val::num(cmp > 0);
    }
    return a;
  }
  Val unary() {
    if (take("!")) {
      Depth guard(depth_);
      return Val::num(!unary().truth());
    }
    return primary();
  }
  static bool matches(const std::string& pattern, const std::string& text) {
    try {
      return std::regex_search(text, std::regex(pattern, std::regex::ECMAScript));
    } catch (const std::regex_error& e) {
      throw std::invalid_argument(cat("bad regular expression '", pattern, "'"));
    }
  }
  std::string name() {
    space();
    const size_t b = i_;
    while (i_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[i_])) || s_[i_] == '_' || s_[i_] == ':' || s_[i_] == '.')) ++i_;
    if (i_ == b) bad("a name was expected");
    std::string n(s_.substr(b, i_ - b));
    return n.find(':') == std::string::npos ? "user:" + n : n;
  }
  Val variable(const std::string& n) const {
    auto it = c_.user_.find(n);
    if (it == c_.user_.end()) return Val::str("");
    Val v = Val::str(it->second.text);
    v.isNumber = it->second.isNumber, v.number = it->second.number;
    return v;
  }
  std::vector<Val> callArgs() {
    if (!take("(")) bad("'(' was expected");
    std::vector<Val> args;
    if (take(")")) return args;
    do args.push_back(orExpr());
    while (take(","));
    if (!take(")")) bad("')' was expected");
    return args;
  }
  Val primary() {
    space();
    if (i_ >= s_.size()) bad("the condition ends early");
    const char c = s_[i_];
    if (c == '(') {
      ++i_;
      Val v = orExpr();
      if (!take(")")) bad("')' was expected");
      return v;
    }
    if (c == '\'' || c == '"') {
      const size_t close = s_.find(c, i_ + 1);
      if (close == std::string_view::npos) bad("unterminated string");
      Val v = Val::str(std::string(s_.substr(i_ + 1, close - i_ - 1)));
      i_ = close + 1;
      return v;
    }
    if (c == '$') {
      ++i_;
      if (take("{")) {
        const std::string n = name();
        if (!take("}")) bad("'}' was expected");
        return variable(n);
      }
      return variable(name());
    }
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '+' || c == '.') {
      double d = 0;
      const auto [end, ec] = std::from_chars(s_.data() + i_ + (c == '+'), s_.data() + s_.size(), d);
      if (ec != std::errc() || !std::isfinite(d)) bad("malformed number");
      i_ = size_t(end - s_.data());
      return Val::num(d);
    }
    const std::string fn = name();
    if (fn == "user:defined") {
      if (!take("(")) bad("'(' was expected");
      const std::string n = name();
      if (!take(")")) bad("')' was expected");
      return Val::num(c_.user_.count(n) > 0);
    }
    if (fn == "user:concat") {
      std::string out;
      for (const Val& a : callArgs()) out += a.text;
      return Val::str(out);
    }
    if (fn == "user:match") {
      const auto args = callArgs();
      if (args.size() != 2) bad("match takes a pattern and a string");
      return Val::num(matches(args[0].text, args[1].text));
    }
    bad(cat("unknown word '", fn.rfind("user:", 0) == 0 ? fn.substr(5) : fn, "' (variables start with $)"));
  }

  const Conditionals& c_;
  std::string_view s_;
  size_t i_ = 0;
  int depth_ = 0;
};

void Conditionals::setUser(const std::string& name, const std::string& text, bool isNumber, double number) {
  Var& v = user_["user:" + name];
  v.text = text, v.isNumber = isNumber, v.number = number;
}

bool Conditionals::evaluate(std::string_view condition) const { return ConditionParser(*this, condition).run(); }

bool Conditionals::ifBegin(bool value) {
  Block b;
  b.parentActive = active();
  b.active = b.parentActive && value;
  b.taken = b.active;
  blocks_.push_back(b);
  return true;
}

bool Conditionals::elseIf(bool value) {
  if (blocks_.empty() || blocks_.back().sawElse) return false;
  Block& b = blocks_.back();
  b.active = b.parentActive && !b.taken && value;
  b.taken = b.taken || b.active;
  return true;
}

bool Conditionals::elseBranch() {
  if (blocks_.empty() || blocks_.back().sawElse) return false;
  Block& b = blocks_.back();
  b.active = b.parentActive && !b.taken;
  b.taken = true, b.sawElse = true;
  return true;
}

bool Conditionals::ifEnd() {
  if (blocks_.empty()) return false;
  blocks_.pop_back();
  return true;
}

}  // namespace reshutter::rib

// Conditional RIB: IfBegin / ElseIf / Else / IfEnd blocks whose conditions test Option "user"
// values, as render-pass pipelines write them (IfBegin "$user:pass == 'beauty'"). The reader
// keeps one of these: it records user options as they are read, evaluates each condition, and
// skips every request of a branch not taken (ReadArchive included: a skipped branch never reads
// its archives).
//
// Conditions: numbers, 'strings' (or "strings"), variables $user:name or ${user:name} (a name
// without a class means user:name; an undefined one is the empty string), defined(user:name),
// concat(a, b, …), match('regex', s) and s =~ 'regex' (ECMAScript regular expressions, searched),
// comparisons == != < <= > >= (numeric when both sides are numbers, else by string), ! && || and
// parentheses.
#pragma once

#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace reshutter::rib {

class Conditionals {
 public:
  /// Records an Option "user" value (numbers as their first element).
  void setUser(const std::string& name, const std::string& text, bool isNumber, double number);
  /// Evaluates `condition`; throws std::invalid_argument (with the problem) when it is malformed.
  bool evaluate(std::string_view condition) const;

  /// Block structure. Each returns false when the request is misplaced (ElseIf without IfBegin …).
  bool ifBegin(bool value);
  /// Whether an ElseIf's condition needs evaluating at all (not when a branch was taken).
  bool elseIfWanted() const { return !blocks_.empty() && blocks_.back().parentActive && !blocks_.back().taken; }
  bool elseIf(bool value);
  bool elseBranch();
  bool ifEnd();
  /// True while requests are to be handled (every enclosing branch is taken).
  bool active() const { return blocks_.empty() || blocks_.back().active; }
  bool open() const { return !blocks_.empty(); }

 private:
  struct Block {
    bool parentActive = true, taken = false, active = true, sawElse = false;
  };
  struct Var {
    std::string text;
    bool isNumber = false;
    double number = 0;
  };
  std::vector<Block> blocks_;
  std::map<std::string, Var, std::less<>> user_;
  friend class ConditionParser;
};

}  // namespace reshutter::rib

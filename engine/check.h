// Invariants in code (docs/design.md "Invariants"). RF_CHECK states a cheap invariant at a module
// border and holds in every build: a broken one throws CheckFailure (a std::logic_error: a bug,
// never bad input, which gets its own error naming the file or field) naming the file, line and
// condition, so a server answers the call with an internal error instead of going on with a
// broken state. RF_DCHECK states one too costly for release builds (a loop over a table, a check
// per sample); it holds in debug and sanitizer builds (RAYFARM_DCHECKS, set by CMake) and compiles
// to nothing, its operands unevaluated, in release builds. Inside the SIMD lane loops only
// RF_DCHECK, so that nothing stops them vectorising.
//
//   RF_CHECK(task.pass < passes, "task pass " + std::to_string(task.pass));
//   RF_DCHECK(std::fabs(sum - 1) < 1e-4, "pmf sums to " + std::to_string(sum));
//
// The message is an expression evaluated only when the check fails.
#pragma once

#include <stdexcept>
#include <string>

namespace rf {

class CheckFailure : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};

[[noreturn]] void check_failed(const char* file, int line, const char* condition,
                               const std::string& message);

#if !defined(NDEBUG) || defined(RAYFARM_DCHECKS)
inline constexpr bool kDchecks = true;
#else
inline constexpr bool kDchecks = false;
#endif

}  // namespace rf

#define RF_CHECK(condition, message)                                            \
  do {                                                                          \
    if (!(condition)) [[unlikely]]                                              \
      ::rf::check_failed(__FILE__, __LINE__, #condition, std::string(message)); \
  } while (0)

#if !defined(NDEBUG) || defined(RAYFARM_DCHECKS)
#define RF_DCHECK(condition, message) RF_CHECK(condition, message)
#else
#define RF_DCHECK(condition, message) \
  do {                                \
    if (false) {                      \
      (void)(condition);              \
      (void)(message);                \
    }                                 \
  } while (0)
#endif

// Invariant checks that stay on in release builds.
//
// A failed check is a bug in iso, never a property of the input: untrusted input is reported with
// iso::FileError instead. A failed check throws iso::InternalError rather than aborting, because
// library code must never terminate the application that uses it.
#pragma once

#include <stdexcept>

namespace iso {

class InternalError : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};

[[noreturn]] void failCheck(const char* expression, const char* file, int line);

}  // namespace iso

#define ISO_CHECK(condition)                            \
  do {                                                  \
    if (!(condition)) [[unlikely]]                      \
      ::iso::failCheck(#condition, __FILE__, __LINE__); \
  } while (false)

#ifdef NDEBUG
#define ISO_DCHECK(condition) \
  do {                        \
  } while (false && (condition))
#else
#define ISO_DCHECK(condition) ISO_CHECK(condition)
#endif

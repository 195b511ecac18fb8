// What a call throws, as text, for tests that check error messages. Header-only.
#pragma once

#include <string>
#include <utility>

namespace reflex::testing {

/// The message (what()) of the exception of type E that f() throws; `if_none` when f() returns.
/// Any other exception propagates, so the test fails on it with its own message.
template <class E, class F>
std::string messageOf(F&& f, const std::string& if_none = "no error") {
  try {
    std::forward<F>(f)();
  } catch (const E& e) {
    return e.what();
  }
  return if_none;
}

}  // namespace reflex::testing

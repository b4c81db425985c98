// insnav/check.hpp -- failure reporting for the header-only core.
//
// The core never calls std::exit and never lets a NaN pass silently.  Numeric
// routines return a Status; INSNAV_CHECK guards preconditions and calls the
// installed handler, which by default aborts (embedded builds) and which the
// Python bindings replace with one that throws (so Python sees an exception
// naming what was wrong).
#pragma once

#include <cstdio>
#include <cstdlib>

namespace insnav {

enum class Status : int {
  kOk = 0,
  kNonFinite = 1,        // a NaN/inf appeared in an input or the state
  kNotPositiveDefinite,  // a covariance failed Cholesky and could not be repaired
  kBadInput,             // a precondition on the inputs was violated
};

inline const char* to_string(Status s) {
  switch (s) {
    case Status::kOk: return "ok";
    case Status::kNonFinite: return "non-finite value";
    case Status::kNotPositiveDefinite: return "covariance not positive definite";
    case Status::kBadInput: return "bad input";
  }
  return "unknown";
}

using CheckHandler = void (*)(const char* expr, const char* msg, const char* file, int line);

inline void default_check_handler(const char* expr, const char* msg, const char* file, int line) {
  std::fprintf(stderr, "insnav check failed: %s (%s) at %s:%d\n", msg, expr, file, line);
  std::abort();
}

inline CheckHandler& check_handler() {
  static CheckHandler handler = &default_check_handler;
  return handler;
}

/// Install a handler (the Python module installs one that throws).
inline void set_check_handler(CheckHandler h) { check_handler() = h ? h : &default_check_handler; }

}  // namespace insnav

#define INSNAV_CHECK(cond, msg)                                                   \
  do {                                                                            \
    if (!(cond)) ::insnav::check_handler()(#cond, (msg), __FILE__, __LINE__);     \
  } while (0)

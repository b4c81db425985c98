// Minimal assertion helpers for the plain C++ tests (no framework needed).
#pragma once
#include <cmath>
#include <cstdio>

inline int g_failures = 0;

#define EXPECT_LT(a, b)                                                                    \
  do {                                                                                     \
    const double va_ = (a), vb_ = (b);                                                     \
    if (!(va_ < vb_)) {                                                                    \
      std::printf("FAIL %s:%d: %s = %.6g is not < %s = %.6g\n", __FILE__, __LINE__, #a, va_, #b, vb_); \
      ++g_failures;                                                                        \
    }                                                                                      \
  } while (0)

#define EXPECT_TRUE(c)                                                   \
  do {                                                                   \
    if (!(c)) {                                                          \
      std::printf("FAIL %s:%d: %s\n", __FILE__, __LINE__, #c);           \
      ++g_failures;                                                      \
    }                                                                    \
  } while (0)

#define TEST_MAIN_END()                                          \
  if (g_failures) std::printf("%d failure(s)\n", g_failures);   \
  else std::printf("all passed\n");                              \
  return g_failures ? 1 : 0;

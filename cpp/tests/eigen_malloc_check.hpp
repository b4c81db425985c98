// Include FIRST, before any Eigen header: counts Eigen assertions in every
// build type (also Release, where eigen_assert is normally compiled out) and
// switches on EIGEN_RUNTIME_NO_MALLOC, so that
// Eigen::internal::set_is_malloc_allowed(false) makes any heap allocation an
// assertion counted in g_eigen_asserts (the no-heap checks of the hot paths).
#pragma once
#include <cstdio>

inline int g_eigen_asserts = 0;
#define eigen_assert(x)                             \
  do {                                              \
    if (!(x)) {                                     \
      ++g_eigen_asserts;                            \
      std::printf("eigen_assert failed: %s\n", #x); \
    }                                               \
  } while (0)
#define EIGEN_RUNTIME_NO_MALLOC
#include <Eigen/Core>

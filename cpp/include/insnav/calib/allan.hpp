// insnav/calib/allan.hpp -- overlapping Allan variance of a sampled rate
// (gyro angular rate, accelerometer specific force) per axis.
//
// Definition (IEEE Std 952-1997, Annex C, eq. (C.2) with overlapping clusters;
// Riley, NIST SP 1065 (2008), eq. (11)): with the rate samples y_k
// (k = 0..n-1, interval tau0) integrated to the phase (angle or velocity)
//   x_0 = 0,  x_{j+1} = x_j + y_j tau0            (N = n + 1 phase points)
// the overlapping Allan variance at tau = m tau0 is
//   sigma^2(tau) = 1 / (2 tau^2 (N - 2m)) sum_{i=0}^{N-2m-1} (x_{i+2m} - 2 x_{i+m} + x_i)^2,
// the same estimator as allantools.oadev(..., data_type="freq").
//
// Cost: O(n) per tau (the cluster averages are differences of the phase,
// the "cumulative sum" form), no allocation besides one phase buffer per
// worker thread.
//
// Numerics: the rate's mean is removed first (a constant rate is a linear
// phase whose second difference is zero, so the variance is unchanged) and
// the phase is accumulated with Knuth's TwoSum compensation (Higham 2002,
// Accuracy and Stability of Numerical Algorithms, sec. 4.3), so every stored
// x_j is within about one rounding of the exact prefix sum: the second
// difference then loses only log10(|x| / |second difference|) digits instead
// of growing with the record length.  The phase is kept in rate x samples
// (tau0 applied at the end: sigma^2 = S / (2 m^2 (N - 2m)), no rounding by
// tau0), and the squared differences are summed in four partial sums folded
// into a compensated total every 4096 terms.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <thread>
#include <vector>

#include <Eigen/Core>

#include "insnav/check.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace insnav::calib {

/// Cluster sizes m (tau = m tau0) for n rate samples: round(2^(k / per_octave))
/// for k = 0, 1, ..., distinct and at most max_m (default n / 2, the largest m
/// with one term N - 2m >= 1).  per_octave = 1 gives the octave spacing
/// 1, 2, 4, 8, ...; 4 or 8 a denser one.
inline std::vector<std::int64_t> cluster_sizes(std::int64_t n, int per_octave = 1, std::int64_t max_m = -1) {
  INSNAV_CHECK(per_octave >= 1 && per_octave <= 64, "per_octave must be in 1..64");
  std::vector<std::int64_t> out;
  const std::int64_t top = max_m > 0 ? std::min<std::int64_t>(max_m, n / 2) : n / 2;
  for (int k = 0;; ++k) {
    const double v = std::round(std::exp2(static_cast<double>(k) / per_octave));
    if (v > static_cast<double>(top)) break;
    const auto m = static_cast<std::int64_t>(v);
    if (out.empty() || m != out.back()) out.push_back(m);
  }
  return out;
}

/// One axis of rate samples: sample i at data[i * stride].
struct RateSeries {
  const double* data = nullptr;
  std::int64_t stride = 1;
};

namespace detail {

/// Largest number of axes whose phases one pass builds (memory: that many
/// phase buffers of n + 1 doubles per worker thread).
inline constexpr int kAxesPerPass = 3;

/// Phases of k <= kAxesPerPass axes in one pass over their samples
/// (axis a: y[a].data[i * y[a].stride]), each x[a] (n + 1 values) in rate x
/// samples: x_0 = 0, x_{j+1} = sum_{i<=j} (y_i - mean), compensated (TwoSum,
/// the k chains interleaved).  Returns the row of the first non-finite
/// sample, or -1.
template <int K>
inline std::int64_t centred_phases_k(const RateSeries* y, std::int64_t n, double* const* x) {
  // the means need not be exact (any constant leaves the variance unchanged)
  double mean[K] = {}, s[K] = {}, c[K] = {};
  const double* p[K];
  std::int64_t st[K];
  for (int a = 0; a < K; ++a) {
    p[a] = y[a].data;
    st[a] = y[a].stride;
  }
  for (std::int64_t i = 0; i < n; ++i)
    for (int a = 0; a < K; ++a) mean[a] += p[a][i * st[a]];
  for (int a = 0; a < K; ++a) {
    if (!std::isfinite(mean[a])) {
      for (std::int64_t i = 0; i < n; ++i)
        for (int b = 0; b < K; ++b)
          if (!std::isfinite(p[b][i * st[b]])) return i;
    }
    mean[a] /= static_cast<double>(n);
    x[a][0] = 0.0;
  }
  for (std::int64_t i = 0; i < n; ++i) {
    for (int a = 0; a < K; ++a) {
      const double v = p[a][i * st[a]] - mean[a];
      const double t = s[a] + v;  // TwoSum: t + err == s + v exactly
      const double bp = t - s[a];
      c[a] += (s[a] - (t - bp)) + (v - bp);
      s[a] = t;
      x[a][i + 1] = s[a] + c[a];
    }
  }
  return -1;
}

inline std::int64_t centred_phases(const RateSeries* y, std::int64_t n, int k, double* const* x) {
  static_assert(kAxesPerPass == 3, "one instantiation per group size");
  switch (k) {
    case 1: return centred_phases_k<1>(y, n, x);
    case 2: return centred_phases_k<2>(y, n, x);
    default: return centred_phases_k<3>(y, n, x);
  }
}

/// Sum over i in [b, e) of (x_{i+2m} - 2 x_{i+m} + x_i)^2 (Eigen's packet
/// reduction: SIMD with several partial sums).
inline double second_difference_sumsq(const double* x0, std::int64_t m, std::int64_t b, std::int64_t e) {
  using Seg = Eigen::Map<const Eigen::ArrayXd>;
  const Eigen::Index len = static_cast<Eigen::Index>(e - b);
  const Seg p0(x0 + b, len), p1(x0 + b + m, len), p2(x0 + b + 2 * m, len);
  return ((p2 - p1) - (p1 - p0)).square().sum();
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(INSNAV_NO_SIMD_DISPATCH)
#define INSNAV_ALLAN_AVX2 1
/// The same sum with AVX2 (4 doubles, four partial sums of vectors), chosen
/// at run time when the CPU has it (the extension is built for baseline
/// x86-64, whose SSE2 halves the width of the loop above).
__attribute__((target("avx2,fma"))) inline double second_difference_sumsq_avx2(const double* x0, std::int64_t m,
                                                                               std::int64_t b, std::int64_t e) {
  typedef double V __attribute__((vector_size(32), aligned(8), may_alias));  // unaligned loads
  const double* x1 = x0 + m;
  const double* x2 = x0 + 2 * m;
  V a0 = {0.0, 0.0, 0.0, 0.0}, a1 = a0, a2 = a0, a3 = a0;
  std::int64_t i = b;
  for (; i + 16 <= e; i += 16) {
    const V d0 = (*(const V*)(x2 + i) - *(const V*)(x1 + i)) - (*(const V*)(x1 + i) - *(const V*)(x0 + i));
    const V d1 = (*(const V*)(x2 + i + 4) - *(const V*)(x1 + i + 4)) - (*(const V*)(x1 + i + 4) - *(const V*)(x0 + i + 4));
    const V d2 = (*(const V*)(x2 + i + 8) - *(const V*)(x1 + i + 8)) - (*(const V*)(x1 + i + 8) - *(const V*)(x0 + i + 8));
    const V d3 =
        (*(const V*)(x2 + i + 12) - *(const V*)(x1 + i + 12)) - (*(const V*)(x1 + i + 12) - *(const V*)(x0 + i + 12));
    a0 += d0 * d0;
    a1 += d1 * d1;
    a2 += d2 * d2;
    a3 += d3 * d3;
  }
  const V a = (a0 + a1) + (a2 + a3);
  double tot = (a[0] + a[1]) + (a[2] + a[3]);
  for (; i < e; ++i) {
    const double d = (x2[i] - x1[i]) - (x1[i] - x0[i]);
    tot += d * d;
  }
  return tot;
}

inline bool cpu_has_avx2() {
  static const bool yes = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  }();
  return yes;
}
#endif

struct FreeDeleter {
  void operator()(double* p) const { std::free(p); }
};

/// An uninitialised buffer of `count` doubles (the phase is written before
/// it is read).  On Linux a large one is 2 MiB aligned and marked for
/// transparent huge pages: a 24 h, 200 Hz axis (138 MB) then costs tens of
/// page faults instead of 34000 (measured: the phase pass took longer than
/// all 22 sums of a 4 M-sample axis without it).
inline std::unique_ptr<double[], FreeDeleter> phase_buffer(std::size_t count) {
  const std::size_t bytes = count * sizeof(double);
#if defined(__linux__)
  constexpr std::size_t kHuge = std::size_t(2) << 20;
  if (bytes >= 4 * kHuge) {
    const std::size_t rounded = (bytes + kHuge - 1) / kHuge * kHuge;
    if (void* p = std::aligned_alloc(kHuge, rounded)) {
      madvise(p, rounded, MADV_HUGEPAGE);  // advice only: an error leaves ordinary pages
      return std::unique_ptr<double[], FreeDeleter>(static_cast<double*>(p));
    }
  }
#endif
  void* p = std::malloc(bytes > 0 ? bytes : sizeof(double));
  INSNAV_CHECK(p != nullptr, "overlapping_avar: out of memory for the phase buffer");
  return std::unique_ptr<double[], FreeDeleter>(static_cast<double*>(p));
}

/// Neumaier's compensated running sum (Higham 2002, sec. 4.3).
struct CompensatedSum {
  double sum = 0.0, comp = 0.0;
  void add(double v) {
    const double t = sum + v;
    comp += std::fabs(sum) >= std::fabs(v) ? (sum - t) + v : (v - t) + sum;
    sum = t;
  }
  double value() const { return sum + comp; }
};

/// The sums of squared second differences of every cluster size for k axes
/// (phases x[a], N points): one sweep over blocks of i, every m within a
/// block, so that a block's phase pieces at offsets 0, m and 2m are read from
/// memory once and reused by all the m sharing them (for octave spacing the
/// offsets m and 2m of neighbouring octaves coincide): the sweep is bounded
/// by the arithmetic, not by reading the phase 3 x n_m times.
inline void second_difference_sums(double* const* x, int k, std::int64_t N, const std::int64_t* m, int n_m,
                                   CompensatedSum* sums /* n_m x k */, std::int64_t i_begin = 0,
                                   std::int64_t i_end = -1) {
  constexpr std::int64_t kBlock = 4096;  // 32 KiB of each phase piece
  std::int64_t terms_max = 0;
  for (int j = 0; j < n_m; ++j) terms_max = std::max(terms_max, N - 2 * m[j]);
  if (i_end < 0 || i_end > terms_max) i_end = terms_max;
#ifdef INSNAV_ALLAN_AVX2
  const bool avx2 = cpu_has_avx2();
#endif
  for (std::int64_t b = i_begin; b < i_end; b += kBlock) {
    for (int j = 0; j < n_m; ++j) {
      const std::int64_t e = std::min({N - 2 * m[j], b + kBlock, i_end});
      if (e <= b) continue;
      for (int a = 0; a < k; ++a) {
#ifdef INSNAV_ALLAN_AVX2
        if (avx2) {
          sums[j * k + a].add(second_difference_sumsq_avx2(x[a], m[j], b, e));
          continue;
        }
#endif
        sums[j * k + a].add(second_difference_sumsq(x[a], m[j], b, e));
      }
    }
  }
}

}  // namespace detail

/// Outcome of overlapping_avar: kOk, or kNonFinite with the first bad sample.
struct AllanStatus {
  Status status = Status::kOk;
  std::int64_t bad_sample = -1;  // row of the first non-finite value
  int bad_axis = -1;             // first axis of the group of three holding it
};

/// Overlapping Allan variance of n_axes rate series of n samples each.
///
/// y        n_axes series at a uniform interval tau0 (any unit u)
/// m        n_m cluster sizes, each 1 <= m <= n / 2 (tau = m tau0)
/// avar     out: (n_m, n_axes) row-major [u^2]
/// terms    out (optional): n_m counts N - 2m of second differences per m
/// threads  the axes, in groups of up to three, are shared among this many
///          threads (<= 0: the hardware's); with fewer groups than threads
///          each group's sweep over i is split among them
///
/// The variance does not depend on tau0 (the phase is y tau0 summed and
/// divided by tau = m tau0), so tau0 is not an argument.  Memory: one phase
/// buffer of n + 1 doubles per axis of a group, per thread.  No sample is
/// copied; a non-finite one makes its group's variances NaN and is reported.
inline AllanStatus overlapping_avar(const RateSeries* y, int n_axes, std::int64_t n, const std::int64_t* m, int n_m,
                                    double* avar, std::int64_t* terms = nullptr, int threads = 1) {
  INSNAV_CHECK(n >= 2 && n_axes >= 1, "need at least 2 samples and 1 axis");
  for (int j = 0; j < n_m; ++j) INSNAV_CHECK(m[j] >= 1 && 2 * m[j] <= n, "cluster size m must be in 1..n/2");
  const std::int64_t N = n + 1;
  if (terms)
    for (int j = 0; j < n_m; ++j) terms[j] = N - 2 * m[j];
  constexpr int kPass = detail::kAxesPerPass;
  const int groups = (n_axes + kPass - 1) / kPass;
  if (threads <= 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  // threads per group for the sweep when there are fewer groups than threads (a single axis on 2 cores)
  const int inner = std::max(1, threads / std::max(1, groups));
  threads = std::max(1, std::min(threads, groups));
  std::vector<std::int64_t> bad(groups, -1);
  auto work = [&](int first_group) {
    // no value-initialisation: every element is written by centred_phases before it is read
    const int width = std::min(kPass, n_axes);
    const auto buf = detail::phase_buffer(static_cast<std::size_t>(N) * width);
    std::vector<detail::CompensatedSum> sums(static_cast<std::size_t>(n_m) * kPass);
    for (int g = first_group; g < groups; g += threads) {
      const int a0 = g * kPass;
      const int k = std::min(kPass, n_axes - a0);
      double* x[kPass];
      for (int a = 0; a < k; ++a) x[a] = buf.get() + static_cast<std::size_t>(a) * N;
      bad[g] = detail::centred_phases(y + a0, n, k, x);
      if (bad[g] >= 0) {
        for (int j = 0; j < n_m; ++j)
          for (int a = 0; a < k; ++a) avar[j * n_axes + a0 + a] = std::nan("");
        continue;
      }
      std::fill(sums.begin(), sums.end(), detail::CompensatedSum{});
      if (inner <= 1) {
        detail::second_difference_sums(x, k, N, m, n_m, sums.data());
      } else {  // fewer groups than threads: the sweep over i is split among `inner` threads
        std::int64_t most = 0;
        for (int j = 0; j < n_m; ++j) most = std::max(most, N - 2 * m[j]);
        const std::int64_t span = (most + inner - 1) / inner;
        std::vector<std::vector<detail::CompensatedSum>> part(inner, std::vector<detail::CompensatedSum>(sums.size()));
        std::vector<std::thread> sub;
        for (int t = 1; t < inner; ++t)
          sub.emplace_back([&, t] { detail::second_difference_sums(x, k, N, m, n_m, part[t].data(), t * span,
                                                                     (t + 1) * span); });
        detail::second_difference_sums(x, k, N, m, n_m, part[0].data(), 0, span);
        for (auto& th : sub) th.join();
        for (int t = 0; t < inner; ++t)
          for (std::size_t q = 0; q < sums.size(); ++q) sums[q].add(part[t][q].value());
      }
      for (int j = 0; j < n_m; ++j) {
        const double mm = static_cast<double>(m[j]);
        for (int a = 0; a < k; ++a)
          avar[j * n_axes + a0 + a] = sums[j * k + a].value() / (2.0 * mm * mm * static_cast<double>(N - 2 * m[j]));
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work, t);
  work(0);
  for (auto& th : pool) th.join();
  AllanStatus st;
  for (int g = 0; g < groups; ++g)
    if (bad[g] >= 0 && (st.bad_sample < 0 || bad[g] < st.bad_sample)) {
      st.status = Status::kNonFinite;
      st.bad_sample = bad[g];
      st.bad_axis = g * kPass;
    }
  return st;
}

/// The same for one row-major (n, n_axes) array.
inline AllanStatus overlapping_avar(const double* y, std::int64_t n, int n_axes, const std::int64_t* m, int n_m,
                                    double* avar, std::int64_t* terms = nullptr, int threads = 1) {
  std::vector<RateSeries> axes(static_cast<std::size_t>(n_axes));
  for (int a = 0; a < n_axes; ++a) axes[a] = RateSeries{y + a, n_axes};
  return overlapping_avar(axes.data(), n_axes, n, m, n_m, avar, terms, threads);
}

}  // namespace insnav::calib

// Overlapping Allan variance (calib/allan.hpp) against the definition
// evaluated directly (IEEE Std 952-1997, eq. (C.2); NIST SP 1065, eq. (11)):
// the variance of the differences of adjacent overlapping cluster averages,
// summed in long double from the rate samples themselves (no phase);
// a rate with a large constant offset and a random walk gives the same
// numbers (the mean removal and the compensated phase); white noise follows
// sigma^2 / m; a non-finite sample is reported by row.
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "insnav/calib/allan.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

/// 1/2 <(ybar_{i+m} - ybar_i)^2> over all i, ybar_i the mean of y_i..y_{i+m-1}.
double direct_avar(const std::vector<double>& y, std::int64_t m) {
  const std::int64_t n = static_cast<std::int64_t>(y.size());
  long double s = 0.0L;
  std::int64_t count = 0;
  for (std::int64_t i = 0; i + 2 * m <= n; ++i) {
    long double a = 0.0L, b = 0.0L;
    for (std::int64_t k = 0; k < m; ++k) {
      a += y[i + k];
      b += y[i + m + k];
    }
    const long double d = (b - a) / static_cast<long double>(m);
    s += d * d;
    ++count;
  }
  return static_cast<double>(s / (2.0L * count));
}

}  // namespace

int main() {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> nd;
  const std::int64_t n = 3000;
  std::vector<double> y(n * 2);
  double walk = 0.0;
  for (std::int64_t i = 0; i < n; ++i) {
    walk += 0.01 * nd(rng);
    y[2 * i] = nd(rng);                        // white noise, sigma 1
    y[2 * i + 1] = 9.80665 + 0.2 * nd(rng) + walk;  // offset + white + random walk
  }
  const auto m = calib::cluster_sizes(n, 2);
  EXPECT_TRUE(m.front() == 1 && m.back() <= n / 2);
  for (std::size_t j = 1; j < m.size(); ++j) EXPECT_TRUE(m[j] > m[j - 1]);
  EXPECT_TRUE(calib::cluster_sizes(n, 1).size() == 11);  // 1 .. 1024 <= 1500
  std::vector<double> avar(m.size() * 2);
  std::vector<std::int64_t> terms(m.size());
  const auto st = calib::overlapping_avar(y.data(), n, 2, m.data(), static_cast<int>(m.size()), avar.data(),
                                          terms.data(), 2);
  EXPECT_TRUE(st.status == Status::kOk);
  double worst = 0.0;
  for (std::size_t j = 0; j < m.size(); ++j) {
    EXPECT_TRUE(terms[j] == n + 1 - 2 * m[j]);
    for (int a = 0; a < 2; ++a) {
      std::vector<double> col(n);
      for (std::int64_t i = 0; i < n; ++i) col[i] = y[2 * i + a];
      const double ref = direct_avar(col, m[j]);
      worst = std::fmax(worst, std::fabs(avar[j * 2 + a] / ref - 1.0));
    }
  }
  std::printf("largest relative difference from the direct definition: %.2e\n", worst);
  EXPECT_LT(worst, 1e-12);
  // white noise of unit variance: sigma^2(m) = 1 / m within the estimate's spread
  EXPECT_LT(std::fabs(avar[0] - 1.0), 0.1);
  // a non-finite sample: its row, its group's variances NaN
  y[2 * 1234 + 1] = std::nan("");
  const auto bad = calib::overlapping_avar(y.data(), n, 2, m.data(), static_cast<int>(m.size()), avar.data());
  EXPECT_TRUE(bad.status == Status::kNonFinite && bad.bad_sample == 1234 && std::isnan(avar[1]));
  TEST_MAIN_END();
}

// The fixed-size measurement-update kernels that the Python extension runs
// (RbUkf: 6 rows x 6 or n columns; Ukf: 6 rows), which the sanitizer build of
// the other tests leaves out (-DINSNAV_NO_FIXED_UPDATE_KERNELS: the bounded
// dynamic path, half the compile time).  This file is compiled with them in
// every build: each kernel against the linear Kalman (Joseph) update for a
// linear measurement (seed 000: the RB-UKF's measurement update is the linear
// KF update; the UT is exact for a linear h), to 1e-9, and the whole cycle
// with them allocates nothing on the heap.
#include <cstdio>
#include <random>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#undef INSNAV_NO_FIXED_UPDATE_KERNELS  // the kernels are what this test is for
#include "insnav/filter/kalman_update.hpp"
#include "insnav/filter/layout.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "fixtures.hpp"
#include "test_util.hpp"

using namespace insnav;
using L = Layout15;

namespace {

/// A linear measurement: h(dx) = H dx.
struct LinMeas {
  LinearMeasurement<L> lin;
  const LinearMeasurement<L>& linear() const { return lin; }
  LinearMeasurement<L>::RowVec predicted_residual(const StateVec<L>& dx) const {
    LinearMeasurement<L>::RowVec z = lin.H * dx;
    return z;
  }
};

double rel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) { return (a - b).norm() / std::max(b.norm(), 1e-300); }

StateCov<L> random_spd(std::mt19937& rng) {
  std::normal_distribution<double> nd;
  StateCov<L> A;
  for (int i = 0; i < L::kSize; ++i)
    for (int j = 0; j < L::kSize; ++j) A(i, j) = nd(rng);
  return A * A.transpose() / L::kSize + 0.1 * StateCov<L>::Identity();
}

/// 6 rows; `cols` leading non-zero columns of H (6: the <6, 6> kernel; n: <6, n>).
LinMeas make_meas(std::mt19937& rng, int cols) {
  std::normal_distribution<double> nd;
  LinMeas m;
  m.lin.residual.resize(6);
  m.lin.H.setZero(6, L::kSize);
  m.lin.R.setZero(6, 6);
  for (int i = 0; i < 6; ++i) {
    m.lin.residual[i] = 3.0 * nd(rng);
    for (int j = 0; j < cols; ++j) m.lin.H(i, j) = (cols == 6) ? (i == j) : nd(rng);
    m.lin.R(i, i) = 0.5 + std::abs(nd(rng));
  }
  m.lin.n_cols = cols;
  return m;
}

void test_kernels_equal_the_kalman_update() {
  std::mt19937 rng(11);
  for (int cols : {6, L::kSize}) {
    const LinMeas meas = make_meas(rng, cols);
    const StateCov<L> P0 = random_spd(rng);
    StateVec<L> xr = StateVec<L>::Zero();
    StateCov<L> Pr = P0;
    const UpdateResult rr = kalman_update<L>(xr, Pr, meas.lin, 0.0);
    for (UpdateForm form : {UpdateForm::kDensePaper, UpdateForm::kDenseJoseph, UpdateForm::kBlockSparseJoseph,
                            UpdateForm::kBlockSparseFactored}) {
      RbUkf<L> f(ImuErrorModel{});
      f.initialize(P0);
      f.set_update_form(form);
      const UpdateResult res = f.update(meas, 0.0);
      EXPECT_TRUE(res.applied);
      EXPECT_LT(std::abs(res.nis - rr.nis), 1e-9 * (1.0 + rr.nis));
      EXPECT_LT(rel(f.x(), xr), 1e-9);
      EXPECT_LT(rel(f.P(), Pr), 1e-9);
    }
    Ukf<L> u(ImuErrorModel{});
    u.initialize(P0);
    const UpdateResult ru = u.update(meas, 0.0);
    EXPECT_TRUE(ru.applied);
    EXPECT_LT(rel(u.x(), xr), 1e-9);
    EXPECT_LT(rel(u.P(), Pr), 1e-9);
  }
}

void test_cycle_without_heap() {
  std::mt19937 rng(12);
  const auto ivs = make_intervals(50);
  const LinMeas m6 = make_meas(rng, 6), mn = make_meas(rng, L::kSize);
  RbUkf<L> rb(ImuErrorModel{});
  Ukf<L> uk(ImuErrorModel{});
  rb.initialize(random_spd(rng));
  uk.initialize(random_spd(rng));
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  for (UpdateForm form : {UpdateForm::kDensePaper, UpdateForm::kBlockSparseFactored}) {
    rb.set_update_form(form);
    rb.begin_cycle();
    for (const auto& iv : ivs) rb.propagate(iv);
    rb.end_cycle();
    rb.update(m6, 0.0);
    rb.update(mn, 0.0);
    rb.reset_state();
  }
  uk.begin_cycle();
  for (const auto& iv : ivs) uk.propagate(iv);
  uk.end_cycle();
  uk.update(m6, 0.0);
  uk.reset_state();
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);
}

}  // namespace

int main() {
  test_kernels_equal_the_kalman_update();
  test_cycle_without_heap();
  EXPECT_TRUE(g_eigen_asserts == 0);
  TEST_MAIN_END()
}

// bench/cpp/update_cost.cpp -- cost of one measurement update, for
// bench/update_cost.sh (instruction counts under valgrind --tool=callgrind).
//
//   update_cost KIND N [STATES] [ROWS] [COLS]
// KIND: flops (print the analytic counts of flops.hpp), none (the baseline: everything but the update), ukf, dense_paper,
// dense_joseph, sparse_joseph, sparse_factored.  N updates are run on the same
// P, H, R and residual (the filter is restored from a prototype before each
// one, in the baseline too), so  (instructions(KIND, N) - instructions(none, N)) / N
// is the cost of one update.  STATES: 15 (default), 17 or 21.  ROWS: 6 (default)
// or 3; COLS: non-zero columns of H (default 6: H = [I 0]; otherwise a dense
// random block of that width).  h(dx) = H_c dx_c (the UKF evaluates it at every
// augmented point; the RB-UKF once, at the mean).
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <vector>

#include "insnav/core.hpp"
#include "insnav/filter/flops.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"

using namespace insnav;

namespace {

template <class L>
struct BenchMeas {
  LinearMeasurement<L> lin;
  const LinearMeasurement<L>& linear() const { return lin; }
  typename LinearMeasurement<L>::RowVec predicted_residual(const StateVec<L>& dx) const {
    typename LinearMeasurement<L>::RowVec z = lin.H.leftCols(lin.n_cols) * dx.head(lin.n_cols);
    return z;
  }
};

volatile double g_sink = 0.0;

template <class Filter, class Meas>
void loop(const Filter& proto, const Meas& meas, long n, bool do_update) {
  for (long i = 0; i < n; ++i) {
    Filter f = proto;  // same P, x, sigma points every time
    if (do_update) f.update(meas, 0.0);
    g_sink = g_sink + f.x()[0] + f.P()(0, 0);
  }
}

template <class L>
int run(const char* kind, long n, int rows, int cols) {
  constexpr int N = L::kSize;
  std::mt19937 rng(1);
  std::normal_distribution<double> nd;
  ImuErrorModel model;
  // one filter cycle so that P is a realistic full matrix and the UKF has its
  // propagated points and cycle Q
  NavState s;
  s.lat = 0.6;
  s.h = 100.0;
  s.v_n = Vec3(15.0, -3.0, 0.0);
  s.q_nb = quat_from_euler(Vec3(0.05, -0.03, 1.0));
  Strapdown ins(s);
  const Vec3 w_b(0.02, -0.01, 0.1), f_b(1.0, 0.5, -9.79);
  std::vector<InsInterval> ivs(50);
  auto point = [&](InsPoint& p) {
    const NavState& q = ins.state();
    p.set(q.lat, q.h, q.v_n, q.q_nb.toRotationMatrix(), f_b, w_b);
  };
  InsPoint start;
  point(start);
  for (auto& iv : ivs) {
    iv.start = start;
    for (int j = 1; j <= 2; ++j) {
      ImuIncrement imu;
      imu.dt = 0.01;
      imu.t = ins.state().t + imu.dt;
      imu.dtheta_b = w_b * imu.dt;
      imu.dv_b = f_b * imu.dt;
      ins.update(imu);
      if (j == 1) point(iv.mid);
    }
    point(iv.end);
    iv.dt = 0.02;
    start = iv.end;
  }
  StateVec<L> sig = StateVec<L>::Constant(1e-3);
  sig.template segment<3>(L::kPos) = Vec3(5, 5, 10);
  sig.template segment<3>(L::kVel) = Vec3::Constant(0.2);
  sig.template segment<3>(L::kAtt) = Vec3::Constant(0.02);
  const StateCov<L> P0 = sig.cwiseAbs2().asDiagonal();

  BenchMeas<L> meas;
  meas.lin.residual.resize(rows);
  meas.lin.H.setZero(rows, N);
  meas.lin.R.setZero(rows, rows);
  for (int i = 0; i < rows; ++i) {
    meas.lin.residual[i] = nd(rng);
    meas.lin.R(i, i) = i < 3 ? 25.0 : 0.04;
    if (cols == 6) meas.lin.H(i, i) = 1.0;
    else
      for (int j = 0; j < cols; ++j) meas.lin.H(i, j) = nd(rng);
  }
  meas.lin.n_cols = cols;

  auto cycle = [&](auto& f) {
    f.initialize(P0);
    f.begin_cycle();
    for (const auto& iv : ivs) f.propagate(iv);
    f.end_cycle();
  };
  if (!std::strcmp(kind, "ukf")) {
    Ukf<L> f(model);
    cycle(f);
    loop(f, meas, n, true);
  } else {
    RbUkf<L> f(model);
    cycle(f);
    bool upd = true;
    if (!std::strcmp(kind, "none")) upd = false;
    else if (!std::strcmp(kind, "dense_paper")) f.set_update_form(UpdateForm::kDensePaper);
    else if (!std::strcmp(kind, "dense_joseph")) f.set_update_form(UpdateForm::kDenseJoseph);
    else if (!std::strcmp(kind, "sparse_joseph")) f.set_update_form(UpdateForm::kBlockSparseJoseph);
    else if (!std::strcmp(kind, "sparse_factored")) f.set_update_form(UpdateForm::kBlockSparseFactored);
    else {
      std::fprintf(stderr, "unknown kind %s\n", kind);
      return 2;
    }
    loop(f, meas, n, upd);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s KIND N [STATES=15] [ROWS=6] [COLS=6]\n", argv[0]);
    return 2;
  }
  const char* kind = argv[1];
  const long n = std::atol(argv[2]);
  const int states = argc > 3 ? std::atoi(argv[3]) : 15;
  const int rows = argc > 4 ? std::atoi(argv[4]) : 6;
  const int cols = argc > 5 ? std::atoi(argv[5]) : 6;
  if (rows < 1 || rows > kMaxMeasRows || cols < 1 || cols > states) return 2;
  if (!std::strcmp(kind, "flops")) {  // the analytic counts of flops.hpp for this configuration
    const double m = states, r = rows, c = cols;
    std::printf("ukf %.0f dense_paper %.0f dense_joseph %.0f sparse_joseph %.0f sparse_factored %.0f "
                "paper_ukf %.0f paper_rbukf %.0f\n",
                flops::ukf_update(m, r, c), flops::rbukf_dense_paper(m, r), flops::rbukf_dense_joseph(m, r),
                flops::rbukf_block_sparse_joseph(m, r, c), flops::rbukf_block_sparse_factored(m, r, c),
                flops::ukf_update_paper(m, r), flops::rbukf_update_paper(m, r));
    return 0;
  }
  switch (states) {
    case 15: return run<Layout15>(kind, n, rows, cols);
    case 17: return run<Layout17>(kind, n, rows, cols);
    case 21: return run<Layout21>(kind, n, rows, cols);
    default: std::fprintf(stderr, "STATES must be 15, 17 or 21\n"); return 2;
  }
}

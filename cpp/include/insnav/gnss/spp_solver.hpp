// insnav/gnss/spp_solver.hpp -- single point positioning of a batch of epochs:
// weighted Gauss-Newton least squares for position, receiver clock and one
// inter-system bias per further system, RAIM fault detection and exclusion,
// then velocity and clock drift from the rates with the same tests.
//
// The C++ twin of python/insnav/gnss/spp.py (``solve_spp``; the Python loop
// there is the reference of tests/test_spp.py, which compares the two on real
// data).  Model of one epoch (Misra & Enge, *Global Positioning System*, 2nd
// ed., sec. 6.1; Groves 2013, eq. (9.141) for several systems):
//
//   rho_i  = |r_s,i - r| + b + ISB_sys(i) - clk_s,i + e_i,   e_i ~ N(0, sigma_i^2)
//   rhod_i = u_i . (v_s,i - v) + d - clkdot_s,i
//
// RAIM: global test v^T W v against the 1 - alpha quantile of chi^2 with
// n - p degrees of freedom, local tests w_i = |v_i| / sqrt((Q_v)_ii) with
// Q_v = W^-1 - H (H^T W H)^-1 H^T, the largest excluded while the redundancy
// allows (Baarda 1968; Kuusniemi 2005, sec. 4.2, eqs. (4.7)-(4.12)).
//
// Frames: e = ECEF, n = NED at the solution.  SI throughout.  Nothing is
// allocated per epoch: an epoch holds at most kSppMaxRows rows (the caller
// checks; solve_spp_batch returns Status::kBadInput otherwise).
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "insnav/check.hpp"
#include "insnav/earth/wgs84.hpp"
#include "insnav/gnss/code_position_fit.hpp"

namespace insnav::gnss {

// Systems in the order of their index (GPS first: the reference clock when present): kSppNumSystems
// (code_position_fit.hpp).  Not named kSppNumSystems: gnss/double_difference.hpp's RtkSystem has that
// name for its five systems (QZSS apart), and a program may include both.

/// Columns of a row of the flat satellite table (TightInputs.sats, python/insnav/gnss/tight_inputs.py).
struct SppRowLayout {
  static constexpr int kPseudorange = 0;   // [m]
  static constexpr int kRate = 1;          // [m/s]
  static constexpr int kSatPos = 2;        // r_s ECEF at reception [m], 3 columns
  static constexpr int kSatVel = 5;        // v_s [m/s], 3 columns
  static constexpr int kSatClock = 8;      // c dt_sv minus modelled delays [m]
  static constexpr int kSatClockRate = 9;  // [m/s]
  static constexpr int kCols = 12;
};

/// RAIM status of an epoch (python: insnav.gnss.spp.RAIM_STATUS).
enum class RaimStatus : std::int8_t { kPassed = 0, kExcluded = 1, kFailed = 2, kUntested = 3, kNoSolution = 4 };

struct SppOptions {
  bool raim = true;
  double raim_alpha = 1e-3;  // false-alarm probability of the global test
  int max_exclusions = -1;   // -1: as many as the redundancy allows
  int min_sats = 4;
  int iterations = 10;       // Gauss-Newton, converged at a position step below 0.1 mm
  bool velocity = true;
  bool warm_start = true;    // start each epoch from the previous solution
};

// ----------------------------------------------------------------- chi-square quantile

/// Regularized lower incomplete gamma P(a, x): series for x < a + 1, else the continued
/// fraction (Press et al., *Numerical Recipes*, 3rd ed., sec. 6.2); the same operations as
/// insnav.gnss.spp._gammp.
inline double gammp(double a, double x) {
  if (x <= 0.0) return 0.0;
  const double gln = std::lgamma(a);
  if (x < a + 1.0) {
    double ap = a, s = 1.0 / a, d = 1.0 / a;
    for (int i = 0; i < 1000; ++i) {
      ap += 1.0;
      d *= x / ap;
      s += d;
      if (std::abs(d) < std::abs(s) * 1e-15) break;
    }
    return s * std::exp(-x + a * std::log(x) - gln);
  }
  double b = x + 1.0 - a;
  double c = 1.0 / 1e-300;
  double d = 1.0 / b;
  double h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    d = std::abs(d) < 1e-300 ? 1e-300 : d;
    c = b + an / c;
    c = std::abs(c) < 1e-300 ? 1e-300 : c;
    d = 1.0 / d;
    h *= d * c;
    if (std::abs(d * c - 1.0) < 1e-15) break;
  }
  return 1.0 - std::exp(-x + a * std::log(x) - gln) * h;
}

/// x with P(chi^2_dof <= x) = p: bisection on gammp to a relative 1e-12 (insnav.gnss.spp.chi2_quantile).
inline double chi2_quantile(double p, int dof) {
  const double k = 0.5 * dof;
  double lo = 0.0, hi = std::max(10.0, 4.0 * dof);
  while (gammp(k, 0.5 * hi) < p) hi *= 2.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (gammp(k, 0.5 * mid) < p)
      lo = mid;
    else
      hi = mid;
    if (hi - lo < 1e-12 * hi) break;
  }
  return 0.5 * (lo + hi);
}

// ----------------------------------------------------------------- fixed-capacity types

using SppParMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kSppMaxParams, kSppMaxParams>;
using SppRowsBy4 = Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::ColMajor, kSppMaxRows, 4>;
using SppParByRows = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kSppMaxParams, kSppMaxRows>;

/// Input of solve_spp_batch: M rows in E epochs (all pointers to C-contiguous arrays).
struct SppBatchInput {
  std::int64_t n_epochs = 0;
  const std::int64_t* epoch_start = nullptr;  // (E+1,) epoch e owns rows [epoch_start[e], epoch_start[e+1])
  const double* sats = nullptr;               // (M, SppRowLayout::kCols)
  const double* sigma_pr_m = nullptr;         // (M,) 1-sigma pseudorange [m]
  const double* sigma_prr_mps = nullptr;      // (M,) 1-sigma rate [m/s]
  const std::int8_t* system = nullptr;        // (M,) index 0..kSppNumSystems-1
  Vec3 r0_e = Vec3::Zero();                   // start [m] (first epoch, after an epoch without solution)
};

/// Output of solve_spp_batch, preset by the caller to NaN / 0 / kNoSolution (as solve_spp's arrays).
struct SppBatchOutput {
  double* r_e;              // (E, 3)
  double* clock_bias_m;     // (E,)
  double* v_e;              // (E, 3)
  double* clock_drift_mps;  // (E,)
  double* sigma_pos_n_m;    // (E, 3)
  double* sigma_vel_n_mps;  // (E, 3)
  double* isb_m;            // (E, kSppNumSystems)
  double* sigma_isb_m;      // (E, kSppNumSystems)
  double* cov_r_e;          // (E, 3, 3)
  double* cov_v_e;          // (E, 3, 3)
  double* sigma_clock_m;    // (E,)
  double* sigma_drift_mps;  // (E,)
  double* gdop;             // (E,)
  double* pdop;
  double* hdop;
  double* vdop;
  double* tdop;
  double* chi2;             // (E,)
  double* chi2_threshold;   // (E,)
  std::int64_t* n_sats;     // (E,)
  std::int64_t* n_used;
  std::int64_t* n_excluded;
  std::int64_t* n_rate_used;
  std::int64_t* n_rate_excluded;
  std::int8_t* raim_status;  // (E,)
  std::int8_t* ref_system;   // (E,) index, -1 without a solution
  std::uint8_t* row_excluded;       // (M,)
  std::uint8_t* rate_row_excluded;  // (M,)
};

namespace detail {

/// chi^2 quantiles of one batch (computed on first use per degree of freedom).
struct Chi2Table {
  double p;
  double q[kSppMaxRows + 1];
  explicit Chi2Table(double p_) : p(p_) {
    for (double& v : q) v = std::numeric_limits<double>::quiet_NaN();
  }
  double operator()(int dof) {
    if (std::isnan(q[dof])) q[dof] = chi2_quantile(p, dof);
    return q[dof];
  }
};

/// Baarda's local statistics w_i = |v_i| / sqrt(Q_v,ii) (0 where the redundancy number is ~0)
/// and v^T W v; false when H^T W H is not positive definite.
template <class HMat>
inline bool w_test(const HMat& H, const SppRowsVec& w, const SppRowsVec& v, SppRowsVec& wt, double& chi2) {
  const int n = static_cast<int>(H.rows());
  SppParMat N = (w.asDiagonal() * H).transpose() * (w.asDiagonal() * H);
  chi2 = (v.array() * w.array()).square().sum();
  Eigen::LLT<SppParMat> llt(N);
  if (llt.info() != Eigen::Success) return false;
  // H N^-1 H^T = B^T B with B = L^-1 H^T
  SppParByRows B = H.transpose();
  llt.matrixL().solveInPlace(B);
  wt.resize(n);
  for (int i = 0; i < n; ++i) {
    const double hii = B.col(i).squaredNorm();
    const double w2 = 1.0 / (w[i] * w[i]);
    const double qv = w2 - hii;
    wt[i] = qv > 1e-9 * w2 ? std::abs(v[i]) / std::sqrt(std::max(qv, 1e-300)) : 0.0;
  }
  return true;
}

/// Index of the first largest entry (numpy argmax).
inline int argmax(const SppRowsVec& a) {
  int k = 0;
  for (int i = 1; i < a.size(); ++i)
    if (a[i] > a[k]) k = i;
  return k;
}


/// The row whose omission gives the smallest weighted residual sum among the fits that converge, or
/// -1 (the fault exclusion of RTKLIB raim_fde for an epoch whose full fit does not converge).  Rows
/// as code_position_fit's; H, u, rng, y are scratch.  The Python twin is spp._leave_one_out.
template <class Row>
inline int leave_one_out(int n, int np, const Row& row, const int* col, const SppRowsVec& w, const Eigen::Vector4d& x0,
                         int iterations, SppRowsMat& H, SppRowsBy3& u, SppRowsVec& rng, SppRowsVec& y) {
  int best = -1;
  double best_chi2 = std::numeric_limits<double>::infinity();
  int col_k[kSppMaxRows];
  SppRowsVec w_k(n - 1);
  SppParVec x(np);
  for (int k = 0; k < n; ++k) {
    for (int j = 0, m = 0; j < n; ++j)
      if (j != k) {
        col_k[m] = col[j];
        w_k[m++] = w[j];
      }
    const auto row_k = [&](int j) { return row(j < k ? j : j + 1); };
    x.setZero();
    x.head<4>() = x0;
    if (!code_position_fit(n - 1, np, row_k, col_k, w_k, iterations, x, H, u, rng, y)) continue;
    const double chi2 = y.cwiseProduct(w_k).squaredNorm();
    if (chi2 < best_chi2) {
      best = k;
      best_chi2 = chi2;
    }
  }
  return best;
}

}  // namespace detail

/// Solve every epoch of a batch (see the file comment).  Returns kBadInput when an epoch has
/// more than kSppMaxRows rows or a system index is out of range (nothing is written then).
inline Status solve_spp_batch(const SppBatchInput& in, const SppOptions& opt, SppBatchOutput& out) {
  using L = SppRowLayout;
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  const std::int64_t E = in.n_epochs;
  for (std::int64_t e = 0; e < E; ++e) {
    if (in.epoch_start[e + 1] - in.epoch_start[e] > kSppMaxRows) return Status::kBadInput;
    for (std::int64_t i = in.epoch_start[e]; i < in.epoch_start[e + 1]; ++i)
      if (in.system[i] < 0 || in.system[i] >= kSppNumSystems) return Status::kBadInput;
  }
  detail::Chi2Table chi2_q(1.0 - opt.raim_alpha);
  auto row = [&](std::int64_t i) { return in.sats + i * L::kCols; };

  // state carried between epochs: (x, y, z, reference clock)
  Eigen::Vector4d x_prev;
  x_prev << in.r0_e, 0.0;
  const Eigen::Vector4d x_reset = x_prev;

  int rows[kSppMaxRows];
  int excluded[kSppMaxRows];
  SppRowsMat H;
  SppRowsBy3 u;
  SppRowsVec rng, w, y, v, wt;
  SppParVec x;

  for (std::int64_t e = 0; e < E; ++e) {
    const std::int64_t a = in.epoch_start[e], b = in.epoch_start[e + 1];
    int n = 0;
    std::int64_t n_finite = 0;
    for (std::int64_t i = a; i < b; ++i) {
      const double pr = row(i)[L::kPseudorange], s = in.sigma_pr_m[i];
      if (std::isfinite(pr)) ++n_finite;
      if (std::isfinite(pr) && std::isfinite(s) && s > 0.0) rows[n++] = static_cast<int>(i - a);
    }
    out.n_sats[e] = n_finite;
    int n_excl = 0;
    Eigen::Vector4d x0 = opt.warm_start ? x_prev : x_reset;

    enum class Fit { kTooFew, kFailed, kOk } fit = Fit::kFailed;
    RaimStatus st = RaimStatus::kUntested;
    double chi2 = kNaN, thr = kNaN;
    int col[kSppMaxRows];
    int n_clk = 0;
    int letters[kSppNumSystems];  // system index of clock column k (0: reference)
    while (true) {
      // clock columns: the reference is the first system present (in index order), then the others
      bool present[kSppNumSystems] = {false, false, false, false};
      for (int k = 0; k < n; ++k) present[in.system[a + rows[k]]] = true;
      n_clk = 0;
      int col_of_sys[kSppNumSystems] = {0, 0, 0, 0};
      for (int s = 0; s < kSppNumSystems; ++s)
        if (present[s]) {
          col_of_sys[s] = n_clk;
          letters[n_clk++] = s;
        }
      const int p = n > 0 ? 3 + n_clk : 4;
      if (n < std::max(opt.min_sats, p)) {
        fit = Fit::kTooFew;
        break;
      }
      for (int k = 0; k < n; ++k) col[k] = col_of_sys[in.system[a + rows[k]]];
      const int np = 3 + n_clk;
      w.resize(n);
      for (int k = 0; k < n; ++k) w[k] = 1.0 / in.sigma_pr_m[a + rows[k]];
      // Gauss-Newton from x0: position and reference clock, inter-system biases from 0
      x.setZero(np);
      x.head<4>() = x0;
      const auto fit_row = [&](int k) {
        const double* s = row(a + rows[k]);
        return CodeFitRow{Vec3(s[L::kSatPos], s[L::kSatPos + 1], s[L::kSatPos + 2]), s[L::kPseudorange],
                                  s[L::kSatClock]};
      };
      if (!code_position_fit(n, np, fit_row, col, w, opt.iterations, x, H, u, rng, y)) {
        // a gross row can keep Gauss-Newton from converging: leave out the row whose omission fits
        // best (RTKLIB raim_fde) and start again; the RAIM tests then judge the rest
        const bool may_exclude = opt.raim && n - 1 - np >= 1 && !(opt.max_exclusions >= 0 && opt.max_exclusions <= n_excl);
        const int k = may_exclude ? detail::leave_one_out(n, np, fit_row, col, w, x0, opt.iterations, H, u, rng, y) : -1;
        if (k >= 0) {
          excluded[n_excl++] = rows[k];
          for (int j = k; j < n - 1; ++j) rows[j] = rows[j + 1];
          --n;
          continue;
        }
        fit = Fit::kFailed;
        break;
      }
      v = y;  // residuals at the solution
      fit = Fit::kOk;
      const int dof = n - np;
      if (dof < 1) {
        st = RaimStatus::kUntested;
        chi2 = thr = kNaN;
        break;
      }
      const bool wt_ok = detail::w_test(H, w, v, wt, chi2);
      if (!wt_ok) chi2 = kNaN;
      thr = chi2_q(dof);
      if (!opt.raim) {
        st = RaimStatus::kUntested;
        break;
      }
      if (!wt_ok) {
        fit = Fit::kFailed;
        break;
      }
      if (chi2 <= thr) {
        st = n_excl > 0 ? RaimStatus::kExcluded : RaimStatus::kPassed;
        break;
      }
      if (dof < 2 || (opt.max_exclusions >= 0 && opt.max_exclusions <= n_excl)) {
        st = RaimStatus::kFailed;
        break;
      }
      const int k = detail::argmax(wt);
      excluded[n_excl++] = rows[k];
      for (int j = k; j < n - 1; ++j) rows[j] = rows[j + 1];
      --n;
      x0 = x.head<4>();
    }
    if (fit == Fit::kTooFew) continue;
    if (fit == Fit::kFailed) {
      x_prev = x_reset;
      continue;
    }
    const int np = 3 + n_clk;
    const SppRowsMat Hw = w.asDiagonal() * H;
    const SppParMat Nw = Hw.transpose() * Hw;
    Eigen::LLT<SppParMat> llt(Nw);
    if (llt.info() != Eigen::Success) {
      x_prev = x_reset;
      continue;
    }
    const SppParMat Q = llt.solve(SppParMat::Identity(np, np));
    const Vec3 r = x.head<3>();
    const Vec3 llh = wgs84::ecef_to_geodetic(r);
    const Mat3 C_ne = wgs84::C_en(llh[0], llh[1]).transpose();
    for (int i = 0; i < 3; ++i) out.r_e[3 * e + i] = r[i];
    out.clock_bias_m[e] = x[3];
    const Mat3 Qr = Q.topLeftCorner<3, 3>();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) out.cov_r_e[9 * e + 3 * i + j] = Qr(i, j);
    const Mat3 Qn = C_ne * Qr * C_ne.transpose();
    for (int i = 0; i < 3; ++i) out.sigma_pos_n_m[3 * e + i] = std::sqrt(Qn(i, i));
    out.sigma_clock_m[e] = std::sqrt(Q(3, 3));
    out.isb_m[kSppNumSystems * e + letters[0]] = 0.0;
    out.sigma_isb_m[kSppNumSystems * e + letters[0]] = 0.0;
    for (int k = 1; k < n_clk; ++k) {
      out.isb_m[kSppNumSystems * e + letters[k]] = x[3 + k];
      out.sigma_isb_m[kSppNumSystems * e + letters[k]] = std::sqrt(Q(3 + k, 3 + k));
    }
    // DOPs from the unweighted geometry in NED
    {
      SppRowsMat Hn = H;
      Hn.leftCols<3>() = -(u * C_ne.transpose());
      Eigen::LLT<SppParMat> lln(Hn.transpose() * Hn);
      if (lln.info() == Eigen::Success) {
        const SppParMat Qd = lln.solve(SppParMat::Identity(np, np));
        out.pdop[e] = std::sqrt(Qd(0, 0) + Qd(1, 1) + Qd(2, 2));
        out.gdop[e] = std::sqrt(Qd.diagonal().sum());
        out.hdop[e] = std::sqrt(Qd(0, 0) + Qd(1, 1));
        out.vdop[e] = std::sqrt(Qd(2, 2));
        out.tdop[e] = std::sqrt(Qd(3, 3));
      }
    }
    out.chi2[e] = chi2;
    out.chi2_threshold[e] = thr;
    out.raim_status[e] = static_cast<std::int8_t>(st);
    out.ref_system[e] = static_cast<std::int8_t>(letters[0]);
    out.n_used[e] = n;
    out.n_excluded[e] = n_excl;
    for (int k = 0; k < n_excl; ++k) out.row_excluded[a + excluded[k]] = 1;
    x_prev = x.head<4>();
    if (!opt.velocity) continue;

    // velocity and drift from the rates of the rows kept, with their own FDE
    int idx[kSppMaxRows];
    int m = 0;
    for (int k = 0; k < n; ++k) {
      const std::int64_t i = a + rows[k];
      const double sr = in.sigma_prr_mps[i];
      if (std::isfinite(row(i)[L::kRate]) && std::isfinite(sr) && sr > 0.0) idx[m++] = k;
    }
    int n_rx = 0;
    bool have = true;
    SppRowsBy4 Hv;
    SppRowsVec wr, yv;
    Eigen::Vector4d sol;
    while (true) {
      if (m < std::max(opt.min_sats, 4)) {
        have = false;
        break;
      }
      Hv.resize(m, 4);
      wr.resize(m);
      yv.resize(m);
      for (int j = 0; j < m; ++j) {
        const std::int64_t i = a + rows[idx[j]];
        const double* s = row(i);
        Hv.block<1, 3>(j, 0) = -u.row(idx[j]);
        Hv(j, 3) = 1.0;
        wr[j] = 1.0 / in.sigma_prr_mps[i];
        yv[j] = s[L::kRate] -
                (u(idx[j], 0) * s[L::kSatVel] + u(idx[j], 1) * s[L::kSatVel + 1] + u(idx[j], 2) * s[L::kSatVel + 2]) +
                s[L::kSatClockRate];
      }
      const SppRowsBy4 Hvw = wr.asDiagonal() * Hv;
      sol = Eigen::CompleteOrthogonalDecomposition<SppRowsBy4>(Hvw).solve(SppRowsVec(yv.cwiseProduct(wr)));
      const int dof = m - 4;
      if (!opt.raim || dof < 2 || (opt.max_exclusions >= 0 && opt.max_exclusions <= n_rx)) break;
      const SppRowsVec res = yv - Hv * sol;
      double chi2_v = 0.0;
      if (!detail::w_test(Hv, wr, res, wt, chi2_v) || chi2_v <= chi2_q(dof)) break;
      const int k = detail::argmax(wt);
      out.rate_row_excluded[a + rows[idx[k]]] = 1;
      for (int j = k; j < m - 1; ++j) idx[j] = idx[j + 1];
      --m;
      ++n_rx;
    }
    if (!have) continue;
    const SppRowsBy4 Hvw = wr.asDiagonal() * Hv;
    Eigen::LLT<Eigen::Matrix4d> llv(Hvw.transpose() * Hvw);
    if (llv.info() != Eigen::Success) continue;
    const Eigen::Matrix4d Qv = llv.solve(Eigen::Matrix4d::Identity());
    for (int i = 0; i < 3; ++i) out.v_e[3 * e + i] = sol[i];
    out.clock_drift_mps[e] = sol[3];
    const Mat3 Qvr = Qv.topLeftCorner<3, 3>();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) out.cov_v_e[9 * e + 3 * i + j] = Qvr(i, j);
    const Mat3 Qvn = C_ne * Qvr * C_ne.transpose();
    for (int i = 0; i < 3; ++i) out.sigma_vel_n_mps[3 * e + i] = std::sqrt(Qvn(i, i));
    out.sigma_drift_mps[e] = std::sqrt(Qv(3, 3));
    out.n_rate_used[e] = m;
    out.n_rate_excluded[e] = n_rx;
  }
  return Status::kOk;
}

}  // namespace insnav::gnss

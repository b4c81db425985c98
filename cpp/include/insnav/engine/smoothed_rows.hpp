// insnav/engine/smoothed_rows.hpp -- the RTS smoother's result on the output
// rows of a closed-loop run.
//
// The backward pass (filter/rts_smoother.hpp) gives, per filter epoch k, the
// smoothed error s_k of the post-feedback nominal m_k.  Between two epochs the
// output rows are the nominal INS corrected by the filter's running estimate
// (zero after every feedback; after an epoch without feedback, e.g. in an
// outage, the propagated mean of a sigma-point filter).  The smoothed row is
// that row corrected by the difference (rts_smoother.hpp's symbols):
//   d_k     = s_k - r_k                          just after epoch k
//   d_end_k = s_k + fed_k x_k - xp_k             just before epoch k
// where xp_k is the filter's own prediction, the estimate the rows carried
// (SmootherEpoch::x_rows), not the smoother's: a fix not fed back
// (continuous ambiguity resolution) or a TDCP clone update changes the latter
// only (closed_loop.hpp condition_for_smoother, clone_update_for_smoother).
// interpolated linearly in time in between (the error dynamics are slow
// against the 0.1-1 s between epochs; for the EKF r and xp are zero), and
// applied as the feedback is (ins/nav_error.hpp: position, velocity,
// C_nb <- dcm(psi) C_nb).  Columns after the 9 navigation errors (receiver
// clock bias and drift, inter-system biases) are additive: b <- b - d.
// The sigmas sqrt(diag Ps) are interpolated the same way.
//
// Usage (C++): record the forward run (ClosedLoop::record_for_smoother), run
// rts_backward, fill SmoothedErrors with smoothed_row_errors() per epoch, then
// smooth_nav_rows() over the run's output rows (any strides, radians or
// degrees).  python/insnav/filters/smoothing.py is this through _core.smooth_rows.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <thread>
#include <vector>

#include "insnav/filter/rts_smoother.hpp"
#include "insnav/ins/nav_error.hpp"

namespace insnav {

/// The row corrections of epoch k (the file comment): d (just after the
/// epoch) and d_end (just before it), each L::kSize values.  prev_x_pred: whether
/// the epoch has a prediction from an earlier one (k > 0).
template <class L>
void smoothed_row_errors(const SmootherEpoch<L>& f, const SmoothedEpoch<L>& b, bool has_prediction, double* d,
                         double* d_end) {
  for (int j = 0; j < L::kSize; ++j) {
    d[j] = f.fed_back ? b.s[j] : b.s[j] - f.x[j];
    d_end[j] = (f.fed_back ? b.s[j] + f.x[j] : b.s[j]) - (has_prediction ? f.x_rows[j] : 0.0);
  }
}

/// The smoothed errors of E >= 2 epochs, row-major (E, cols): columns 0-8 the
/// navigation errors (position N, E, D [m], velocity [m/s], attitude [rad]),
/// then cols - 9 additive states; sigma in any units (interpolated only).
struct SmoothedErrors {
  std::int64_t n_epochs = 0;
  int cols = 9;
  const double* t = nullptr;      // (E,) epoch times [s], increasing
  const double* d = nullptr;      // (E, cols) correction of the rows from the epoch on
  const double* d_end = nullptr;  // (E, cols) correction of the rows just before the epoch
  const double* sigma = nullptr;  // (E, cols)
};

/// A column of doubles with a stride in elements (a field of an array of rows).
struct StridedColumn {
  double* p = nullptr;
  std::ptrdiff_t stride = 1;
  double& operator[](std::int64_t i) const { return p[i * stride]; }
};

/// A matrix of doubles with row and column strides in elements.
struct StridedMatrix {
  double* p = nullptr;
  std::ptrdiff_t row_stride = 0, col_stride = 1;
  double& operator()(std::int64_t i, std::int64_t j) const { return p[i * row_stride + j * col_stride]; }
};

/// The output rows corrected in place.  Angles (lat, lon, roll, pitch, yaw)
/// in the unit given by to_rad / from_rad: radians (1, 1, the engines' rows)
/// or degrees (pi/180, 180/pi, insnav's solution).
struct NavRowsRef {
  std::int64_t n = 0;
  const double* t = nullptr;  // (n,) [s], sorted
  StridedColumn lat, lon, h;  // h [m]
  StridedMatrix v_n;          // (n, 3) [m/s]
  StridedColumn roll, pitch, yaw;
  StridedMatrix sigma;  // (n, cols) written: the interpolated sigmas
  StridedMatrix extra;  // (n, cols - 9): the additive states (receiver clock, ISBs), corrected
  double to_rad = 1.0, from_rad = 1.0;
};

inline constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
inline constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

/// Rows [i_begin, i_end) of `rows` smoothed with the errors `e` (the file
/// comment).  A row at or after the last epoch gets the last epoch's d.  No
/// allocation; rows are independent (any split over threads gives the same bits).
inline void smooth_nav_rows(const SmoothedErrors& e, const NavRowsRef& rows, std::int64_t i_begin,
                            std::int64_t i_end) {
  const std::int64_t E = e.n_epochs;
  const int c = e.cols, q = c - 9;
  const double *pt = rows.t, *pe = e.t, *ps = e.d, *pse = e.d_end, *pg = e.sigma;
  std::int64_t k = 0;  // epoch interval [te[k], te[k+1]) holding the row
  if (i_begin < i_end) {
    const std::int64_t idx = std::lower_bound(pe, pe + E, pt[i_begin]) - pe;  // pe[idx] >= t
    k = std::min<std::int64_t>(std::max<std::int64_t>(idx - 1, 0), E - 2);
  }
  // blocks of kBlock rows in three passes (interpolation; position and velocity; attitude):
  // the short passes let the rows' sqrt / division chains overlap (the same arithmetic per row)
  constexpr std::int64_t kBlock = 32;
  double X[kBlock][9];
  for (std::int64_t i0 = i_begin; i0 < i_end; i0 += kBlock) {
    const std::int64_t m = std::min(kBlock, i_end - i0);
    for (std::int64_t b = 0; b < m; ++b) {
      const std::int64_t i = i0 + b;
      double* x = X[b];
      const double ti = pt[i];
      while (k + 2 < E && pe[k + 1] < ti) ++k;  // ti in (te[k], te[k+1]]
      const double t0 = pe[k], t1 = pe[k + 1];
      const double w = t1 > t0 ? std::min(1.0, std::max(0.0, (ti - t0) / (t1 - t0))) : 1.0;
      // a row at t_{k+1} (or after the last epoch) is written after that epoch's feedback: d_{k+1};
      // before it, d_end_{k+1}
      const double* end = ti > t1 - 1e-9 ? ps + c * (k + 1) : pse + c * (k + 1);
      const double* beg = ps + c * k;
      for (int j = 0; j < c; ++j) rows.sigma(i, j) = (1.0 - w) * pg[c * k + j] + w * pg[c * (k + 1) + j];
      for (int j = 0; j < 9; ++j) x[j] = (1.0 - w) * beg[j] + w * end[j];
      for (int j = 0; j < q; ++j) rows.extra(i, j) -= (1.0 - w) * beg[9 + j] + w * end[9 + j];
    }
    for (std::int64_t b = 0; b < m; ++b) {
      const std::int64_t i = i0 + b;
      const double* x = X[b];
      const double lat = rows.lat[i] * rows.to_rad;
      double sin_lat, cos_lat;
      sin_cos(lat, sin_lat, cos_lat);
      const LatLonCorrection d = latlon_correction(sin_lat, cos_lat, rows.h[i], x[0], x[1]);
      rows.lat[i] = (lat - d.dlat) * rows.from_rad;
      rows.lon[i] -= d.dlon * rows.from_rad;
      rows.h[i] += x[2];
      for (int j = 0; j < 3; ++j) rows.v_n(i, j) -= x[3 + j];
    }
    for (std::int64_t b = 0; b < m; ++b) {
      const std::int64_t i = i0 + b;
      const double* x = X[b];
      // the row's attitude from the sines and cosines of its half angles; the corrected angles as
      // the row's plus a small difference (euler_from_dcm_near), with the row's sines and cosines
      // from the half angles' (double-angle formulas)
      const Vec3 rpy(rows.roll[i] * rows.to_rad, rows.pitch[i] * rows.to_rad, rows.yaw[i] * rows.to_rad);
      double sh[3], ch[3];
      for (int j = 0; j < 3; ++j) sin_cos(0.5 * rpy[j], sh[j], ch[j]);
      const Quat q_row = quat_from_half_sincos(sh[0], ch[0], sh[1], ch[1], sh[2], ch[2]);
      const Mat3 C = corrected_attitude(Vec3(x[6], x[7], x[8]), q_row).toRotationMatrix();
      Vec3 s_ref, c_ref;
      for (int j = 0; j < 3; ++j) {
        s_ref[j] = 2.0 * sh[j] * ch[j];
        c_ref[j] = (ch[j] - sh[j]) * (ch[j] + sh[j]);
      }
      const Vec3 out = euler_from_dcm_near(C, rpy, s_ref, c_ref);
      rows.pitch[i] = out.y() * rows.from_rad;
      rows.roll[i] = out.x() * rows.from_rad;
      rows.yaw[i] = out.z() * rows.from_rad;
    }
  }
}

/// All rows, split over `threads` threads (1: the calling thread only; the
/// rows' trigonometry dominates, ~0.25 us a row).  e.n_epochs >= 2.
inline void smooth_nav_rows(const SmoothedErrors& e, const NavRowsRef& rows, int threads = 1) {
  const std::int64_t n = rows.n;
  threads = std::max(1, threads);
  std::vector<std::thread> pool;
  const std::int64_t block = (n + threads - 1) / threads;
  for (int th = 1; th < threads; ++th)
    pool.emplace_back([&, th] {
      smooth_nav_rows(e, rows, std::min<std::int64_t>(n, th * block), std::min<std::int64_t>(n, (th + 1) * block));
    });
  smooth_nav_rows(e, rows, 0, std::min<std::int64_t>(n, block));
  for (auto& t : pool) t.join();
}

}  // namespace insnav

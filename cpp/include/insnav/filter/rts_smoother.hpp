// insnav/filter/rts_smoother.hpp -- Rauch-Tung-Striebel fixed-interval
// smoother for the closed-loop error-state filters (backward pass).
//
// Rauch, Tung, Striebel (1965), "Maximum likelihood estimates of linear
// dynamic systems", AIAA J. 3(8); the error-state / closed-loop form as in
// Groves (2013) sec. 3.4.2 and the unscented form of Sarkka (2008),
// "Unscented Rauch-Tung-Striebel smoother", IEEE TAC 53(3), eqs. (13)-(15).
//
// Forward pass (the engine records one SmootherEpoch per filter epoch k, at
// the end of its cycle, after the measurement update and before feedback):
//   n_k      the INS (nominal) solution at epoch k, before feedback
//   x_k      the filter's error estimate of n_k after the update
//            (error = computed - true, layout.hpp)
//   fed_k    whether x_k was fed back (closed loop): the nominal the next
//            cycle starts from is m_k = n_k - x_k, and what remains of the
//            estimate is r_k = 0; otherwise m_k = n_k and r_k = x_k
//   P_k      covariance of x_k (posterior)
//   and for the step k -> k+1 (stored with epoch k + 1):
//   xp_{k+1} predicted mean of the error of n_{k+1} (= Phi r_k for the EKF)
//   Pp_{k+1} predicted covariance
//   C_{k+1}  cross-covariance cov(error of m_k, predicted error of n_{k+1}):
//            P_k Phi' for the EKF (Phi the transition over the cycle), the
//            UT cross-covariance for the RB-UKF / UKF (Sarkka eq. (13))
//
//   c_k      a correction of the estimate of the error of m_k that the
//            forward pass did not feed back (zero unless an engine sets it,
//            ClosedLoop::condition_for_smoother / clone_update_for_smoother):
//            the integer-fixed solution of an RTK/INS epoch, or the clone's
//            side of a TDCP update at epoch k + 1; P_k is then the covariance
//            of r_k + c_k
//
// Backward pass, in terms of s_k = smoothed error of the post-feedback
// nominal m_k (the filtered output at epoch k is m_k - r_k; the smoothed one
// is m_k - s_k):
//   s_N  = r_N + c_N,           Ps_N = P_N
//   A_k  = C_{k+1} Pp_{k+1}^-1                                (gain, via LLT)
//   s_k  = r_k + c_k + A_k (s_{k+1} + fed_{k+1} x_{k+1} - xp_{k+1})
//   Ps_k = P_k + A_k (Ps_{k+1} - Pp_{k+1}) A_k'
// This is the backward kernel p(x_k | x_{k+1}, data up to the step k -> k+1)
// of the fixed-interval smoother (Rauch, Tung & Striebel 1965; Groves 2013
// sec. 3.4.2): (r_k + c_k, P_k) the estimate of x_k and (xp_{k+1}, Pp_{k+1},
// C_{k+1}) the joint moments with x_{k+1}, all given the same data.  For a
// measurement of x_k alone that is the filtered estimate and the prediction;
// a relative measurement of (x_k, x_{k+1}) (TDCP by stochastic cloning)
// updates all five moments jointly, and the kernel stays exact because later
// measurements depend on x_k only through x_{k+1}.
// (s_{k+1} + fed_{k+1} x_{k+1} is the smoothed error of n_{k+1}, the point
// the prediction xp_{k+1} refers to.)  With fed = 0 throughout and linear
// dynamics this is the textbook RTS smoother; with feedback it is the same
// estimate expressed about the corrected nominal (the linear closed-loop and
// open-loop filters are equal), which the tests check against a batch
// least-squares solution.
//
// Memory: sizeof(SmootherEpoch<L>) per filter epoch (3 n x n + 5 n doubles:
// 11.4 kB for 21 states, 41 MB per hour at 1 Hz), allocated by the caller
// once for the whole run; the backward pass allocates nothing.
#pragma once

#include <Eigen/Cholesky>
#include <cstdint>

#include "insnav/filter/types.hpp"

namespace insnav {

/// What the forward pass records at filter epoch k (see the file comment).
template <class L>
struct SmootherEpoch {
  double t = 0.0;
  StateVec<L> x = StateVec<L>::Zero();        // posterior error estimate of n_k (before feedback)
  StateCov<L> P = StateCov<L>::Zero();        // its covariance
  bool fed_back = false;                      // x was fed back into the nominal
  // prediction from the previous epoch to this one (unused at k = 0)
  StateVec<L> x_pred = StateVec<L>::Zero();   // predicted error of n_k
  StateCov<L> P_pred = StateCov<L>::Zero();   // its covariance
  StateCov<L> C = StateCov<L>::Zero();        // cov(error of m_{k-1}, predicted error of n_k)
  StateVec<L> x_cond = StateVec<L>::Zero();   // c_k: correction of the error of m_k not fed back
  // the filter's own predicted mean, the running estimate the output rows carried just before epoch k:
  // x_pred before the smoother's conditioning (a fix not fed back) or clone update (TDCP) changed it
  // (engine/smoothed_rows.hpp d_end)
  StateVec<L> x_rows = StateVec<L>::Zero();
};

/// Result per epoch: the smoothed error s_k of the post-feedback nominal
/// m_k (smoothed solution = m_k - s_k) and its covariance.
template <class L>
struct SmoothedEpoch {
  StateVec<L> s = StateVec<L>::Zero();
  StateCov<L> P = StateCov<L>::Zero();
};

/// Status of the backward pass: number of epochs whose predicted covariance
/// was not positive definite (the gain is then zero: the filtered value is kept).
struct SmootherStatus {
  int gain_failures = 0;
};

/// RTS backward pass over `n` recorded epochs (fwd[0..n-1], time order) into
/// out[0..n-1].  No allocation.
template <class L>
SmootherStatus rts_backward(const SmootherEpoch<L>* fwd, std::int64_t n, SmoothedEpoch<L>* out) {
  using Cov = StateCov<L>;
  using Vec = StateVec<L>;
  SmootherStatus st;
  if (n <= 0) return st;
  // r_k + c_k: the estimate of the error of m_k the backward kernel starts from
  const auto remaining = [](const SmootherEpoch<L>& e) -> Vec {
    return e.fed_back ? Vec(e.x_cond) : Vec(e.x + e.x_cond);
  };
  out[n - 1].s = remaining(fwd[n - 1]);
  out[n - 1].P = fwd[n - 1].P;
  Eigen::LLT<Cov> llt;
  Cov A;
  for (std::int64_t k = n - 2; k >= 0; --k) {
    const SmootherEpoch<L>& e = fwd[k];
    const SmootherEpoch<L>& nx = fwd[k + 1];
    llt.compute(nx.P_pred);
    if (llt.info() != Eigen::Success) {
      ++st.gain_failures;
      out[k].s = remaining(e);
      out[k].P = e.P;
      continue;
    }
    A = llt.solve(nx.C.transpose()).transpose();  // C Pp^-1 (Pp symmetric)
    const Vec s_next_n = out[k + 1].s + (nx.fed_back ? Vec(nx.x) : Vec::Zero());
    out[k].s = remaining(e) + A * (s_next_n - nx.x_pred);
    Cov P = e.P + A * (out[k + 1].P - nx.P_pred) * A.transpose();
    out[k].P = 0.5 * (P + P.transpose());
  }
  return st;
}

}  // namespace insnav

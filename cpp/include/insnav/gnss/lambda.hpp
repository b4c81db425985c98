// insnav/gnss/lambda.hpp -- integer least squares for carrier-phase ambiguities (MLAMBDA).
//
// Solves  min_{a in Z^n} (a_hat - a)^T Q^{-1} (a_hat - a)  for the best and
// second-best integer vectors, by the modified LAMBDA method:
//
//   X.-W. Chang, X. Yang, T. Zhou, "MLAMBDA: a modified LAMBDA method for
//   integer least-squares estimation", J. Geodesy 79 (2005) 552-565.
//
//   1. Q = L^T D L (L unit lower triangular, D diagonal; Sec. 2, eq. (2)).
//   2. Reduction (Sec. 3, Algorithm REDUCTION): integer Gauss transformations
//      (eq. (6)) and symmetric permutations (eq. (9)-(12)) give a unimodular
//      Z with Z^T Q Z = L^T D L decorrelated and D sorted (the "decorrelation";
//      |det Z| = 1, so det Q is kept).  Scale-free: k Q gives the same Z and
//      k D (the permutation test's tolerance is relative, kPermuteRelTol).
//   3. Search (Sec. 4, Algorithm SEARCH): depth-first enumeration of the
//      shrinking ellipsoid in the z = Z^T a space with Schnorr-Euchner
//      zig-zag ordering of each level, keeping the m best points.
//   4. a = Z^{-T} z.
//
// Sizes are bounded by kMaxAmbiguities; nothing is allocated on the heap: the
// workspace is a member of Lambda and is reused from one call to the next.
#pragma once

#include <Eigen/Dense>

#include <cmath>
#include <limits>

namespace insnav::gnss {

/// Largest ambiguity vector MLAMBDA handles (bounded sizes, no heap allocation per call).
constexpr int kMaxAmbiguities = 96;

using AmbVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxAmbiguities, 1>;
using AmbMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxAmbiguities, kMaxAmbiguities>;
using AmbCand = Eigen::Matrix<double, Eigen::Dynamic, 2, 0, kMaxAmbiguities, 2>;

enum class LambdaStatus : int { kOk = 0, kNotPositiveDefinite = 1, kTooLarge = 2, kSearchLimit = 3 };

/// MLAMBDA with a reusable workspace (allocate once, e.g. as a member of the RTK engine).
class Lambda {
 public:
  /// Best (column 0) and second-best (column 1) integer vectors of (a_hat, Q) and their
  /// squared norms  s_i = (a_hat - a_i)^T Q^{-1} (a_hat - a_i)  (s(0) <= s(1)).
  LambdaStatus solve(const AmbVec& a_hat, const AmbMat& Q, AmbCand& a_fix, double s[2]) {
    const int n = static_cast<int>(a_hat.size());
    if (n > kMaxAmbiguities) return LambdaStatus::kTooLarge;
    a_fix.resize(n, 2);
    s[0] = s[1] = 0.0;
    nodes_ = 0;
    permutations_ = 0;
    if (n == 0) return LambdaStatus::kOk;
    if (!ldl(Q)) return LambdaStatus::kNotPositiveDefinite;
    Z_.setIdentity(n, n);
    reduction();
    z_hat_.noalias() = Z_.transpose() * a_hat;  // z = Z^T a
    const LambdaStatus st = search(s);
    if (st != LambdaStatus::kOk) return st;
    // a = Z^{-T} z  (solve Z^T a = z with an LU of the unimodular Z)
    lu_.compute(Z_.transpose());
    for (int c = 0; c < 2; ++c) a_fix.col(c) = lu_.solve(zn_.col(c)).array().round().matrix();
    return LambdaStatus::kOk;
  }

  /// Decorrelation only (for tests and diagnostics): Z with Z^T Q Z = L^T D L (Algorithm REDUCTION).
  bool decorrelate(const AmbMat& Q, AmbMat& Z, AmbMat& L, AmbVec& D) {
    nodes_ = 0;
    permutations_ = 0;
    if (!ldl(Q)) return false;
    Z_.setIdentity(Q.rows(), Q.rows());
    reduction();
    Z = Z_;
    L = L_;
    D = D_;
    return true;
  }

  /// Bootstrapped success rate of the (decorrelated) problem of the last solve() or decorrelate():
  ///   P_s = prod_i (2 Phi(1 / (2 sqrt(k D_i))) - 1),  Phi the standard normal distribution,
  /// D_i the conditional variances of the decorrelated ambiguities (P. J. G. Teunissen, "Success
  /// probability of integer GPS ambiguity rounding and bootstrapping", J. Geodesy 72 (1998)
  /// 606-612, eq. (11)) and k a variance factor of the float covariance (k Q: 1 for Q as given; the
  /// decorrelation Z does not depend on k, the D_i scale with it).  It is a lower bound of the
  /// integer least-squares success rate (P. J. G. Teunissen, "An optimality property of the integer
  /// least-squares estimator", J. Geodesy 73 (1999) 587-593), computed from the float covariance
  /// alone: it says whether the float solution is precise enough for any integer to be trusted,
  /// which the ratio test of the data does not.  It is only as good as that covariance: a
  /// configured noise larger than the receiver's makes it a pessimistic bound.
  double bootstrap_success_rate(double variance_factor = 1.0) const {
    double p = 1.0;
    for (int i = 0; i < D_.size(); ++i)  // 2 Phi(x) - 1 = erf(x / sqrt 2)
      p *= std::erf(1.0 / (2.0 * std::sqrt(2.0 * variance_factor * D_(i))));
    return p;
  }

  /// Search-node budget (guards pathological, badly conditioned problems).
  long max_nodes = 10000000;

  /// Search nodes visited by the last solve() (its cost: one per step down, up or along a level
  /// of Algorithm SEARCH) and permutations of its reduction (or of the last decorrelate()).
  long nodes() const { return nodes_; }
  int permutations() const { return permutations_; }

  /// Relative tolerance of the reduction's permutation test del < (1 - tol) D(j+1): it stops rounding
  /// from permuting back and forth, and being relative it keeps the reduction independent of the
  /// scale of Q.  RTKLIB's absolute del + 1e-6 < D(j+1) (lambda.c) stops permuting once the
  /// conditional variances fall below 1e-6 cycles^2, which a phase sigma of 0.1 mm gives
  /// (D ~ 1e-7 .. 1e-5): the ambiguities stay correlated and the search visits 10-100x more nodes
  /// for the same two integer vectors.
  static constexpr double kPermuteRelTol = 1e-6;

 private:
  // Q = L^T diag(D) L, L unit lower triangular, computed from the last row up (Sec. 2).
  bool ldl(const AmbMat& Q) {
    const int n = static_cast<int>(Q.rows());
    A_ = Q;
    L_.setZero(n, n);
    D_.resize(n);
    for (int i = n - 1; i >= 0; --i) {
      D_(i) = A_(i, i);
      if (!(D_(i) > 0.0) || !std::isfinite(D_(i))) return false;
      const double a = std::sqrt(D_(i));
      for (int j = 0; j <= i; ++j) L_(i, j) = A_(i, j) / a;
      for (int j = 0; j <= i - 1; ++j)
        for (int k = 0; k <= j; ++k) A_(j, k) -= L_(i, k) * L_(i, j);
      for (int j = 0; j <= i; ++j) L_(i, j) /= L_(i, i);
    }
    return true;
  }

  // Integer Gauss transformation Z_ij (eq. (6)): zero L(i,j) to within 1/2.
  void gauss(int i, int j) {
    const int n = static_cast<int>(L_.rows());
    const double mu = std::round(L_(i, j));
    if (mu == 0.0) return;
    for (int k = i; k < n; ++k) L_(k, j) -= mu * L_(k, i);
    for (int k = 0; k < n; ++k) Z_(k, j) -= mu * Z_(k, i);
  }

  // Permutation of j and j+1 with the updates of L and D (eq. (9)-(12)).
  void permute(int j, double del) {
    const int n = static_cast<int>(L_.rows());
    const double eta = D_(j) / del;
    const double lam = D_(j + 1) * L_(j + 1, j) / del;
    D_(j) = eta * D_(j + 1);
    D_(j + 1) = del;
    for (int k = 0; k < j; ++k) {
      const double a0 = L_(j, k), a1 = L_(j + 1, k);
      L_(j, k) = -L_(j + 1, j) * a0 + a1;
      L_(j + 1, k) = eta * a0 + lam * a1;
    }
    L_(j + 1, j) = lam;
    for (int k = j + 2; k < n; ++k) std::swap(L_(k, j), L_(k, j + 1));
    for (int k = 0; k < n; ++k) std::swap(Z_(k, j), Z_(k, j + 1));
  }

  // Algorithm REDUCTION (Sec. 3): the Gauss transformations of a column are applied only
  // when the column is new since the last permutation (the "j <= k" test).
  void reduction() {
    const int n = static_cast<int>(L_.rows());
    int j = n - 2, k = n - 2;
    while (j >= 0) {
      if (j <= k)
        for (int i = j + 1; i < n; ++i) gauss(i, j);
      const double del = D_(j) + L_(j + 1, j) * L_(j + 1, j) * D_(j + 1);
      if (del < (1.0 - kPermuteRelTol) * D_(j + 1)) {  // Sec. 3: permute when it lowers D(j+1)
        ++permutations_;
        permute(j, del);
        k = j;
        j = n - 2;
      } else {
        --j;
      }
    }
  }

  static double sgn(double x) { return x <= 0.0 ? -1.0 : 1.0; }

  // Algorithm SEARCH (Sec. 4): the two best points of the ellipsoid, shrinking it as they improve.
  LambdaStatus search(double s_out[2]) {
    const int n = static_cast<int>(L_.rows());
    constexpr int m = 2;
    S_.setZero(n, n);
    dist_.setZero(n);
    zb_.setZero(n);
    z_.setZero(n);
    step_.setZero(n);
    zn_.resize(n, 2);
    double s[m] = {0.0, 0.0};
    int nn = 0, imax = 0;
    double maxdist = std::numeric_limits<double>::infinity();
    int k = n - 1;
    zb_(k) = z_hat_(k);
    z_(k) = std::round(zb_(k));
    double y = zb_(k) - z_(k);
    step_(k) = sgn(y);
    long nodes = 0;
    for (;;) {
      if (++nodes > max_nodes) {
        nodes_ = nodes;
        return LambdaStatus::kSearchLimit;
      }
      const double newdist = dist_(k) + y * y / D_(k);
      if (newdist < maxdist) {
        if (k != 0) {  // move down a level
          --k;
          dist_(k) = newdist;
          for (int i = 0; i <= k; ++i) S_(k, i) = S_(k + 1, i) + (z_(k + 1) - zb_(k + 1)) * L_(k + 1, i);
          zb_(k) = z_hat_(k) + S_(k, k);
          z_(k) = std::round(zb_(k));
          y = zb_(k) - z_(k);
          step_(k) = sgn(y);
        } else {  // a full integer point
          if (nn < m) {
            if (nn == 0 || newdist > s[imax]) imax = nn;
            zn_.col(nn) = z_;
            s[nn++] = newdist;
          } else {
            if (newdist < s[imax]) {
              zn_.col(imax) = z_;
              s[imax] = newdist;
              imax = s[0] > s[1] ? 0 : 1;
            }
            maxdist = s[imax];
          }
          z_(0) += step_(0);  // next candidate of level 0 (zig-zag)
          y = zb_(0) - z_(0);
          step_(0) = -step_(0) - sgn(step_(0));
        }
      } else {  // move up a level
        if (k == n - 1) break;
        ++k;
        z_(k) += step_(k);
        y = zb_(k) - z_(k);
        step_(k) = -step_(k) - sgn(step_(k));
      }
    }
    if (nn < m) {  // fewer than two points (n = 0 never reaches here); duplicate the best
      zn_.col(1) = zn_.col(0);
      s[1] = std::numeric_limits<double>::infinity();
    }
    if (s[0] > s[1]) {
      std::swap(s[0], s[1]);
      const AmbVec t = zn_.col(0);
      zn_.col(0) = zn_.col(1);
      zn_.col(1) = t;
    }
    s_out[0] = s[0];
    s_out[1] = s[1];
    nodes_ = nodes;
    return LambdaStatus::kOk;
  }

  long nodes_ = 0;
  int permutations_ = 0;
  AmbMat A_, L_, Z_, S_;
  AmbVec D_, z_hat_, dist_, zb_, z_, step_;
  AmbCand zn_;
  Eigen::PartialPivLU<AmbMat> lu_{kMaxAmbiguities};
};

}  // namespace insnav::gnss

// LS-VCE sums of the RTK noise estimate (insnav/gnss/noise_vce.hpp) on synthetic double differences
// with the engine's covariance structure (two groups per kind sharing a reference): the normal matrix,
// right-hand side and redundancy numbers of the whitened 3 x 3 form against the dense definition
// N_kl = 1/2 tr(Q_k R Q_l R), l_k = 1/2 y^T R Q_k R y, R = W - W A (A^T W A)^{-1} A^T W
// (Teunissen & Amiri-Simkooei 2008, sec. 3) to 1e-9 relative; the redundancy numbers summing to
// m - 3 per epoch; unusable epochs (rank-deficient A, no phase row) skipped; no heap allocation in
// the accumulation (Eigen's malloc check on).
#include <cstdio>
#include <memory>
#include <random>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/gnss/noise_vce.hpp"
#include "test_util.hpp"

using namespace insnav::gnss;

namespace {

struct Rows {
  std::vector<std::int64_t> epoch;
  std::vector<int> code, group;
  std::vector<double> y, h, var_own, var_ref;
  VceRows view() const {
    VceRows v;
    v.n = static_cast<std::int64_t>(y.size());
    v.epoch = epoch.data();
    v.code = code.data();
    v.group = group.data();
    v.y = y.data();
    v.h = h.data();
    v.var_own = var_own.data();
    v.var_ref = var_ref.data();
    return v;
  }
};

// rows of one epoch: per kind two groups of n_sat satellites, the first of each group the reference
void add_epoch(Rows& r, std::mt19937& gen, std::int64_t e, int n_sat, bool with_code, bool degenerate) {
  std::normal_distribution<double> nd;
  std::uniform_real_distribution<double> ud(1e-6, 2e-5);
  for (int c = 0; c < (with_code ? 2 : 1); ++c)
    for (int g = 0; g < 2; ++g) {
      const double vref = ud(gen) * (c ? 1e4 : 1.0);
      for (int s = 0; s < n_sat; ++s) {
        r.epoch.push_back(e);
        r.code.push_back(c);
        r.group.push_back(g);
        r.y.push_back(nd(gen) * (c ? 0.3 : 0.003));
        for (int i = 0; i < 3; ++i) r.h.push_back(degenerate && i == 2 ? 0.0 : nd(gen));
        r.var_own.push_back(ud(gen) * (c ? 1e4 : 1.0));
        r.var_ref.push_back(vref);
      }
    }
}

// the dense definition for the rows idx of one epoch
void dense(const Rows& r, const std::vector<std::int64_t>& idx, const Eigen::Vector2d& k, Eigen::Matrix2d& N,
           Eigen::Vector2d& l, Eigen::VectorXd& red) {
  const int m = static_cast<int>(idx.size());
  Eigen::MatrixXd A(m, 3), Q[2] = {Eigen::MatrixXd::Zero(m, m), Eigen::MatrixXd::Zero(m, m)};
  Eigen::VectorXd y(m);
  for (int i = 0; i < m; ++i) {
    const auto a = idx[i];
    for (int j = 0; j < 3; ++j) A(i, j) = r.h[3 * a + j];
    y(i) = r.y[a];
    for (int j = 0; j < m; ++j) {
      const auto b = idx[j];
      if (r.code[a] != r.code[b]) continue;
      Q[r.code[a]](i, j) = (r.group[a] == r.group[b] ? r.var_ref[a] : 0.0) + (i == j ? r.var_own[a] : 0.0);
    }
  }
  const Eigen::MatrixXd Qy = k(0) * Q[0] + k(1) * Q[1];
  const Eigen::MatrixXd W = Qy.inverse();
  const Eigen::MatrixXd G = (A.transpose() * W * A).inverse() * A.transpose() * W;
  const Eigen::MatrixXd R = W - W * A * G;
  for (int p = 0; p < 2; ++p) {
    l(p) = 0.5 * y.dot(R * Q[p] * R * y);
    for (int q = 0; q < 2; ++q) N(p, q) = 0.5 * (Q[p] * R * Q[q] * R).trace();
  }
  red = (Eigen::MatrixXd::Identity(m, m) - A * G).diagonal();
}

}  // namespace

int main() {
  std::mt19937 gen(7);
  Rows r;
  const int n_ep = 12;
  for (int e = 0; e < n_ep; ++e) add_epoch(r, gen, e, 4 + e % 5, e != 3, e == 5);  // epoch 3: phase only
  add_epoch(r, gen, n_ep, 1, false, false);  // 2 rows: too few
  const Eigen::Vector2d k(0.8, 2.3);
  std::vector<std::int64_t> order(r.y.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<std::int64_t>(i);
  std::vector<double> red(r.y.size(), -1.0);
  auto acc = std::make_unique<VceAccumulator>();
  const int asserts0 = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  const VceSums s = acc->accumulate(r.view(), order.data(), k, red.data());
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == asserts0);  // no heap allocation (and no Eigen assertion)
  EXPECT_TRUE(s.status == VceStatus::kOk);
  EXPECT_TRUE(s.n_epochs == n_ep - 1);  // epoch 5 (rank 2) and the 2-row epoch skipped
  Eigen::Matrix2d Nd = Eigen::Matrix2d::Zero();
  Eigen::Vector2d ld = Eigen::Vector2d::Zero();
  double worst_red = 0.0;
  int n_rows = 0;
  for (int e = 0; e < n_ep; ++e) {
    if (e == 5) continue;
    std::vector<std::int64_t> idx;
    for (std::size_t i = 0; i < r.y.size(); ++i)
      if (r.epoch[i] == e) idx.push_back(static_cast<std::int64_t>(i));
    Eigen::Matrix2d N;
    Eigen::Vector2d l;
    Eigen::VectorXd rd;
    dense(r, idx, k, N, l, rd);
    if (e == 3) N.row(1).setZero(), N.col(1).setZero(), l(1) = 0.0;  // no code block: (0 / 0 of Q_P = 0)
    Nd += N;
    ld += l;
    double sum = 0.0;
    for (std::size_t i = 0; i < idx.size(); ++i) {
      worst_red = std::max(worst_red, std::abs(red[idx[i]] - rd(static_cast<int>(i))));
      sum += red[idx[i]];
    }
    EXPECT_LT(std::abs(sum - (static_cast<double>(idx.size()) - 3.0)), 1e-9);
    n_rows += static_cast<int>(idx.size());
  }
  EXPECT_LT(worst_red, 1e-9);
  EXPECT_TRUE(s.n_phase_rows + s.n_code_rows == n_rows);
  for (int p = 0; p < 2; ++p) {
    EXPECT_LT(std::abs(s.l(p) / ld(p) - 1.0), 1e-9);
    for (int q = 0; q < 2; ++q) EXPECT_LT(std::abs(s.N(p, q) / Nd(p, q) - 1.0), 1e-9);
  }
  // the skipped epochs' rows are left untouched
  for (std::size_t i = 0; i < r.y.size(); ++i)
    if (r.epoch[i] == 5 || r.epoch[i] == n_ep) EXPECT_TRUE(red[i] == -1.0);
  // an epoch with more rows of one kind than the capacity: a status, not a crash
  Rows big;
  add_epoch(big, gen, 0, kMaxVceRows / 2 + 1, false, false);
  std::vector<std::int64_t> ob(big.y.size());
  for (std::size_t i = 0; i < ob.size(); ++i) ob[i] = static_cast<std::int64_t>(i);
  const VceSums sb = acc->accumulate(big.view(), ob.data(), k);
  EXPECT_TRUE(sb.status == VceStatus::kTooManyRows && sb.bad_epoch == 0);
  TEST_MAIN_END();
}

// seed 000's analytic flop counts and this library's own counts (flops.hpp).
#include <cstdio>

#include "insnav/filter/flops.hpp"
#include "test_util.hpp"

using namespace insnav::flops;

static_assert(ukf_update_paper(15, 6) == 29295.0, "seed 000: UKF augmentation + update, m = 15, n = 6");
static_assert(rbukf_update_paper(15, 6) == 17091.0, "seed 000: RB-UKF update, m = 15, n = 6");

int main() {
  EXPECT_TRUE(ukf_update_paper(15, 6) == 29295.0);
  EXPECT_TRUE(rbukf_update_paper(15, 6) == 17091.0);
  const double s = saving(ukf_update_paper(15, 6), rbukf_update_paper(15, 6));
  std::printf("seed 000: UKF %.0f, RB-UKF %.0f flops, saving %.1f %%\n", ukf_update_paper(15, 6),
              rbukf_update_paper(15, 6), 100 * s);
  EXPECT_LT(std::abs(s - 0.417), 5e-4);  // "41.7 %"
  // this library's counts, m = 15, n = 6, H = [I6 0] (c = 6)
  const double ukf = ukf_update(15, 6, 6), dp = rbukf_dense_paper(15, 6), dj = rbukf_dense_joseph(15, 6),
               sj = rbukf_block_sparse_joseph(15, 6, 6), sf = rbukf_block_sparse_factored(15, 6, 6);
  std::printf("insnav: UKF %.0f, RB-UKF dense eq.(24) %.0f (%.1f %%), dense Joseph %.0f (%.1f %%), "
              "block-sparse Joseph %.0f (%.1f %%), block-sparse factored %.0f (%.1f %%)\n",
              ukf, dp, 100 * saving(ukf, dp), dj, 100 * saving(ukf, dj), sj, 100 * saving(ukf, sj), sf,
              100 * saving(ukf, sf));
  // the analytic count of our UKF is within 10 % of the paper's
  EXPECT_LT(std::abs(ukf / ukf_update_paper(15, 6) - 1.0), 0.1);
  EXPECT_LT(0.417, saving(ukf, dp));
  EXPECT_LT(0.80, saving(ukf, sf));
  EXPECT_LT(sf, sj);
  EXPECT_LT(sj, dj);
  // block sparsity matters more as the state grows (21 states, c = 6)
  EXPECT_LT(0.85, saving(ukf_update(21, 6, 6), rbukf_block_sparse_factored(21, 6, 6)));
  TEST_MAIN_END()
}

// The innovation gate of the GNSS records (nis_gate.hpp): the chi-square
// quantiles against reference values (scipy.stats.chi2.ppf, and the closed
// form -2 ln(1 - p) for 2 degrees of freedom), the threshold per row count,
// the fixed-threshold override, and the reopening after a run of rejections.
#include <cmath>
#include <cstdio>

#include "insnav/filter/nis_gate.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

bool near(double a, double b, double rel) { return std::fabs(a - b) <= rel * std::fabs(b); }

void test_quantiles() {
  struct Case {
    double p;
    int dof;
    double x;
  };
  const Case cases[] = {{0.9999, 6, 27.85634123601417}, {0.9999, 3, 21.107513466160444},
                        {0.999, 6, 22.457744484825323}, {0.95, 1, 3.841458820694124},
                        {0.9999, 1, 15.136705226623606}, {0.999, 100, 149.44925277903886},
                        {0.5, 40, 39.33534484661134}};
  for (const Case& c : cases) {
    const double x = chi2_quantile(c.p, c.dof);
    if (!near(x, c.x, 1e-9)) {
      std::printf("FAIL chi2_quantile(%g, %d) = %.12g, want %.12g\n", c.p, c.dof, x, c.x);
      ++g_failures;
    }
  }
  for (double p : {0.5, 0.9, 0.999, 0.9999, 1 - 1e-7}) {  // 2 dof: exactly -2 ln(1 - p)
    EXPECT_TRUE(near(chi2_quantile(p, 2), -2.0 * std::log1p(-p), 1e-9));
    EXPECT_TRUE(near(gamma_p(1.0, 0.5 * chi2_quantile(p, 2)), p, 1e-12));
  }
  EXPECT_TRUE(chi2_quantile(0.0, 6) == 0.0);
  EXPECT_TRUE(std::isinf(chi2_quantile(1.0, 6)));
}

UpdateResult rejected() {
  UpdateResult r;
  r.rejected_by_gate = true;
  return r;
}
UpdateResult applied() {
  UpdateResult r;
  r.applied = true;
  return r;
}

void test_threshold_and_reopen() {
  NisGate dflt;  // defaults: p = 0.9999, reopened after 5 rejections in a row
  for (int i = 0; i < 4; ++i) dflt.record(rejected());
  EXPECT_TRUE(!dflt.reopening() && near(dflt.threshold(6), 27.85634123601417, 1e-9));
  dflt.record(rejected());
  EXPECT_TRUE(dflt.reopening());

  GateConfig cfg;
  cfg.reopen_after = 10;
  NisGate gate(cfg);
  EXPECT_TRUE(near(gate.threshold(6), 27.85634123601417, 1e-9));
  EXPECT_TRUE(near(gate.threshold(3), 21.107513466160444, 1e-9));
  EXPECT_TRUE(near(gate.threshold(100), chi2_quantile(0.9999, 100), 1e-12));  // beyond the table
  EXPECT_TRUE(gate.threshold(0) == 0.0);

  for (int i = 0; i < 9; ++i) gate.record(rejected());
  EXPECT_TRUE(gate.threshold(6) > 0.0);  // 9 in a row: still gated
  gate.record(rejected());
  EXPECT_TRUE(gate.reopening() && gate.threshold(6) == 0.0);  // 10 in a row: the next record is ungated
  EXPECT_TRUE(near(gate.nominal_threshold(6), 27.85634123601417, 1e-9));
  EXPECT_TRUE(gate.reopened() == 0);
  gate.record(applied(), /*forced=*/true);
  EXPECT_TRUE(gate.reopened() == 1 && gate.rejected_in_a_row() == 0);
  EXPECT_TRUE(gate.threshold(6) > 0.0);  // gated again

  // an applied record in between resets the count; neither-applied-nor-rejected leaves it
  for (int i = 0; i < 9; ++i) gate.record(rejected());
  gate.record(UpdateResult{});
  gate.record(applied());
  for (int i = 0; i < 9; ++i) gate.record(rejected());
  EXPECT_TRUE(gate.threshold(6) > 0.0 && gate.reopened() == 1);
  gate.record(rejected());  // 10 in a row: reopening, but the next record passes the gate by itself
  gate.record(applied());
  EXPECT_TRUE(gate.reopened() == 1 && gate.rejected_in_a_row() == 0 && !gate.reopening());

  GateConfig fixed;
  fixed.chi2 = 30.0;
  fixed.reopen_after = 0;
  NisGate g2(fixed);
  EXPECT_TRUE(g2.threshold(1) == 30.0 && g2.threshold(12) == 30.0);
  for (int i = 0; i < 100; ++i) g2.record(rejected());
  EXPECT_TRUE(g2.threshold(6) == 30.0);  // never reopened

  GateConfig off;
  off.prob = 0.0;
  EXPECT_TRUE(!NisGate(off).config().enabled() && NisGate(off).threshold(6) == 0.0);
}

}  // namespace

int main() {
  test_quantiles();
  test_threshold_and_reopen();
  TEST_MAIN_END()
}

// RTK from RINEX files without Python (gnss/rtk_rinex.hpp, the engine of the numpy-free
// `insnav run --filter rtk`), under the sanitizers of the C++ suite:
// - the MatRTKLIB static pair (two Septentrio receivers, 5 min at 1 Hz; ../shared/data,
//   INSNAV_SHARED_DATA overrides; skipped with a message when absent), GPS L1, instantaneous
//   AR as bench/rtk/matrtklib_l1_g_inst.toml: every rover epoch gets a row, at least 99 % are
//   fixed, and every fixed row is within 5 cm of the rover's known position (the definition of
//   a wrong fix in docs/results/rtk_matrtklib_static_septentrio.md);
// - bad input: a missing file gives ok = false and a reason; an observation file cut inside an
//   epoch gives a reason or a run over the epochs before the cut; no navigation file gives no
//   fixed epoch; never a crash or an out-of-bounds read.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include "insnav/earth/wgs84.hpp"
#include "insnav/gnss/rtk_rinex.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

std::string data_dir() {
  if (const char* env = std::getenv("INSNAV_SHARED_DATA")) return std::string(env) + "/matrtklib_static_septentrio";
  std::string here = __FILE__;  // <repo>/cpp/tests/test_rtk_rinex.cpp; the data sit beside the repository
  for (int up = 0; up < 3; ++up) here = here.substr(0, here.find_last_of('/'));
  return here + "/../shared/data/matrtklib_static_septentrio";
}

bool exists(const std::string& p) { return std::ifstream(p).good(); }

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

gnss::RtkRinexInputs inputs(const std::string& dir) {
  gnss::RtkRinexInputs in;
  in.rover_path = dir + "/rover.obs";
  in.base_path = dir + "/base.obs";
  in.nav_paths = {dir + "/base.nav"};
  in.systems = "G";
  in.n_freq = 1;
  in.has_base_position = true;  // bench/rtk/matrtklib_l1_g_inst.toml
  in.base_position_e_m[0] = -3817681.1213;
  in.base_position_e_m[1] = 3562839.4311;
  in.base_position_e_m[2] = 3650159.1593;
  // SIGNALS["G"] of insnav.gnss._rtk_keys (order of preference per frequency slot)
  in.signal_prefs['G'] = {{"1C", "1W", "1X", "1P", "1S", "1L"},
                          {"2W", "2L", "2S", "2X", "2P", "2C", "2D"},
                          {"5Q", "5X", "5I"}};
  return in;
}

gnss::RtkOptions options() {
  gnss::RtkOptions o;  // the [rtk] defaults, then the TOML's settings
  o.ar_mode = gnss::ArMode::kInstantaneous;
  o.n_freq = 1;
  o.elevation_mask_rad = 15.0 * M_PI / 180.0;
  o.ratio_threshold = 3.0;
  o.glonass_ar = false;
  return o;
}

/// The MatRTKLIB pair: counts and the fixed rows against the known rover position.
void real_pair(const std::string& dir) {
  const gnss::RtkRinexResult r = gnss::rtk_rinex_run(inputs(dir), options());
  EXPECT_TRUE(r.ok);
  if (!r.ok) {
    std::printf("rtk_rinex_run: %s\n", r.why.c_str());
    return;
  }
  EXPECT_TRUE(r.epochs == 301);  // 5 min at 1 Hz, both ends
  EXPECT_TRUE(r.n_fixed + r.n_float + r.n_dgps + r.n_none == r.epochs);
  EXPECT_LT(0.99 * r.epochs, r.n_fixed + 0.5);

  double lat_t = 0, lon_t = 0, h_t = 0;  // rover_position.txt: latitude, longitude [deg], height [m]
  std::istringstream(slurp(dir + "/rover_position.txt")) >> lat_t >> lon_t >> h_t;
  const Vec3 r_true = wgs84::geodetic_to_ecef(lat_t * M_PI / 180.0, lon_t * M_PI / 180.0, h_t);

  std::istringstream pos(r.pos_text);
  std::string line;
  int rows = 0, fixed = 0;
  double worst_m = 0.0;
  while (std::getline(pos, line)) {
    if (line.empty() || line[0] == '%') continue;
    std::istringstream f(line);
    std::string date, time;
    double lat = 0, lon = 0, h = 0;
    int q = 0;
    f >> date >> time >> lat >> lon >> h >> q;
    EXPECT_TRUE(!f.fail());
    ++rows;
    if (q != 1) continue;
    ++fixed;
    const Vec3 r_e = wgs84::geodetic_to_ecef(lat * M_PI / 180.0, lon * M_PI / 180.0, h);
    worst_m = std::max(worst_m, (r_e - r_true).norm());
  }
  EXPECT_TRUE(rows == r.epochs);
  EXPECT_TRUE(fixed == r.n_fixed);
  EXPECT_LT(worst_m, 0.05);
  // one .rtk.csv row per epoch below its header line
  int table_rows = -1;
  std::istringstream tab(r.table_text);
  while (std::getline(tab, line))
    if (!line.empty() && line[0] != '#') ++table_rows;
  EXPECT_TRUE(table_rows == r.epochs);
  std::printf("MatRTKLIB L1 GPS: %d epochs, %d fixed, largest fixed error %.4f m\n", r.epochs, r.n_fixed, worst_m);
}

/// Bad input: a reason, never a crash.
void bad_input(const std::string& dir) {
  gnss::RtkRinexInputs in = inputs(dir);
  in.rover_path = dir + "/no_such_rover.obs";
  gnss::RtkRinexResult r = gnss::rtk_rinex_run(in, options());
  EXPECT_TRUE(!r.ok && !r.why.empty());

  // the rover file cut in the middle of an epoch's satellite lines
  const std::string text = slurp(dir + "/rover.obs");
  const std::size_t cut = text.find('>', text.size() / 2);
  EXPECT_TRUE(cut != std::string::npos);
  char tmpl[] = "/tmp/insnav_test_rtk_rinex_XXXXXX";
  const int fd = ::mkstemp(tmpl);
  EXPECT_TRUE(fd >= 0);
  if (fd >= 0) {
    const std::string head = text.substr(0, text.find('\n', cut + 1) + 1) + "G05  2";  // a torn line
    EXPECT_TRUE(::write(fd, head.data(), head.size()) == static_cast<ssize_t>(head.size()));
    ::close(fd);
    in = inputs(dir);
    in.rover_path = tmpl;
    r = gnss::rtk_rinex_run(in, options());
    // a reason (the Python path then reports the line), or a run over the epochs before the tear
    EXPECT_TRUE(r.ok ? r.epochs > 0 && r.epochs < 301 : !r.why.empty());
    ::unlink(tmpl);
  }

  // no navigation file: no satellite has an orbit, so no epoch may be fixed (or a reason)
  in = inputs(dir);
  in.nav_paths.clear();
  r = gnss::rtk_rinex_run(in, options());
  EXPECT_TRUE(r.ok ? r.n_fixed == 0 : !r.why.empty());
}

}  // namespace

int main() {
  const std::string dir = data_dir();
  if (!exists(dir + "/rover.obs")) {
    std::printf("SKIP: the MatRTKLIB pair is not at %s (set INSNAV_SHARED_DATA)\n", dir.c_str());
    return 0;
  }
  real_pair(dir);
  bad_input(dir);
  TEST_MAIN_END();
}

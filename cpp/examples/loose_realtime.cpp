// Real-time loosely coupled navigation with the push API, no Python: reads a
// KF-GINS configuration, IMU file and GNSS file line by line and pushes each
// sample into an insnav::LooseNavigator (21-state EKF, KF-GINS's model:
// Gauss-Markov biases and scale factors), as a robot's driver would.  The GNSS
// line for time t_g is pushed only once the IMU has passed t_g by the
// receiver's latency (`--latency-samples`, default 20 = 0.1 s at 200 Hz),
// which the navigator's IMU hold absorbs.
//
// Then it runs the batch engine (LooseEngine::run) over the same samples and
// compares every output row: exit 0 when the pushed solution reproduces the
// batch one to 1e-9 (m, m/s, rad), 1 otherwise, 2 on bad input.
//
// Usage: loose_realtime KF-GINS.yaml IMU.txt GNSS.txt [--max-samples N] [--latency-samples K]
//   IMU.txt:  sow dtheta_x dtheta_y dtheta_z [rad] dvel_x dvel_y dvel_z [m/s] (FRD increments)
//   GNSS.txt: sow lat lon [deg] h [m] std_N std_E std_D [m]
// (the formats of ../shared/data/kfgins; the YAML keys used: starttime, initpos,
// initvel, initatt, initposstd, initvelstd, initattstd, imunoise.{arw, vrw,
// gbstd, abstd, gsstd, asstd, corrtime}, antlever).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "insnav/engine/navigator.hpp"
#include "insnav/filter/ekf.hpp"

using namespace insnav;

namespace {

constexpr double kDeg = M_PI / 180.0;

[[noreturn]] void fail(const std::string& msg) {
  std::fprintf(stderr, "loose_realtime: %s\n", msg.c_str());
  std::exit(2);
}

/// The flat KF-GINS YAML subset: `key: number` and `key: [a, b, c]`, one
/// nested level (`imunoise:` then indented keys, stored as "imunoise.arw").
std::map<std::string, std::vector<double>> read_yaml(const std::string& path) {
  std::ifstream in(path);
  if (!in) fail(path + ": cannot open");
  std::map<std::string, std::vector<double>> kv;
  std::string line, parent;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    const size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    const bool indented = !line.empty() && (line[0] == ' ' || line[0] == '\t');
    std::string key = line.substr(0, colon);
    key.erase(0, key.find_first_not_of(" \t"));
    key.erase(key.find_last_not_of(" \t") + 1);
    std::string val = line.substr(colon + 1);
    val.erase(0, val.find_first_not_of(" \t"));
    val.erase(val.find_last_not_of(" \t\r") + 1);
    if (val.empty()) {  // a nested table starts
      parent = key;
      continue;
    }
    if (!indented) parent.clear();
    if (val[0] == '"') continue;  // paths: not used here (files come from the command line)
    for (char& c : val)
      if (c == '[' || c == ']' || c == ',') c = ' ';
    std::istringstream ss(val);
    std::vector<double> v;
    double x;
    while (ss >> x) v.push_back(x);
    if (!ss.eof()) fail(path + " line " + std::to_string(lineno) + ": key '" + key + "': not a number list");
    kv[parent.empty() ? key : parent + "." + key] = v;
  }
  return kv;
}

Vec3 vec3(const std::map<std::string, std::vector<double>>& kv, const std::string& key, const std::string& path) {
  auto it = kv.find(key);
  if (it == kv.end()) fail(path + ": key '" + key + "' missing");
  if (it->second.size() == 1) return Vec3::Constant(it->second[0]);
  if (it->second.size() != 3) fail(path + ": key '" + key + "' needs 1 or 3 numbers");
  return Vec3(it->second[0], it->second[1], it->second[2]);
}

/// Reads whitespace-separated numeric lines one at a time.
struct LineReader {
  std::ifstream in;
  std::string path;
  long lineno = 0;
  explicit LineReader(const std::string& p) : in(p), path(p) {
    if (!in) fail(p + ": cannot open");
  }
  bool next(double* v, int n) {
    std::string line;
    while (std::getline(in, line)) {
      ++lineno;
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
      const char* p = line.c_str();
      for (int i = 0; i < n; ++i) {
        char* end = nullptr;
        v[i] = std::strtod(p, &end);
        if (end == p) fail(path + " line " + std::to_string(lineno) + ": expected " + std::to_string(n) + " numbers");
        p = end;
      }
      return true;
    }
    return false;
  }
};

/// A KF-GINS GNSS line (sow, lat, lon [deg], h [m], std N/E/D [m]) as a position-only fix.
GnssFix fix_of(const double* g) {
  GnssFix f;
  f.t = g[0];
  f.lat = g[1] * kDeg;
  f.lon = g[2] * kDeg;
  f.h = g[3];
  f.sigma_pos_n = Vec3(g[4], g[5], g[6]);
  f.has_vel = false;
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: %s KF-GINS.yaml IMU.txt GNSS.txt [--max-samples N] [--latency-samples K]\n", argv[0]);
    return 2;
  }
  long max_samples = -1;
  int latency = 20;
  for (int i = 4; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--max-samples")) max_samples = std::atol(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--latency-samples")) latency = std::atoi(argv[i + 1]);
    else fail(std::string("unknown option ") + argv[i]);
  }
  using L = Layout21;
  using Filter = Ekf<L>;
  const std::string ypath = argv[1];
  const auto kv = read_yaml(ypath);

  // KF-GINS's model in SI: ARW [deg/sqrt(h)], VRW [m/s/sqrt(h)], biases [deg/h, mGal], scales [ppm], corrtime [h]
  NavigatorConfig cfg;
  ImuErrorModel& m = cfg.imu_model;
  m.gyro_arw = vec3(kv, "imunoise.arw", ypath) * kDeg / 60.0;
  m.acc_vrw = vec3(kv, "imunoise.vrw", ypath) / 60.0;
  m.gyro_bias_sigma = vec3(kv, "imunoise.gbstd", ypath) * kDeg / 3600.0;
  m.acc_bias_sigma = vec3(kv, "imunoise.abstd", ypath) * 1e-5;
  m.gyro_scale_sigma = vec3(kv, "imunoise.gsstd", ypath) * 1e-6;
  m.acc_scale_sigma = vec3(kv, "imunoise.asstd", ypath) * 1e-6;
  const double tau = vec3(kv, "imunoise.corrtime", ypath)[0] * 3600.0;
  m.gyro_bias_tau = m.acc_bias_tau = m.gyro_scale_tau = m.acc_scale_tau = Vec3::Constant(tau);
  cfg.loose.lever_arm_b = vec3(kv, "antlever", ypath);
  cfg.loose.use_velocity = false;  // KF-GINS: position fixes only
  cfg.imu_hold = latency + 1;
  if (latency < 0 || cfg.imu_hold > 256) fail("--latency-samples must be in 0 .. 255");

  NavState s0;
  const Vec3 pos = vec3(kv, "initpos", ypath), att = vec3(kv, "initatt", ypath);
  s0.t = vec3(kv, "starttime", ypath)[0];
  s0.lat = pos[0] * kDeg;
  s0.lon = pos[1] * kDeg;
  s0.h = pos[2];
  s0.v_n = vec3(kv, "initvel", ypath);
  s0.q_nb = quat_from_euler(att * kDeg);
  StateVec<L> sd;
  sd << vec3(kv, "initposstd", ypath), vec3(kv, "initvelstd", ypath), vec3(kv, "initattstd", ypath) * kDeg,
      m.acc_bias_sigma, m.gyro_bias_sigma, m.acc_scale_sigma, m.gyro_scale_sigma;
  const StateCov<L> P0 = sd.cwiseAbs2().asDiagonal();

  // --- push, line by line -----------------------------------------------------------------
  auto nav = std::make_unique<LooseNavigator<Filter>>(cfg, s0, P0);
  LineReader imu_in(argv[2]), gnss_in(argv[3]);
  std::vector<double> t, dth, dv;  // kept only for the batch comparison below
  std::vector<GnssFix> fixes;
  std::vector<double> push_llh, push_t;  // the pushed solution, one row per integrated sample
  double imu[7], g[7];
  bool have_g = gnss_in.next(g, 7);
  std::vector<double> imu_t_window;  // times of the last `latency` samples: a fix "arrives" `latency` samples late
  std::vector<double> us_sample, us_update;  // time of each push_imu call [us]: without / with a GNSS update
  us_sample.reserve(1 << 20);
  const auto t_start = std::chrono::steady_clock::now();
  auto record_row = [&]() {
    const auto r = nav->solution();
    push_t.push_back(r.t);
    for (int j = 0; j < 3; ++j) push_llh.push_back(r.llh[j]);
    for (int j = 0; j < 3; ++j) push_llh.push_back(r.v_n[j]);
    for (int j = 0; j < 3; ++j) push_llh.push_back(r.rpy[j]);
  };
  long n = 0;
  while ((max_samples < 0 || n < max_samples) && imu_in.next(imu, 7)) {
    if (!(imu[0] > s0.t)) continue;  // before the start time
    t.push_back(imu[0]);
    for (int j = 0; j < 3; ++j) dth.push_back(imu[1 + j]), dv.push_back(imu[4 + j]);
    // the fixes whose time of validity the IMU passed `latency` samples ago arrive now
    const double t_arrived = t.size() > static_cast<size_t>(latency) ? t[t.size() - 1 - latency] : -kInf;
    while (have_g && g[0] <= t_arrived) {
      if (g[0] > s0.t) {
        fixes.push_back(fix_of(g));
        if (nav->push_gnss_fix(fixes.back()) != RecordStatus::kNotUsed)
          fail("fix at " + std::to_string(g[0]) + " refused");
      }
      have_g = gnss_in.next(g, 7);
    }
    const std::int64_t before = nav->samples();
    const int updates_before = nav->updates();
    const auto c0 = std::chrono::steady_clock::now();
    nav->push_imu(imu[0], Vec3(imu[1], imu[2], imu[3]), Vec3(imu[4], imu[5], imu[6]));
    const double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - c0).count();
    (nav->updates() > updates_before ? us_update : us_sample).push_back(us);
    if (nav->samples() > before) record_row();
    ++n;
  }
  while (have_g && g[0] <= (t.empty() ? -kInf : t.back())) {  // the fixes still in flight at the end
    if (g[0] > s0.t) {
      fixes.push_back(fix_of(g));
      nav->push_gnss_fix(fixes.back());
    }
    have_g = gnss_in.next(g, 7);
  }
  nav->flush();  // integrate the held samples: the last row
  record_row();
  const double push_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  if (n == 0) fail(std::string(argv[2]) + ": no IMU sample after starttime");

  // --- the batch engine over the same samples -------------------------------------------------
  std::vector<double> bt(n), bllh(3 * n), bv(3 * n), brpy(3 * n);
  LooseOutputs out;
  out.t = bt.data();
  out.llh = bllh.data();
  out.v_n = bv.data();
  out.rpy = brpy.data();
  auto batch = std::make_unique<LooseEngine<Filter>>(cfg.imu_model, cfg.loose, cfg.ut);
  batch->run(s0, P0, ImuCorrection{}, n, t.data(), dth.data(), dv.data(), static_cast<std::int64_t>(fixes.size()),
             fixes.data(), out);
  // rows: the pushed rows are samples 0 .. n-held-1 one by one, then the last row after the flush
  double worst = 0.0;
  const size_t rows = push_t.size();
  for (size_t i = 0; i < rows; ++i) {
    const size_t k = (i + 1 == rows) ? static_cast<size_t>(n - 1) : i;
    if (push_t[i] != bt[k]) {
      std::printf("row %zu: time %.6f vs batch %.6f\n", i, push_t[i], bt[k]);
      return 1;
    }
    const double* p = &push_llh[9 * i];
    worst = std::max(worst, std::abs(p[0] - bllh[3 * k]) * 6.4e6);
    worst = std::max(worst, std::abs(p[1] - bllh[3 * k + 1]) * 6.4e6);
    worst = std::max(worst, std::abs(p[2] - bllh[3 * k + 2]));
    for (int j = 0; j < 3; ++j) worst = std::max(worst, std::abs(p[3 + j] - bv[3 * k + j]));
    for (int j = 0; j < 3; ++j) worst = std::max(worst, std::abs(p[6 + j] - brpy[3 * k + j]));
  }
  auto pct = [](std::vector<double>& v, double q) -> double {
    if (v.empty()) return NAN;
    const size_t i = std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5));
    std::nth_element(v.begin(), v.begin() + static_cast<long>(i), v.end());
    return v[i];
  };
  std::printf("push_imu latency [us]: IMU sample only median %.3f p99 %.3f (%zu calls); with a GNSS update "
              "median %.3f p99 %.3f (%zu calls)\n",
              pct(us_sample, 0.5), pct(us_sample, 0.99), us_sample.size(), pct(us_update, 0.5), pct(us_update, 0.99),
              us_update.size());
  std::printf("loose_realtime: %ld IMU samples, %zu fixes pushed (%d applied, latency %d samples) in %.3f s "
              "(%.2f us per sample); pushed vs batch: max difference %.3g (m, m/s, rad) over %zu rows\n",
              n, fixes.size(), nav->updates(), latency, push_s, 1e6 * push_s / n, worst, rows);
  return (worst <= 1e-9 && nav->updates() == out.updates && nav->refused_records() == 0) ? 0 : 1;
}

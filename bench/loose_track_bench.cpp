// Standalone timing of LooseEngine<Filter<Layout21>> (no Python) on the
// inputs of insnav.run's C++ call, dumped by bench/kfgins_track.py --dump DIR
// (arrays, model.txt, and config_<filter>.txt: the engine settings of that filter).
//
//   python3 bench/kfgins_track.py --dump /tmp/kfgins_bin
//   g++ -O3 -DNDEBUG -std=c++17 -Icpp/include -I/usr/include/eigen3 \
//       bench/loose_track_bench.cpp -o /tmp/loose_track_bench
//   /tmp/loose_track_bench /tmp/kfgins_bin/full ekf 5 [out.bin]
//
// Prints the median wall and process-CPU time of `repeats` runs (output
// buffers allocated once, outside the timing: this is the engine's compute
// only).  With an output path it writes the outputs of the last run
// (n_out, then t, llh, v_n, rpy, sigma, imu_err, innovation, nis as float64)
// for comparisons between builds.  -DLOOSE_BENCH_EKF_ONLY compiles the EKF
// only (a quicker build).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "insnav/engine/loose_engine.hpp"
#include "insnav/filter/ekf.hpp"
#ifndef LOOSE_BENCH_EKF_ONLY
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#endif

using namespace insnav;

namespace {

std::vector<double> read_bin(const std::string& path) {
  std::ifstream f(path, std::ios::binary | std::ios::ate);
  if (!f) {
    std::fprintf(stderr, "cannot read %s\n", path.c_str());
    std::exit(2);
  }
  std::vector<double> v(static_cast<size_t>(f.tellg()) / sizeof(double));
  f.seekg(0);
  f.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(double)));
  return v;
}

/// "key v1 [v2 v3]" lines (model.txt, config.txt of the dump).
std::map<std::string, std::vector<double>> read_keys(const std::string& path) {
  std::map<std::string, std::vector<double>> out;
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    std::istringstream is(line);
    std::string k;
    is >> k;
    double v;
    while (is >> v) out[k].push_back(v);
  }
  return out;
}

Vec3 vec3(const std::map<std::string, std::vector<double>>& m, const std::string& k, const Vec3& dflt) {
  auto it = m.find(k);
  if (it == m.end()) return dflt;
  const auto& v = it->second;
  return v.size() == 1 ? Vec3::Constant(v[0]) : Vec3(v[0], v[1], v[2]);
}

double process_cpu_s() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

template <class Filter>
int run(const std::string& dir, const std::string& name, int repeats, const char* out_path) {
  using L = typename Filter::Layout;
  constexpr int ns = L::kSize;
  const auto t = read_bin(dir + "/t.bin"), dth = read_bin(dir + "/dtheta_b.bin"), dv = read_bin(dir + "/dv_b.bin"),
             gn = read_bin(dir + "/gnss.bin"), init = read_bin(dir + "/init.bin"), P0v = read_bin(dir + "/P0.bin");
  const auto mk = read_keys(dir + "/model.txt"), ck = read_keys(dir + "/config_" + name + ".txt");
  if (P0v.size() != static_cast<size_t>(ns * ns)) {
    std::fprintf(stderr, "P0.bin: expected %d x %d values\n", ns, ns);
    return 2;
  }
  ImuErrorModel m;
  m.gyro_arw = vec3(mk, "gyro_arw", m.gyro_arw);
  m.acc_vrw = vec3(mk, "acc_vrw", m.acc_vrw);
  m.gyro_bias_sigma = vec3(mk, "gyro_bias_sigma", m.gyro_bias_sigma);
  m.acc_bias_sigma = vec3(mk, "acc_bias_sigma", m.acc_bias_sigma);
  m.gyro_bias_tau = vec3(mk, "gyro_bias_tau", m.gyro_bias_tau);
  m.acc_bias_tau = vec3(mk, "acc_bias_tau", m.acc_bias_tau);
  m.gyro_bias_rw = vec3(mk, "gyro_bias_rw", m.gyro_bias_rw);
  m.acc_bias_rw = vec3(mk, "acc_bias_rw", m.acc_bias_rw);
  m.gyro_scale_sigma = vec3(mk, "gyro_scale_sigma", m.gyro_scale_sigma);
  m.acc_scale_sigma = vec3(mk, "acc_scale_sigma", m.acc_scale_sigma);
  m.gyro_scale_tau = vec3(mk, "gyro_scale_tau", m.gyro_scale_tau);
  m.acc_scale_tau = vec3(mk, "acc_scale_tau", m.acc_scale_tau);
  LooseConfig cfg;
  cfg.lever_arm_b = vec3(ck, "lever_arm_b", cfg.lever_arm_b);
  cfg.propagation_interval = vec3(ck, "propagation_interval", Vec3::Constant(cfg.propagation_interval))[0];
  cfg.cycle_period = vec3(ck, "cycle_period", Vec3::Constant(cfg.cycle_period))[0];
  cfg.gate.chi2 = vec3(ck, "gate_chi2", Vec3::Constant(cfg.gate.chi2))[0];
  cfg.gate.prob = vec3(ck, "gate_prob", Vec3::Constant(cfg.gate.prob))[0];
  cfg.gate.reopen_after = static_cast<int>(vec3(ck, "gate_reopen_after", Vec3::Constant(cfg.gate.reopen_after))[0]);
  cfg.use_position = vec3(ck, "use_position", Vec3::Constant(1.0))[0] != 0.0;
  cfg.use_velocity = vec3(ck, "use_velocity", Vec3::Constant(1.0))[0] != 0.0;
  UtParams ut;
  ut.alpha = vec3(ck, "ut_alpha", Vec3::Constant(ut.alpha))[0];
  ut.beta = vec3(ck, "ut_beta", Vec3::Constant(ut.beta))[0];
  ut.kappa = vec3(ck, "ut_kappa", Vec3::Constant(3.0 - ns))[0];

  NavState nav;
  nav.t = init[0];
  nav.lat = init[1];
  nav.lon = init[2];
  nav.h = init[3];
  nav.v_n = Vec3(init[4], init[5], init[6]);
  nav.q_nb = quat_from_euler(Vec3(init[7], init[8], init[9]));
  const StateCov<L> P0 = Eigen::Map<const Eigen::Matrix<double, ns, ns, Eigen::RowMajor>>(P0v.data());
  const auto n_fix = static_cast<std::int64_t>(gn.size() / 13);
  std::vector<GnssFix> fixes(static_cast<size_t>(n_fix));
  for (std::int64_t i = 0; i < n_fix; ++i) {  // rows as in loose_run.hpp
    const double* r = &gn[13 * i];
    GnssFix& f = fixes[i];
    f.t = r[0];
    f.lat = r[1];
    f.lon = r[2];
    f.h = r[3];
    f.v_n = Vec3(r[4], r[5], r[6]);
    f.sigma_pos_n = Vec3(r[7], r[8], r[9]);
    f.sigma_vel_n = Vec3(r[10], r[11], r[12]);
    f.has_pos = std::isfinite(r[1]) && std::isfinite(r[2]) && std::isfinite(r[3]);
    f.has_vel = f.v_n.allFinite() && f.sigma_vel_n.allFinite();
  }
  const auto n = static_cast<std::int64_t>(t.size());
  const size_t rows = static_cast<size_t>(n + 1);
  std::vector<double> o_t(rows), o_llh(3 * rows), o_v(3 * rows), o_rpy(3 * rows), o_sig(ns * rows),
      o_err(12 * rows), o_in(6 * n_fix), o_nis(n_fix);
  std::vector<std::int8_t> o_st(n_fix);
  std::vector<double> wall, cpu;
  LooseOutputs out;
  for (int r = 0; r < repeats; ++r) {
    out = LooseOutputs{};
    out.t = o_t.data();
    out.llh = o_llh.data();
    out.v_n = o_v.data();
    out.rpy = o_rpy.data();
    out.sigma = o_sig.data();
    out.imu_err = o_err.data();
    out.innovation = o_in.data();
    out.nis = o_nis.data();
    out.status = o_st.data();
    const double c0 = process_cpu_s();
    const auto t0 = std::chrono::steady_clock::now();
    auto engine = std::make_unique<LooseEngine<Filter>>(m, cfg, ut);
    engine->run(nav, P0, ImuCorrection{}, n, t.data(), dth.data(), dv.data(), n_fix, fixes.data(), out);
    wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    cpu.push_back(process_cpu_s() - c0);
  }
  std::sort(wall.begin(), wall.end());
  std::sort(cpu.begin(), cpu.end());
  std::printf("%s %s: %lld IMU samples, %d updates; median of %d: wall %.4f s, CPU %.4f s (min %.4f)\n",
              dir.c_str(), name.c_str(), static_cast<long long>(n), out.updates, repeats, wall[wall.size() / 2],
              cpu[cpu.size() / 2], cpu[0]);
  if (out_path) {
    std::ofstream f(out_path, std::ios::binary);
    const std::int64_t k = out.n_out;
    auto put = [&](const std::vector<double>& v, size_t count) {
      f.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(count * sizeof(double)));
    };
    f.write(reinterpret_cast<const char*>(&k), sizeof(k));
    put(o_t, k);
    put(o_llh, 3 * k);
    put(o_v, 3 * k);
    put(o_rpy, 3 * k);
    put(o_sig, ns * k);
    put(o_err, 12 * k);
    put(o_in, 6 * n_fix);
    put(o_nis, n_fix);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s DUMP_DIR {ekf|rbukf|ukf} [repeats=5] [out.bin]\n", argv[0]);
    return 2;
  }
  const std::string dir = argv[1], name = argv[2];
  const int repeats = argc > 3 ? std::max(1, std::atoi(argv[3])) : 5;
  const char* out_path = argc > 4 ? argv[4] : nullptr;
  if (name == "ekf") return run<Ekf<Layout21>>(dir, name, repeats, out_path);
#ifndef LOOSE_BENCH_EKF_ONLY
  if (name == "rbukf") return run<RbUkf<Layout21>>(dir, name, repeats, out_path);
  if (name == "ukf") return run<Ukf<Layout21>>(dir, name, repeats, out_path);
#endif
  std::fprintf(stderr, "unknown filter %s\n", name.c_str());
  return 2;
}

// Strapdown throughput in plain C++: generates 1 h of 200 Hz increments (a
// turning, pitching motion; the same formulas as bench/bench_mechanization.py),
// runs Strapdown::update over them `repeats` times and prints the samples per
// second of every repeat, for two loops:
//   plain   Strapdown::update only (the state is kept, nothing written);
//   output  the loop of the Python batch API (cpp/bindings/bind_ins.cpp,
//           mechanize): update, then lat/lon/h, v_n and roll/pitch/yaw of every
//           sample written to caller-owned arrays (9 doubles per sample),
//           allocated and zeroed before the timed region;
//   output_fresh  the same into buffers malloc'ed inside the timed region and
//           never touched before (what the binding does with new numpy arrays).
// Built and run by bench/bench_mechanization.py (one repeat per call, the
// Python batch call in between, so both are measured side by side).
//
//   mechanization_bench [n_samples=720000] [repeats=1]
// Output lines per repeat: "<loop> <samples/s by wall clock> <samples/s by thread CPU time>"
// for loop = plain, output, output_fresh.
#include <time.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "insnav/core.hpp"

/// CPU time of this thread [s] (not advanced while the thread waits for a core).
static double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int main(int argc, char** argv) {
  using namespace insnav;
  const long n = argc > 1 ? std::atol(argv[1]) : 720000;
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 1;
  if (n < 2 || repeats < 1) {
    std::fprintf(stderr, "usage: mechanization_bench [n_samples >= 2] [repeats >= 1]\n");
    return 2;
  }
  const double dt = 0.005;
  std::vector<ImuIncrement> imu(n);
  for (long i = 0; i < n; ++i) {
    const double t = (i + 1) * dt;
    imu[i].t = t;
    imu[i].dt = dt;
    imu[i].dtheta_b = Vec3(0.01 * std::sin(0.5 * t), 0.02 * std::cos(0.3 * t), 0.05) * dt;
    imu[i].dv_b = Vec3(0.3 * std::sin(0.1 * t), 0.2, -9.8) * dt;
  }
  NavState s0;
  s0.t = 0.0;
  s0.lat = 0.6;
  s0.lon = 2.0;
  s0.h = 100.0;
  s0.v_n = Vec3(10.0, 0.0, 0.0);
  std::vector<double> llh(3 * n), v(3 * n), rpy(3 * n);
  volatile double sink = 0.0;
  for (int r = 0; r < repeats; ++r) {
    {
      Strapdown ins(s0);
      const auto t0 = std::chrono::steady_clock::now();
      const double c0 = thread_cpu_s();
      for (long i = 0; i < n; ++i) ins.update(imu[i]);
      const double el = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double cpu = thread_cpu_s() - c0;
      sink = sink + ins.state().lat;
      std::printf("plain %.0f %.0f\n", n / el, n / cpu);
    }
    {
      Strapdown ins(s0);
      double* o_llh = llh.data();
      double* o_v = v.data();
      double* o_rpy = rpy.data();
      const auto t0 = std::chrono::steady_clock::now();
      const double c0 = thread_cpu_s();
      for (long i = 0; i < n; ++i) {
        ins.update(imu[i]);
        const NavState& s = ins.state();
        o_llh[3 * i] = s.lat;
        o_llh[3 * i + 1] = s.lon;
        o_llh[3 * i + 2] = s.h;
        o_v[3 * i] = s.v_n.x();
        o_v[3 * i + 1] = s.v_n.y();
        o_v[3 * i + 2] = s.v_n.z();
        const Vec3 e = euler_from_quat(s.q_nb);
        o_rpy[3 * i] = e.x();
        o_rpy[3 * i + 1] = e.y();
        o_rpy[3 * i + 2] = e.z();
      }
      const double el = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double cpu = thread_cpu_s() - c0;
      sink = sink + llh[3 * (n - 1)] + rpy[3 * (n - 1) + 2];
      std::printf("output %.0f %.0f\n", n / el, n / cpu);
    }
    {
      // the same, into output buffers allocated inside the timed region and not
      // touched before (as the binding's fresh numpy arrays: first-touch page faults)
      Strapdown ins(s0);
      const auto t0 = std::chrono::steady_clock::now();
      const double c0 = thread_cpu_s();
      double* o_llh = static_cast<double*>(std::malloc(sizeof(double) * 3 * n));
      double* o_v = static_cast<double*>(std::malloc(sizeof(double) * 3 * n));
      double* o_rpy = static_cast<double*>(std::malloc(sizeof(double) * 3 * n));
      if (!o_llh || !o_v || !o_rpy) return 3;
      for (long i = 0; i < n; ++i) {
        ins.update(imu[i]);
        const NavState& s = ins.state();
        o_llh[3 * i] = s.lat;
        o_llh[3 * i + 1] = s.lon;
        o_llh[3 * i + 2] = s.h;
        o_v[3 * i] = s.v_n.x();
        o_v[3 * i + 1] = s.v_n.y();
        o_v[3 * i + 2] = s.v_n.z();
        const Vec3 e = euler_from_quat(s.q_nb);
        o_rpy[3 * i] = e.x();
        o_rpy[3 * i + 1] = e.y();
        o_rpy[3 * i + 2] = e.z();
      }
      const double el = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double cpu = thread_cpu_s() - c0;
      sink = sink + o_llh[3 * (n - 1)] + o_v[0] + o_rpy[3 * (n - 1) + 2];
      std::free(o_llh);
      std::free(o_v);
      std::free(o_rpy);
      std::printf("output_fresh %.0f %.0f\n", n / el, n / cpu);
    }
  }
  return sink == 12345.0 ? 1 : 0;  // keeps the results alive
}

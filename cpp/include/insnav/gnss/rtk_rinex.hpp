// RTK from RINEX files in one call: the rover and base observations (rinex3_obs.hpp), the GPS and
// QZSS broadcast ephemerides (rinex_nav.hpp), the satellite states at transmission, the engine
// rows, the base epoch matching, the RTK engine (rtk.hpp) and the text of the RTKLIB-layout .pos
// and of the per-epoch table -- the same arithmetic, step by step and in the same order, as the
// Python path (python/insnav/gnss/rtk.py: read_phase_obs, read_rinex_nav, transmit_states,
// receiver_rows, match_base, solve_rtk, write_rtklib_pos, write_rtk_table), so that both give the
// same files byte for byte.
//
// Scope: RINEX 3 observation and navigation files, systems G and J (GPS LNAV Kepler orbits,
// IS-GPS-200 Table 20-IV; QZSS the same, IS-QZSS-PNT 4.1.2).  Anything else (RINEX 2, GLONASS,
// Galileo, BeiDou, a file or value the Python readers would report) returns ok = false with the
// reason: the caller then takes the Python path, which gives the error message or the result.
#pragma once

#ifndef EIGEN_STACK_ALLOCATION_LIMIT  // before the first Eigen include (gnss/rtk.hpp's fixed-capacity matrices)
#define EIGEN_STACK_ALLOCATION_LIMIT 1048576
#endif

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "insnav/earth/wgs84.hpp"
#include "insnav/gnss/broadcast_orbit.hpp"
#include "insnav/gnss/ephemeris_selection.hpp"
#include "insnav/gnss/rtk.hpp"
#include "insnav/gnss/code_position_fit.hpp"
#include "insnav/io/rinex3_obs.hpp"
#include "insnav/io/rinex_nav.hpp"

namespace insnav::gnss {

/// Inputs of rtk_rinex_run besides the engine options.
struct RtkRinexInputs {
  std::string rover_path, base_path;
  std::vector<std::string> nav_paths;
  std::string systems;                                   // letters of GJ
  int n_freq = 1;                                        // 1..3
  double max_age_s = 30.0;
  bool has_base_position = false;
  double base_position_e_m[3] = {0.0, 0.0, 0.0};         // ECEF [m]
  std::map<char, std::vector<std::vector<std::string>>> signal_prefs;  // SIGNALS of rtk.py
  std::string program = "insnav";                        // the .pos header's program
};

/// Result: the two files' text and the counts of the summary line; ok = false: why not.
struct RtkRinexResult {
  bool ok = false;
  std::string why;
  std::string pos_text, table_text;
  int epochs = 0, n_fixed = 0, n_float = 0, n_dgps = 0, n_none = 0;
  long slips_total = 0;
};

namespace rtk_rinex_detail {

inline constexpr double kDefaultFitS = 4.0 * 3600.0;
inline constexpr double kWeekS = 604800.0;
inline constexpr long kGpsEpochDays = 3657;            // 1980-01-06 from 1970-01-01

/// Python's float formatting of ``f"{v:{width}.{dec}f}"`` (NaN as "nan", no "-nan").
inline void put_f(std::string& s, double v, int width, int dec) {
  char buf[64];
  if (std::isnan(v)) std::snprintf(buf, sizeof buf, "%*s", width, "nan");
  else if (std::isinf(v)) std::snprintf(buf, sizeof buf, "%*s", width, v > 0 ? "inf" : "-inf");
  else std::snprintf(buf, sizeof buf, "%*.*f", width, dec, v);
  s += buf;
}

inline void put_i(std::string& s, long v, int width) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%*ld", width, v);
  s += buf;
}

/// Ephemeris table of the GPS-like records (rinex.py _gps_like_table), columns by _NAV_ORDER.
struct KeplerTable {
  std::vector<std::int64_t> prn;
  std::vector<std::uint8_t> usable;  // health == 0
  std::vector<double> toc, af0, af1, af2, toe, fit_window;
  std::vector<std::array<double, io::kNavOrbitValues>> orbit;  // NaN -> 0 (fit_h kept)
};

enum NavCol { kIode, kCrs, kDeltaN, kM0, kCuc, kE, kCus, kSqrtA, kToeSow, kCic, kOmega0, kCis, kI0, kCrc, kOmega,
              kOmegaDot, kIdot, kL2Codes, kWeek, kL2pFlag, kSvAcc, kHealth, kTgd, kIodc, kTransmitSow, kFitH };

inline double gps_seconds(std::int64_t y, std::int64_t mo, std::int64_t d, std::int64_t h, std::int64_t mi,
                          double sec) {
  const long days = io::detail::days_from_civil(y, static_cast<unsigned>(mo), static_cast<unsigned>(d)) - kGpsEpochDays;
  return static_cast<double>(days) * 86400.0 + static_cast<double>(h) * 3600.0 + static_cast<double>(mi) * 60.0 + sec;
}

inline bool read_text(const std::string& path, std::string& out) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return false;
  std::ostringstream ss;
  ss << f.rdbuf();
  out = ss.str();
  return true;
}

/// A 4-value ionosphere header field as rinex.py _float reads it (blank -> NaN -> malformed).
inline bool four_floats(std::string_view line, std::size_t start, std::size_t width) {
  for (int k = 0; k < 4; ++k) {
    double v;
    if (!io::detail::nav_float(io::detail::nav_field(line, start + width * k, width), v, true) || std::isnan(v))
      return false;
  }
  return true;
}

/// One RINEX 3 navigation file's G/J records appended to g and j; false: leave it to Python.  A
/// single-system file of a system not in want is skipped (other_system set), as
/// insnav.gnss.rinex.read_nav_multi skips it beside a file of the systems used.
inline bool read_nav(const std::string& path, const std::string& want, KeplerTable& g, KeplerTable& j,
                     std::string& why, bool& other_system) {
  other_system = false;
  std::string text;
  if (!read_text(path, text)) return why = path + ": cannot read", false;
  std::size_t p = 0, body = std::string::npos;
  bool first = true;
  while (p < text.size()) {
    std::size_t q = text.find('\n', p);
    if (q == std::string::npos) q = text.size();
    std::string_view line(text.data() + p, q - p);
    if (!line.empty() && line.back() == '\r') return why = "CR line ends", false;
    const std::string_view label = line.size() > 60 ? line.substr(60) : std::string_view();
    auto has = [&](const char* l) { return label.substr(0, std::char_traits<char>::length(l)) == l; };
    if (first) {
      first = false;
      double version = 0.0;
      if (!io::detail::nav_float(io::detail::nav_field(line, 0, 9), version, false) || version < 3.0)
        return why = "navigation file not RINEX 3", false;
      const char ftype = line.size() > 20 ? line[20] : ' ';
      const char sysc = line.size() > 40 ? line[40] : ' ';
      if (ftype != 'N') return why = "navigation file type", false;
      if (sysc != 'M' && want.find(sysc) == std::string::npos) return other_system = true, true;
    } else if (has("END OF HEADER")) {
      body = q + 1;
      break;
    } else if (has("ION ALPHA") || has("ION BETA")) {
      if (!four_floats(line, 2, 12)) return why = "ionosphere header", false;
    } else if (has("IONOSPHERIC CORR")) {
      std::string kind(line.substr(0, std::min<std::size_t>(4, line.size())));
      while (!kind.empty() && kind.back() == ' ') kind.pop_back();
      if ((kind == "GPSA" || kind == "GPSB") && !four_floats(line, 5, 12)) return why = "ionosphere header", false;
    } else if (has("LEAP SECONDS")) {
      std::int64_t leap = 0;
      const std::string_view f = line.substr(0, std::min<std::size_t>(6, line.size()));
      if (!io::detail::nav_blank(f) && (!io::detail::nav_int(f, leap) || leap < 0 || leap >= 100))
        return why = "leap seconds header", false;
    }
    p = q + 1;
  }
  if (body == std::string::npos) return why = "no END OF HEADER", false;
  std::string_view rest(text.data() + std::min(body, text.size()), text.size() - std::min(body, text.size()));
  io::NavScan scan;
  io::scan_rinex_nav_body(rest, true, false, want, scan);
  if (scan.irregular) return why = "navigation records the Python reader reads", false;
  const std::size_t n = scan.prn.size();
  for (std::size_t r = 0; r < n; ++r) {
    const char s = scan.sys[r];
    if (s != 'G' && s != 'J') return why = "navigation system", false;
    KeplerTable& t = s == 'G' ? g : j;
    const std::int64_t* c = &scan.ymdhm[5 * r];
    const double toc = gps_seconds(c[0], c[1], c[2], c[3], c[4], scan.sec[r]);
    std::array<double, io::kNavOrbitValues> o;
    for (int k = 0; k < io::kNavOrbitValues; ++k) {
      const double v = scan.orbit[r * io::kNavOrbitValues + k];
      o[k] = (k != kFitH && std::isnan(v)) ? 0.0 : v;
    }
    if (!(o[kSqrtA] > 0.0)) return why = "sqrt(A) <= 0", false;
    double clk[3];
    for (int k = 0; k < 3; ++k) {
      const double v = scan.clk[3 * r + k];
      clk[k] = std::isnan(v) ? 0.0 : v;
    }
    double toe = o[kWeek] * kWeekS + o[kToeSow];
    toe += kWeekS * std::nearbyint((toc - toe) / kWeekS);
    const double fit_h = o[kFitH];
    double fit_s, health = o[kHealth];
    if (s == 'J') {
      fit_s = (std::isfinite(fit_h) && fit_h > 0) ? kDefaultFitS : 2.0 * 3600.0;
      health = static_cast<double>(static_cast<std::int64_t>(health) & ~std::int64_t{1});
    } else {
      fit_s = (std::isfinite(fit_h) && fit_h > 0) ? fit_h * 3600.0 : kDefaultFitS;
    }
    t.prn.push_back(scan.prn[r]);
    t.usable.push_back(health == 0.0 ? 1 : 0);
    t.toc.push_back(toc);
    t.af0.push_back(clk[0]);
    t.af1.push_back(clk[1]);
    t.af2.push_back(clk[2]);
    t.toe.push_back(toe);
    t.fit_window.push_back(0.5 * fit_s + 1e-6);
    t.orbit.push_back(o);
  }
  return true;
}

/// The record r of t as a row of KeplerCols (broadcast_orbit.hpp); t_k from the full GPS time of toe.
inline void kepler_elements(const KeplerTable& t, std::size_t r, double* k) {
  using C = KeplerCols;
  const auto& o = t.orbit[r];
  k[C::kSqrtA] = o[kSqrtA];
  k[C::kToe] = t.toe[r];
  k[C::kDeltaN] = o[kDeltaN];
  k[C::kM0] = o[kM0];
  k[C::kE] = o[kE];
  k[C::kOmega] = o[kOmega];
  k[C::kCus] = o[kCus];
  k[C::kCuc] = o[kCuc];
  k[C::kCrs] = o[kCrs];
  k[C::kCrc] = o[kCrc];
  k[C::kCis] = o[kCis];
  k[C::kCic] = o[kCic];
  k[C::kI0] = o[kI0];
  k[C::kIdot] = o[kIdot];
  k[C::kOmega0] = o[kOmega0];
  k[C::kOmegaDot] = o[kOmegaDot];
  k[C::kToeSow] = o[kToeSow];
  k[C::kToc] = t.toc[r];
  k[C::kAf0] = t.af0[r];
  k[C::kAf1] = t.af1[r];
  k[C::kAf2] = t.af2[r];
  k[C::kGeo] = 0.0;
}

/// Satellite state of ephemeris.py sat_position_velocity + sat_clock (relativistic) for a batch of
/// one system: out[i] = (r_e [m], v_e [m/s], clock bias [s], drift [s/s]) at GPS time tt[i].  The
/// orbit and clock are broadcast_orbit.hpp's; only Kepler's equation is solved here, for the whole
/// batch at once as the vectorised loop of ephemeris.py _kepler does: every row takes another Newton
/// step until every row's step is below 1e-14 rad (at most 10).  kepler_state stops each row at its
/// own convergence instead; the extra steps change the last bit of E for about 2 % of rows (GPS /
/// QZSS eccentricities), which the byte-identical .pos / .rtk.csv of tests/test_rtk_fast.py cannot take.
inline void kepler_batch(const KeplerTable& t, const std::vector<std::int64_t>& idx, const std::vector<double>& tt,
                         std::vector<std::array<double, 8>>& out) {
  const std::size_t k = idx.size();
  out.assign(k, {});
  std::vector<std::array<double, KeplerCols::kCols>> el(k);
  std::vector<double> M(k), E(k);
  for (std::size_t i = 0; i < k; ++i) {
    kepler_elements(t, static_cast<std::size_t>(idx[i]), el[i].data());
    M[i] = detail::kepler_mean_anomaly(el[i].data(), tt[i], kGmGps);
    E[i] = M[i];
  }
  for (int it = 0; it < 10; ++it) {
    bool all = true;
    for (std::size_t i = 0; i < k; ++i) {
      const double dE = detail::kepler_newton_step(E[i], el[i][KeplerCols::kE], M[i]);
      E[i] = E[i] - dE;
      if (!(std::abs(dE) < 1e-14)) all = false;
    }
    if (all) break;
  }
  OrbitState st;
  for (std::size_t i = 0; i < k; ++i) {
    detail::kepler_state_at_E(el[i].data(), tt[i], kGmGps, kOmegaEDotGps, E[i], st);
    double bias, drift;
    detail::kepler_clock(el[i].data(), tt[i], st, kFRelGps, bias, drift);
    out[i] = {st.r[0], st.r[1], st.r[2], st.v[0], st.v[1], st.v[2], bias, drift};
  }
}

inline double band_hz(char sys, char band) {
  if (band == '1') return 1575.42e6;
  if (band == '2') return 1227.60e6;
  if (band == '5') return 1176.45e6;
  (void)sys;
  return NAN;
}

/// ``YYYY/MM/DD HH:MM:SS.SSS`` of GPS seconds (rtk.py _gpst_texts).
inline void put_gpst(std::string& s, double t_gps_s) {
  const std::int64_t ms = static_cast<std::int64_t>(std::nearbyint(t_gps_s * 1000.0));
  std::int64_t day = ms / 86400000, mod = ms % 86400000;
  if (mod < 0) {
    mod += 86400000;
    --day;
  }
  const std::int64_t hh = mod / 3600000, mi = (mod % 3600000) / 60000, ss = (mod % 60000) / 1000, f = mod % 1000;
  // civil from days (H. Hinnant), days since 1970-01-01
  long z = static_cast<long>(day) + kGpsEpochDays + 719468;
  const long era = (z >= 0 ? z : z - 146096) / 146097;
  const unsigned doe = static_cast<unsigned>(z - era * 146097);
  const unsigned yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  long y = static_cast<long>(yoe) + era * 400;
  const unsigned doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const unsigned mp = (5 * doy + 2) / 153;
  const unsigned d = doy - (153 * mp + 2) / 5 + 1;
  const unsigned m = mp < 10 ? mp + 3 : mp - 9;
  y += m <= 2;
  char buf[48];
  std::snprintf(buf, sizeof buf, "%04ld/%02u/%02u %02lld:%02lld:%02lld.%03lld", y, m, d, static_cast<long long>(hh),
                static_cast<long long>(mi), static_cast<long long>(ss), static_cast<long long>(f));
  s += buf;
}

struct Receiver {
  io::RinexObsTable t;
  std::vector<std::int64_t> off;  // epoch offsets (n+1)
};

/// Largest median residual RMS [m] of a receiver's one-epoch code fits this path accepts; the same
/// value as insnav.gnss._rtk_keys.CODE_FIT_TOLERANCE_M, whose Python check words the error.
inline constexpr double kCodeFitToleranceM = 50.0;

/// Median over up to 10 epochs spread over the file of the residual RMS [m] of one-epoch code-only
/// least-squares fits (position, a reference clock and a GPS-QZSS bias, unit weights, no atmosphere
/// models; gnss/code_position_fit.hpp's Gauss-Newton fit from r0 with the satellites rotated by the Earth's rate over
/// the travel time from r0), as insnav.gnss.rtk.receiver_code_fix; NaN when no epoch has a redundant
/// converged fit.  Time tags shifted against the observations give hundreds of metres, good files a few.
/// ``sat``: per row (from ``row0``) the satellite position [m] and clock [m]; ``code``: pseudorange [m].
inline double code_fit_rms(const Receiver& rx, std::size_t row0, const std::vector<std::array<double, 4>>& sat,
                           const std::vector<double>& code, const double* r0) {
  const auto& T = rx.t;
  const std::size_t ne = T.epoch_t_gps_s.size();
  const std::size_t n_ep = std::min<std::size_t>(10, ne);
  std::vector<double> rms;
  std::int64_t last = -1;
  std::array<CodeFitRow, kSppMaxRows> rows;
  SppRowsMat H;
  SppRowsBy3 u;
  SppRowsVec rng, y;
  SppParVec x;
  for (std::size_t q = 0; q < n_ep; ++q) {
    const auto e = static_cast<std::int64_t>(n_ep == 1 ? 0.0 : double(ne - 1) * double(q) / double(n_ep - 1));
    if (e == last) continue;
    last = e;
    int col[kSppMaxRows], n = 0;
    bool has_sys[2] = {false, false};
    for (auto r = rx.off[static_cast<std::size_t>(e)]; r < rx.off[static_cast<std::size_t>(e) + 1] && n < kSppMaxRows;
         ++r) {
      const std::size_t i = row0 + static_cast<std::size_t>(r);
      const auto& S = sat[i];
      if (!(std::isfinite(code[i]) && std::isfinite(S[0]) && std::isfinite(S[1]) && std::isfinite(S[2]) &&
            std::isfinite(S[3])))
        continue;
      const double d[3] = {S[0] - r0[0], S[1] - r0[1], S[2] - r0[2]};
      const double th = wgs84::kOmegaIe * std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / kCLight;
      rows[n] = {Vec3(std::cos(th) * S[0] + std::sin(th) * S[1], -std::sin(th) * S[0] + std::cos(th) * S[1], S[2]),
                 code[i], S[3]};
      col[n] = T.row_sys[static_cast<std::size_t>(r)] == 'J' ? 1 : 0;
      has_sys[col[n]] = true;
      ++n;
    }
    const int n_clk = int(has_sys[0]) + int(has_sys[1]);
    if (n < 4 + n_clk) continue;  // one redundant row at least
    for (int k = 0; k < n; ++k) col[k] = (has_sys[0] && col[k] == 1) ? 1 : 0;  // QZSS alone: its clock the reference
    x.setZero(3 + n_clk);
    x.head<3>() = Vec3(r0[0], r0[1], r0[2]);
    const SppRowsVec w = SppRowsVec::Ones(n);
    if (!code_position_fit(n, 3 + n_clk, [&](int k) { return rows[k]; }, col, w, 10, x, H, u, rng, y)) continue;
    rms.push_back(std::sqrt(y.squaredNorm() / n));
  }
  if (rms.empty()) return NAN;
  std::sort(rms.begin(), rms.end());
  const std::size_t h = rms.size() / 2;
  return rms.size() % 2 ? rms[h] : 0.5 * (rms[h - 1] + rms[h]);
}

}  // namespace rtk_rinex_detail

/// RTK of RINEX 3 rover and base files against GPS/QZSS broadcast ephemerides, with the texts of
/// the RTKLIB-layout ``.pos`` and the ``.rtk.csv`` table (module comment above).
inline RtkRinexResult rtk_rinex_run(const RtkRinexInputs& in, const RtkOptions& opt) {
  using namespace rtk_rinex_detail;
  RtkRinexResult res;
  auto fail = [&](std::string why) {
    res.ok = false;
    res.why = std::move(why);
    return res;
  };
  for (char s : in.systems)
    if (s != 'G' && s != 'J') return fail(std::string("system ") + s);
  if (in.systems.empty()) return fail("no system");
  const int nf = in.n_freq;
  // observations
  Receiver rx[2];
  const std::string* paths[2] = {&in.rover_path, &in.base_path};
  for (int k = 0; k < 2; ++k) {
    std::ifstream f(*paths[k]);
    std::string first;
    if (!f || !std::getline(f, first)) return fail(*paths[k] + ": cannot read");
    double version = 0.0;
    if (!io::detail::nav_float(io::detail::nav_field(first, 0, 9), version, false) || version < 3.0)
      return fail("observation file not RINEX 3");
    try {
      rx[k].t = io::read_rinex3_obs(*paths[k], in.signal_prefs);
    } catch (const std::exception& e) {
      return fail(e.what());
    }
    const auto& t = rx[k].t;
    if (t.n_repeated_epochs > 0) return fail("repeated epochs");  // the usual path warns about them
    const std::size_t ne = t.epoch_t_gps_s.size(), m = t.row_epoch.size();
    rx[k].off.assign(ne + 1, 0);
    for (std::size_t i = 0; i < m; ++i) {
      if (i && t.row_epoch[i] < t.row_epoch[i - 1]) return fail("rows not in epoch order");
      if (t.row_epoch[i] < 0 || static_cast<std::size_t>(t.row_epoch[i]) >= ne) return fail("row epoch");
      ++rx[k].off[static_cast<std::size_t>(t.row_epoch[i]) + 1];
    }
    for (std::size_t e = 0; e < ne; ++e) rx[k].off[e + 1] += rx[k].off[e];
    for (std::size_t i = 0; i < m; ++i)
      if (t.row_sys[i] != 'G' && t.row_sys[i] != 'J') return fail("row system");
  }
  const auto& R = rx[0].t;
  const auto& B = rx[1].t;
  // navigation
  KeplerTable tab[2];  // G, J
  std::size_t n_nav_read = 0;
  for (const auto& p : in.nav_paths) {
    std::string why;
    bool other_system = false;
    if (!read_nav(p, in.systems, tab[0], tab[1], why, other_system)) return fail(why);
    if (!other_system) ++n_nav_read;
  }
  if (n_nav_read == 0) return fail("no navigation file of the systems used");  // Python words the error
  // base position
  double rb[3];
  if (in.has_base_position) {
    for (int i = 0; i < 3; ++i) rb[i] = in.base_position_e_m[i];
  } else {
    const double* a = B.approx_r_e;
    if (!B.has_approx || !std::isfinite(a[0]) || !std::isfinite(a[1]) || !std::isfinite(a[2]) ||
        (a[0] == 0.0 && a[1] == 0.0 && a[2] == 0.0))
      return fail("no base position");
    // all 8 latitude steps, as earth.py (wgs84.hpp's early stop moves the last bit of about 1 point in 2000)
    const Vec3 llh_b = wgs84::ecef_to_geodetic(Vec3(a[0], a[1], a[2]), 0.0);
    const double lat = llh_b(0), lon = llh_b(1);
    const double h = B.antenna_hen_m[0], e = B.antenna_hen_m[1], n = B.antenna_hen_m[2];
    const double sl = std::sin(lat), cl = std::cos(lat), so = std::sin(lon), co = std::cos(lon);
    const double up[3] = {cl * co, cl * so, sl}, east[3] = {-so, co, 0.0}, north[3] = {-sl * co, -sl * so, cl};
    for (int i = 0; i < 3; ++i) rb[i] = ((a[i] + h * up[i]) + e * east[i]) + n * north[i];
  }
  // base epoch of each rover epoch (match_base)
  const std::size_t nr_e = R.epoch_t_gps_s.size(), nb_e = B.epoch_t_gps_s.size();
  if (nb_e == 0 || nr_e == 0) return fail("no epochs");
  std::vector<std::int64_t> bidx(nr_e, -1);
  bool any = false;
  for (std::size_t e = 0; e < nr_e; ++e) {
    const double tr = R.epoch_t_gps_s[e];
    const auto it = std::upper_bound(B.epoch_t_gps_s.begin(), B.epoch_t_gps_s.end(), tr + 1e-3);
    const std::int64_t j = static_cast<std::int64_t>(it - B.epoch_t_gps_s.begin()) - 1;
    if (j >= 0 && !(tr - B.epoch_t_gps_s[static_cast<std::size_t>(j)] > in.max_age_s + 1e-3)) {
      bidx[e] = j;
      any = true;
    }
  }
  if (!any) return fail("no common epoch");
  // input checks of rtk.py _check_inputs (the Python path words the error)
  auto has_phase = [&](const io::RinexObsTable& t) {
    const std::size_t m = t.row_epoch.size();
    for (std::size_t i = 0; i < m; ++i)
      for (int f = 0; f < nf; ++f)
        if (std::isfinite(t.obs[i * 15 + f * 5 + 1])) return true;
    return false;
  };
  if (!has_phase(B) || !has_phase(R)) return fail("no phase");
  {
    bool common = false;
    for (const auto& [s, sig] : R.chosen)
      for (int f = 0; f < nf; ++f) {
        if (sig[f].empty()) continue;
        const auto it = B.chosen.find(s);
        if (it != B.chosen.end() && !it->second[f].empty()) common = true;
      }
    if (!common) return fail("no common frequency");
    std::vector<std::uint8_t> seen(5 * 64 * 2, 0);
    bool sat = false;
    for (std::size_t i = 0; i < R.row_prn.size(); ++i)
      seen[(R.row_sys[i] == 'J' ? 64 : 0) + std::clamp(R.row_prn[i], 0, 63)] = 1;
    for (std::size_t i = 0; i < B.row_prn.size(); ++i)
      if (seen[(B.row_sys[i] == 'J' ? 64 : 0) + std::clamp(B.row_prn[i], 0, 63)]) sat = true;
    if (!sat) return fail("no common satellite");
  }
  // satellite states at transmission of every row, rover then base (rtk.py transmit_states)
  const std::size_t mr = R.row_epoch.size(), mb = B.row_epoch.size(), m = mr + mb;
  std::vector<double> t_tag(m), code(m);
  std::vector<char> sys(m);
  std::vector<std::int64_t> prn(m);
  for (std::size_t i = 0; i < m; ++i) {
    const auto& T = i < mr ? R : B;
    const std::size_t r = i < mr ? i : i - mr;
    t_tag[i] = T.epoch_t_gps_s[static_cast<std::size_t>(T.row_epoch[r])];
    sys[i] = static_cast<char>(T.row_sys[r]);
    prn[i] = T.row_prn[r];
    double P = T.obs[r * 15 + 0];
    for (int f = 1; f < 3; ++f)
      if (!std::isfinite(P)) P = T.obs[r * 15 + f * 5];
    code[i] = P;
  }
  std::vector<std::array<double, 4>> sat_state(m, {NAN, NAN, NAN, NAN});  // r_e, c dt^s
  {
    // unique (t_ms, key) pairs in order of the key, first row of each
    std::vector<std::pair<std::int64_t, std::size_t>> pairs;
    for (std::size_t i = 0; i < m; ++i) {
      if (!(std::isfinite(code[i]) && code[i] > 1.0e6 && code[i] < 1.0e8)) continue;
      const std::int64_t key = (sys[i] == 'J' ? 4 : 0) * 64 + std::clamp<std::int64_t>(prn[i], 0, 63);
      const std::int64_t t_ms = static_cast<std::int64_t>(std::nearbyint(t_tag[i] * 1000.0));
      pairs.emplace_back(t_ms * 1000 + key, i);
    }
    std::stable_sort(pairs.begin(), pairs.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<std::size_t> u_rows, inv(m, SIZE_MAX);
    for (std::size_t q = 0; q < pairs.size(); ++q) {
      if (q == 0 || pairs[q].first != pairs[q - 1].first) u_rows.push_back(pairs[q].second);
      inv[pairs[q].second] = u_rows.size() - 1;
    }
    const std::size_t nu = u_rows.size();
    std::vector<double> t_ref(nu);
    for (std::size_t u = 0; u < nu; ++u) t_ref[u] = t_tag[u_rows[u]] - code[u_rows[u]] / kCLight;
    std::vector<std::array<double, 8>> st(nu);
    std::vector<std::uint8_t> valid(nu, 0);
    for (int s = 0; s < 2; ++s) {  // unique(system): G, then J
      const char letter = s == 0 ? 'G' : 'J';
      std::vector<std::size_t> rows;
      for (std::size_t u = 0; u < nu; ++u)
        if (sys[u_rows[u]] == letter) rows.push_back(u);
      if (rows.empty() || tab[s].prn.empty()) continue;
      std::vector<std::int64_t> rp(rows.size()), idx(rows.size());
      std::vector<double> rt(rows.size());
      for (std::size_t q = 0; q < rows.size(); ++q) {
        rp[q] = prn[u_rows[rows[q]]];
        rt[q] = t_ref[rows[q]];
      }
      if (select_nearest_record(tab[s].prn.data(), tab[s].usable.data(), tab[s].toe.data(), tab[s].fit_window.data(),
                                static_cast<std::int64_t>(tab[s].prn.size()), rp.data(), rt.data(),
                                static_cast<std::int64_t>(rows.size()), idx.data()) != Status::kOk)
        return fail("ephemeris selection");
      std::vector<std::int64_t> ok_idx;
      std::vector<double> ok_t;
      std::vector<std::size_t> ok_u;
      for (std::size_t q = 0; q < rows.size(); ++q)
        if (idx[q] >= 0) {
          ok_idx.push_back(idx[q]);
          ok_t.push_back(rt[q]);
          ok_u.push_back(rows[q]);
        }
      if (ok_idx.empty()) continue;
      std::vector<std::array<double, 8>> out;
      kepler_batch(tab[s], ok_idx, ok_t, out);
      for (std::size_t q = 0; q < ok_u.size(); ++q) {
        st[ok_u[q]] = out[q];
        valid[ok_u[q]] = std::isfinite(out[q][0]) && std::isfinite(out[q][1]) && std::isfinite(out[q][2]);
      }
    }
    const double w = kOmegaEDotGps;
    std::vector<std::array<double, 3>> a0(nu);
    for (std::size_t u = 0; u < nu; ++u) {
      const auto& S = st[u];
      const double rn = std::sqrt(S[0] * S[0] + S[1] * S[1] + S[2] * S[2]);
      const double rn3 = std::pow(rn, 3.0);
      // cross(w, v) and cross(w, cross(w, r)) with w = (0, 0, w), written as numpy's cross
      const double wv[3] = {0.0 * S[5] - w * S[4], w * S[3] - 0.0 * S[5], 0.0 * S[4] - 0.0 * S[3]};
      const double wr[3] = {0.0 * S[2] - w * S[1], w * S[0] - 0.0 * S[2], 0.0 * S[1] - 0.0 * S[0]};
      const double wwr[3] = {0.0 * wr[2] - w * wr[1], w * wr[0] - 0.0 * wr[2], 0.0 * wr[1] - 0.0 * wr[0]};
      for (int c = 0; c < 3; ++c) a0[u][c] = -wgs84::kGM * S[c] / rn3 - 2.0 * wv[c] - wwr[c];
    }
    for (std::size_t i = 0; i < m; ++i) {
      const std::size_t j = inv[i];
      if (j == SIZE_MAX || !valid[j]) continue;
      const auto& S = st[j];
      const double dt = (t_tag[i] - code[i] / kCLight - S[6]) - t_ref[j];
      if (!(std::abs(dt) < 0.05)) continue;
      for (int c = 0; c < 3; ++c) sat_state[i][c] = S[c] + S[3 + c] * dt + 0.5 * a0[j][c] * (dt * dt);
      sat_state[i][3] = kCLight * (S[6] + S[7] * dt);
    }
  }
  // each receiver's pseudoranges must fit one position and clock (rtk.py check_code_fit): a file that
  // does not is left to the usual path, which refuses it with one line naming it
  for (int k = 0; k < 2; ++k)
    if (code_fit_rms(rx[k], k == 0 ? 0 : mr, sat_state, code, rb) > kCodeFitToleranceM) return fail("code fit");
  // engine rows (rtk.py receiver_rows)
  std::vector<double> rows[2];
  for (int k = 0; k < 2; ++k) {
    const auto& T = rx[k].t;
    const std::size_t mk = T.row_epoch.size();
    rows[k].assign(mk * RtkRow::kCols, NAN);
    for (std::size_t i = 0; i < mk; ++i) {
      double* row = &rows[k][i * RtkRow::kCols];
      const char s = static_cast<char>(T.row_sys[i]);
      const int si = s == 'J' ? 4 : 0;
      row[0] = static_cast<double>(si * 64 + std::clamp(T.row_prn[i], 0, 63));
      row[1] = si;
      const auto ch = T.chosen.find(s);
      for (int f = 0; f < std::min(nf, 3); ++f) {
        double lam = NAN;
        if (ch != T.chosen.end() && !ch->second[f].empty()) lam = kCLight / band_hz(s, ch->second[f][0]);
        const double* o = &T.obs[i * 15 + f * 5];
        row[2 + 5 * f] = o[0];
        row[3 + 5 * f] = std::isfinite(lam) ? o[1] : NAN;
        row[4 + 5 * f] = o[2];
        row[5 + 5 * f] = std::isfinite(o[4]) ? static_cast<double>(static_cast<std::int64_t>(o[4])) : 0.0;
        row[6 + 5 * f] = lam;
      }
      const auto& ss = sat_state[(k == 0 ? 0 : mr) + i];
      row[17] = ss[0];
      row[18] = ss[1];
      row[19] = ss[2];
      row[20] = ss[3];
    }
  }
  // the engine over every rover epoch (bind_rtk.cpp rtk_run)
  const Vec3 rbv(rb[0], rb[1], rb[2]);
  auto eng = std::make_unique<RtkEngine>(opt);
  std::int64_t last_b = -1;
  std::string& pos = res.pos_text;
  std::string& tab_t = res.table_text;
  char buf[128];
  pos += "% program   : " + in.program + " rtk\n";
  pos += "% inp file  : " + in.rover_path + "\n";
  pos += "% inp file  : " + in.base_path + "\n";
  pos += "% ref pos   :";
  for (int i = 0; i < 3; ++i) put_f(pos, rb[i], 15, 4);
  pos += "\n% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)\n"
         "%  GPST                   latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  "
         "sdne(m)  sdeu(m)  sdun(m) age(s)  ratio\n";
  tab_t += "t_gps_s,status,ratio,n_fix,n_dd,n_sat,base_age_s,x_m,y_m,z_m,slips_lli,slips_geometry_free,"
           "slips_melbourne_wuebbena,slips_doppler,slips_gap,slips_outlier\n";
  for (std::size_t e = 0; e < nr_e; ++e) {
    RtkEpoch out;
    const std::int64_t b = bidx[e];
    if (b >= 0) {
      const auto& ro = rx[0].off;
      const auto& bo = rx[1].off;
      out = eng->process(R.epoch_t_gps_s[e], rows[0].data() + ro[e] * RtkRow::kCols,
                         static_cast<int>(ro[e + 1] - ro[e]), rows[1].data() + bo[b] * RtkRow::kCols,
                         static_cast<int>(bo[b + 1] - bo[b]), b != last_b, rbv);
      last_b = b;
    }
    const int q = static_cast<int>(out.status);
    ++res.epochs;
    if (q == 0) ++res.n_none;
    else if (q == 1) ++res.n_fixed;
    else if (q == 2) ++res.n_float;
    else if (q == 4) ++res.n_dgps;
    for (int s = 0; s < kNumSlipKinds; ++s) res.slips_total += out.slips[s];
    const double t = R.epoch_t_gps_s[e];
    const double age = b >= 0 ? t - B.epoch_t_gps_s[static_cast<std::size_t>(b)] : NAN;
    // .rtk.csv
    put_f(tab_t, t, 0, 3);
    std::snprintf(buf, sizeof buf, ",%d,", q);
    tab_t += buf;
    put_f(tab_t, out.ratio, 0, 2);
    std::snprintf(buf, sizeof buf, ",%d,%d,%d,", out.n_fix, out.n_dd, out.n_sat);
    tab_t += buf;
    if (std::isfinite(age)) put_f(tab_t, age, 0, 3);
    else tab_t += "nan";
    if (q > 0) {
      for (int c = 0; c < 3; ++c) {
        tab_t += ',';
        put_f(tab_t, out.r_e(c), 0, 4);
      }
    } else {
      tab_t += ",nan,nan,nan";
    }
    for (int s = 0; s < kNumSlipKinds; ++s) {
      std::snprintf(buf, sizeof buf, ",%d", static_cast<int>(out.slips[s]));
      tab_t += buf;
    }
    tab_t += '\n';
    if (q <= 0) continue;
    // .pos (rtk.py write_rtklib_pos): ENU covariance Q = C P C^T
    const Vec3 llh = wgs84::ecef_to_geodetic(out.r_e, 0.0);  // all 8 steps, as earth.py
    const double lat = llh(0), lon = llh(1), h = llh(2);
    const double sl = std::sin(lat), cl = std::cos(lat), so = std::sin(lon), co = std::cos(lon);
    const double C[3][3] = {{-so, co, 0.0}, {-sl * co, -sl * so, cl}, {cl * co, cl * so, sl}};
    double CP[3][3], Q[3][3];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double acc = 0.0;
        for (int l = 0; l < 3; ++l) acc += C[i][l] * out.P_r(l, j);
        CP[i][j] = acc;
      }
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double acc = 0.0;
        for (int l = 0; l < 3; ++l) acc += CP[i][l] * C[j][l];
        Q[i][j] = acc;
      }
    const double sd[3] = {std::sqrt(std::max(Q[0][0], 0.0)), std::sqrt(std::max(Q[1][1], 0.0)),
                          std::sqrt(std::max(Q[2][2], 0.0))};
    auto ss = [](double v) { return std::copysign(std::sqrt(std::abs(v)), v); };
    put_gpst(pos, t);
    pos += ' ';
    put_f(pos, lat * (180.0 / M_PI), 14, 9);
    pos += ' ';
    put_f(pos, lon * (180.0 / M_PI), 14, 9);
    pos += ' ';
    put_f(pos, h, 10, 4);
    pos += ' ';
    put_i(pos, q, 3);
    pos += ' ';
    put_i(pos, out.n_sat, 3);
    const double cols[6] = {sd[1], sd[0], sd[2], ss(Q[1][0]), ss(Q[0][2]), ss(Q[2][1])};
    for (double v : cols) {
      pos += ' ';
      put_f(pos, v, 8, 4);
    }
    pos += ' ';
    put_f(pos, std::isfinite(age) ? age : 0.0, 6, 2);
    pos += ' ';
    put_f(pos, out.ratio, 6, 1);
    pos += '\n';
  }
  res.ok = true;
  return res;
}

}  // namespace insnav::gnss

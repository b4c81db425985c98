// insnav/io/rinex_nav.hpp -- the records of a RINEX 2 / 3 navigation file (the
// body after the header), split into their fixed-width fields.
//
// The fast path of python/insnav/gnss/rinex.py (read_rinex_nav), which stays
// the reference and the reporter of every error: this scanner takes the same
// record structure (RINEX 2.11 and 3.05 navigation message formats, Tables A4
// and A6 of RINEX 3.05: a first line with the satellite, epoch and three clock
// values in fields of 19 characters, then 7 broadcast orbit lines of 4 values
// for GPS, Galileo and BeiDou, 3 (RINEX 3.05: optionally 4) for GLONASS) and
// gives up (NavScan::irregular) at the first thing the Python reader would
// report or treat specially, so that the caller then runs the Python reader.
// Numbers are the values Python's float() gives (a correctly rounded strtod of
// the field with the Fortran exponent D read as E); a blank field is NaN.
//
// Input: the body lines joined with '\n' (no other line break).  Output
// vectors grow with the records (one reader call per file, not a per-epoch loop).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

namespace insnav::io {

/// Values of one navigation record after the clock: 7 orbit lines of 4.
inline constexpr int kNavOrbitValues = 28;

/// Records of one navigation file, in file order (kept systems only).
struct NavScan {
  bool irregular = false;           // something the Python reader reports or handles itself
  std::vector<char> sys;            // 'G', 'R', 'E', 'C', 'J'
  std::vector<std::int64_t> prn;
  std::vector<std::int64_t> ymdhm;  // year (four digits), month, day, hour, minute per record
  std::vector<double> sec;          // seconds of the epoch
  std::vector<double> clk;          // 3 clock values per record (NaN: blank)
  std::vector<double> orbit;        // kNavOrbitValues per record (NaN: blank or absent)
  std::string skipped_sys;          // skipped record systems in order of first appearance
  std::vector<std::int64_t> skipped_count;
};

namespace detail {

inline bool nav_blank(std::string_view s) {
  for (char ch : s)
    if (ch != ' ') return false;
  return true;
}

/// Python int() of a field after strip(): [+-]digits; false for anything else (the caller gives up).
inline bool nav_int(std::string_view s, std::int64_t& out) {
  std::size_t a = 0, b = s.size();
  while (a < b && s[a] == ' ') ++a;
  while (b > a && s[b - 1] == ' ') --b;
  if (a == b) return false;
  bool neg = false;
  if (s[a] == '+' || s[a] == '-') {
    neg = s[a] == '-';
    ++a;
  }
  if (a == b || b - a > 12) return false;
  std::int64_t v = 0;
  for (std::size_t i = a; i < b; ++i) {
    if (s[i] < '0' || s[i] > '9') return false;
    v = 10 * v + (s[i] - '0');
  }
  out = neg ? -v : v;
  return true;
}

/// Python float() of a fixed-width field with D/d read as E: [sign] digits [. digits] [E [sign] digits]
/// between blanks; a blank (or absent) field is NaN when blank_ok.  False for anything else.
inline bool nav_float(std::string_view s, double& out, bool blank_ok) {
  std::size_t a = 0, b = s.size();
  while (a < b && s[a] == ' ') ++a;
  while (b > a && s[b - 1] == ' ') --b;
  if (a == b) {
    out = std::numeric_limits<double>::quiet_NaN();
    return blank_ok;
  }
  char buf[64];
  if (b - a >= sizeof(buf)) return false;
  std::size_t n = 0, i = a;
  if (s[i] == '+' || s[i] == '-') buf[n++] = s[i++];
  int digits = 0;
  while (i < b && s[i] >= '0' && s[i] <= '9') buf[n++] = s[i++], ++digits;
  if (i < b && s[i] == '.') {
    buf[n++] = s[i++];
    while (i < b && s[i] >= '0' && s[i] <= '9') buf[n++] = s[i++], ++digits;
  }
  if (digits == 0) return false;
  if (i < b && (s[i] == 'E' || s[i] == 'e' || s[i] == 'D' || s[i] == 'd')) {
    buf[n++] = 'E';
    ++i;
    if (i < b && (s[i] == '+' || s[i] == '-')) buf[n++] = s[i++];
    int ed = 0;
    while (i < b && s[i] >= '0' && s[i] <= '9') buf[n++] = s[i++], ++ed;
    if (ed == 0) return false;
  }
  if (i != b) return false;
  buf[n] = '\0';
  out = std::strtod(buf, nullptr);
  return true;
}

/// Field [a, a + w) of a line (the part inside the line; absent characters are blank).
inline std::string_view nav_field(std::string_view line, std::size_t a, std::size_t w) {
  if (a >= line.size()) return {};
  return line.substr(a, std::min(w, line.size() - a));
}

}  // namespace detail

/// Scan the body lines (joined with '\n').  rinex3: RINEX 3 layout (system letter in column 1);
/// else RINEX 2 (GPS, or GLONASS when glonass2).  want: the system letters to keep (others of a
/// RINEX 3 file are skipped and counted).  Records are appended to out; out.irregular on give-up.
inline void scan_rinex_nav_body(std::string_view body, bool rinex3, bool glonass2, std::string_view want,
                                NavScan& out) {
  // lines
  std::vector<std::string_view> lines;
  {
    std::size_t p = 0;
    while (p <= body.size()) {
      const std::size_t q = body.find('\n', p);
      const std::size_t e = q == std::string_view::npos ? body.size() : q;
      lines.push_back(body.substr(p, e - p));
      if (q == std::string_view::npos) break;
      p = q + 1;
    }
    if (!body.empty() && body.back() == '\n') lines.pop_back();
    if (body.empty()) lines.clear();
  }
  for (std::string_view l : lines)
    for (char ch : l)
      if (static_cast<unsigned char>(ch) < 0x20 || static_cast<unsigned char>(ch) >= 0x7f) {
        out.irregular = true;  // tabs, control characters, non-ASCII: the Python reader decides
        return;
      }
  const std::size_t width0 = rinex3 ? 23 : 22, cont = rinex3 ? 4 : 3;
  std::size_t i = 0;
  const std::size_t nl = lines.size();
  auto give_up = [&]() { out.irregular = true; };
  while (i < nl) {
    std::string_view line = lines[i++];
    if (detail::nav_blank(line)) continue;
    char sysid;
    std::int64_t prn = 0, y = 0, mo = 0, d = 0, h = 0, mi = 0;
    double sec = 0.0;
    if (rinex3) {
      sysid = line[0];
      if (!(sysid >= 'A' && sysid <= 'Z')) return give_up();
      const bool known = sysid == 'G' || sysid == 'R' || sysid == 'E' || sysid == 'C' || sysid == 'J';  // J: QZSS, GPS layout
      if (!known || want.find(sysid) == std::string_view::npos) {
        const std::size_t k = out.skipped_sys.find(sysid);
        if (k == std::string::npos) {
          out.skipped_sys.push_back(sysid);
          out.skipped_count.push_back(1);
        } else {
          ++out.skipped_count[k];
        }
        while (i < nl && !lines[i].empty() && lines[i][0] == ' ') ++i;
        continue;
      }
      if (!detail::nav_int(detail::nav_field(line, 1, 2), prn) || !detail::nav_int(detail::nav_field(line, 4, 4), y) ||
          !detail::nav_int(detail::nav_field(line, 9, 2), mo) || !detail::nav_int(detail::nav_field(line, 12, 2), d) ||
          !detail::nav_int(detail::nav_field(line, 15, 2), h) || !detail::nav_int(detail::nav_field(line, 18, 2), mi) ||
          !detail::nav_float(detail::nav_field(line, 21, 2), sec, false))
        return give_up();
    } else {
      sysid = glonass2 ? 'R' : 'G';
      if (line.size() >= 3 && line.substr(0, 3) == "   ") return give_up();
      if (!detail::nav_int(detail::nav_field(line, 0, 2), prn) || !detail::nav_int(detail::nav_field(line, 3, 2), y) ||
          !detail::nav_int(detail::nav_field(line, 6, 2), mo) || !detail::nav_int(detail::nav_field(line, 9, 2), d) ||
          !detail::nav_int(detail::nav_field(line, 12, 2), h) || !detail::nav_int(detail::nav_field(line, 15, 2), mi) ||
          !detail::nav_float(detail::nav_field(line, 17, 5), sec, false))
        return give_up();
      y += y < 80 ? 2000 : 1900;
    }
    if (!(1 <= mo && mo <= 12 && 1 <= d && d <= 31 && 0 <= h && h <= 23 && 0 <= mi && mi <= 59 && 0.0 <= sec &&
          sec < 61.0 && 0 <= prn && prn <= 99))
      return give_up();
    double clk[3];
    for (int k = 0; k < 3; ++k)
      if (!detail::nav_float(detail::nav_field(line, width0 + 19 * k, 19), clk[k], true)) return give_up();
    const int n_req = sysid == 'R' ? 3 : 7;
    const int n_max = sysid == 'R' ? (rinex3 ? 4 : 3) : 7;
    double orbit[kNavOrbitValues];
    for (double& v : orbit) v = std::numeric_limits<double>::quiet_NaN();
    for (int k = 0; k < n_max; ++k) {
      if (k >= n_req && (i >= nl || lines[i].empty() || lines[i][0] != ' ' || detail::nav_blank(lines[i]))) break;
      if (i >= nl) return give_up();  // unexpected end of file
      std::string_view cl = lines[i++];
      if (rinex3 && (cl.empty() || cl[0] != ' ')) return give_up();
      for (int q = 0; q < 4; ++q)
        if (!detail::nav_float(detail::nav_field(cl, cont + 19 * q, 19), orbit[4 * k + q], true)) return give_up();
    }
    out.sys.push_back(sysid);
    out.prn.push_back(prn);
    out.ymdhm.insert(out.ymdhm.end(), {y, mo, d, h, mi});
    out.sec.push_back(sec);
    out.clk.insert(out.clk.end(), clk, clk + 3);
    out.orbit.insert(out.orbit.end(), orbit, orbit + kNavOrbitValues);
  }
}

}  // namespace insnav::io

// insnav/io/rinex3_obs.hpp -- fast RINEX 3.02-3.05 observation reader for carrier-phase work:
// pseudorange, carrier phase, Doppler, C/N0 and the loss-of-lock indicator on up to three
// frequency slots per system.
//
// Format: Gurtner & Estey / IGS RINEX WG, "RINEX The Receiver Independent Exchange Format",
// version 3.05 (2020), Sec. 5.1 and Table A2-A3: an epoch line starts with '>', each satellite
// line holds 16-character fields, F14.3 value + LLI digit + signal-strength digit.
//
// The reader keeps one signal per (system, frequency slot): the first attribute of the slot's
// preference list whose carrier phase type ('L') is in the header (else whose pseudorange is),
// and the pseudorange / Doppler / C/N0 of the same attribute.  Every problem throws
// std::runtime_error "<file>, line <n>: <what>" (the Python layer turns it into RinexError).
#pragma once

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace insnav::io {

/// Per-slot columns of RinexObsTable::obs: pseudorange [m], phase [cycles], Doppler [Hz], C/N0 [dB-Hz], LLI.
inline constexpr int kObsPerSlot = 5;
inline constexpr int kObsSlots = 3;

struct RinexObsTable {
  std::string path;
  double version = 0.0;
  bool has_approx = false;
  double approx_r_e[3] = {NAN, NAN, NAN};
  double antenna_hen_m[3] = {0.0, 0.0, 0.0};  // ANTENNA: DELTA H/E/N
  std::string marker_name;
  std::map<int, int> glonass_channels;        // slot -> FDMA channel (GLONASS SLOT / FRQ #)
  std::map<char, std::array<std::string, kObsSlots>> chosen;  // system -> 3-char code ("1C") per slot
  std::vector<double> epoch_t_gps_s;          // GPS seconds since 1980-01-06
  std::vector<int> epoch_flag;
  std::vector<double> epoch_clock_s;          // receiver clock offset of the epoch line [s], NaN if blank
  std::vector<int> row_epoch, row_sys, row_prn;
  std::vector<double> obs;                    // n_rows x (kObsSlots * kObsPerSlot), NaN where missing
  /// Epochs (flag 0/1) at the very time of the epoch kept before them -- a merge or a logger writing one
  /// twice -- skipped whole (RTKLIB's sortobs keeps the first too), and the line of the first one.
  long n_repeated_epochs = 0;
  long first_repeated_line = 0;
};

namespace detail {

inline long days_from_civil(long y, unsigned m, unsigned d) {  // H. Hinnant's algorithm
  y -= m <= 2;
  const long era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<long>(doe) - 719468;
}

struct LineReader {
  const char* data;   // the whole text (not owned)
  size_t size;
  const std::string& path;
  size_t pos = 0;
  long lineno = 0;
  const char* b = nullptr;
  size_t len = 0;
  bool next() {
    if (pos >= size) return false;
    const void* nl = std::memchr(data + pos, '\n', size - pos);
    const size_t end = nl ? static_cast<size_t>(static_cast<const char*>(nl) - data) : size;
    b = data + pos;
    len = end - pos;
    if (len > 0 && b[len - 1] == '\r') --len;
    pos = end + 1;
    ++lineno;
    return true;
  }
  [[noreturn]] void fail(const std::string& what) const { fail_at(lineno, what); }
  [[noreturn]] void fail_at(long line, const std::string& what) const {
    throw std::runtime_error(path + ", line " + std::to_string(line) + ": " + what);
  }
  std::string field(size_t a, size_t n) const {
    if (a >= len) return std::string();
    return std::string(b + a, std::min(n, len - a));
  }
};

inline bool blank(const char* p, size_t n) {
  for (size_t i = 0; i < n; ++i)
    if (p[i] != ' ') return false;
  return true;
}

// Fixed-point fast path of parse_num: [p, p+n) is blanks, an optional '-', digits with at most one
// '.', blanks (RINEX F14.3, F11.7, I3 ... fields).  With at most 15 significant digits the integer
// mantissa m < 10^15 < 2^53 and the power 10^k (k <= 15 decimals) are exact doubles, so m / 10^k is
// one correctly rounded IEEE division: the value strtod returns (W. D. Clinger, "How to read
// floating point numbers accurately", PLDI 1990, the fast path).  Returns false (nothing written)
// for anything else -- blank, exponent, '+', more digits, a character inside -- left to strtod.
inline bool parse_fixed_fast(const char* p, size_t n, double& v) {
  static constexpr double kPow10[16] = {1e0, 1e1, 1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                        1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15};
  size_t i = 0;
  while (i < n && p[i] == ' ') ++i;
  const bool neg = i < n && p[i] == '-';
  if (neg) ++i;
  std::uint64_t m = 0;
  int n_digits = 0, significant = 0, decimals = -1;  // decimals: -1 before the '.'
  for (; i < n; ++i) {
    const char ch = p[i];
    if (ch >= '0' && ch <= '9') {
      ++n_digits;
      if (m != 0 || ch != '0') ++significant;  // leading zeros are free
      m = m * 10 + static_cast<std::uint64_t>(ch - '0');
      if (decimals >= 0) ++decimals;
      if (significant > 15 || decimals > 15) return false;
    } else if (ch == '.' && decimals < 0) {
      decimals = 0;
    } else {
      break;
    }
  }
  if (n_digits == 0) return false;
  while (i < n && p[i] == ' ') ++i;
  if (i != n) return false;  // an exponent, a second sign, a character inside: strtod decides
  double x = static_cast<double>(m);
  if (decimals > 0) x /= kPow10[decimals];
  v = neg ? -x : x;
  return true;
}

// Parse [p, p+n) as a number; NaN if blank; false if not a number.
inline bool parse_num(const char* p, size_t n, double& v) {
  n = std::min<size_t>(n, 39);  // the longest text the strtod route below reads
  if (parse_fixed_fast(p, n, v)) return true;
  if (blank(p, n)) {
    v = NAN;
    return true;
  }
  char buf[40];
  n = std::min<size_t>(n, sizeof(buf) - 1);
  std::memcpy(buf, p, n);
  buf[n] = 0;
  char* s = buf;
  while (*s == ' ') ++s;
  if (!*s) { v = NAN; return true; }
  for (char* q = s; *q; ++q)
    if (*q == 'D' || *q == 'd') *q = 'E';
  char* end = nullptr;
  v = std::strtod(s, &end);
  while (end && *end == ' ') ++end;
  return end && *end == 0;
}

inline int parse_int(const LineReader& L, size_t a, size_t n, const char* what) {
  double v;
  if (a + n > L.len || !parse_num(L.b + a, n, v) || !std::isfinite(v) || v != std::floor(v))
    L.fail(std::string("bad integer for ") + what + " '" + L.field(a, n) + "'");
  return static_cast<int>(v);
}

}  // namespace detail

/// Which header column holds each observation read: for every system letter, its number of
/// declared types (-1: not declared in the header), whether its rows are kept, and per frequency
/// slot the 0-based column of C, L, D, S (-1: not read).  ``names`` (e.g. "C1C") only label errors.
struct ObsColumns {
  std::array<int, 128> n_types;
  std::array<bool, 128> want{};
  std::array<std::array<std::array<int, 4>, kObsSlots>, 128> col;
  std::array<std::array<std::array<std::string, 4>, kObsSlots>, 128> names;
  /// RINEX 3.05 Sec. 5.1: a missing observation may be written as 0.0; true turns a 0.0 code or
  /// phase into NaN, false keeps the number as written.
  bool zero_is_missing = true;
  /// Each system's header types joined by one blank ("C1C L1C D1C S1C"; RINEX 2: the one list,
  /// under 'G'): an event that re-declares a different list is refused (EventTypes).
  std::array<std::string, 128> type_list;
  /// System ``s``'s header types: their count and type_list.
  void set_types(unsigned char s, const std::vector<std::string>& types) {
    n_types[s] = static_cast<int>(types.size());
    type_list[s].clear();
    for (const auto& t : types) type_list[s] += (type_list[s].empty() ? "" : " ") + t;
  }
  ObsColumns() {
    n_types.fill(-1);
    for (auto& a : col)
      for (auto& b : a) b.fill(-1);
  }
};

namespace detail {

/// Where header column ``cq`` of a satellite's observations is: the line holding it, the field's first
/// character in that line and the line number (RINEX 3: one line from column 4; RINEX 2: five fields a line).
struct ObsField {
  const char* b;
  size_t len;
  size_t a;
  long lineno;
};

inline std::string trimmed(std::string f) {
  while (!f.empty() && f.front() == ' ') f.erase(f.begin());
  while (!f.empty() && f.back() == ' ') f.pop_back();
  return f;
}

/// One satellite's observations into ``o`` (kObsSlots x kObsPerSlot, NaN on entry): for every slot the
/// C, L, D, S columns of ``c`` for system ``s`` (F14.3; a blank or absent field stays NaN), and the LLI digit
/// after the phase (0 where blank or absent).  ``field_of(cq)`` locates column ``cq``; ``bad(field, what)``
/// throws for a field that is not a number (``what``: the observation's name).  Shared by the RINEX 3 and
/// RINEX 2 record loops.
template <class FieldOf, class Bad>
inline void read_sat_observations(const ObsColumns& c, unsigned char s, const FieldOf& field_of, const Bad& bad,
                                  double* o) {
  for (int k = 0; k < kObsSlots; ++k) {
    double* slot = o + k * kObsPerSlot;
    for (int q = 0; q < 4; ++q) {
      const int cq = c.col[s][k][q];
      if (cq < 0) continue;
      const ObsField f = field_of(cq);
      if (q == 1) slot[4] = (f.a + 14 < f.len && f.b[f.a + 14] >= '0' && f.b[f.a + 14] <= '9') ? f.b[f.a + 14] - '0' : 0.0;
      if (f.a >= f.len) continue;
      double v;
      if (!parse_num(f.b + f.a, std::min<size_t>(14, f.len - f.a), v)) {
        bad(f, trimmed(std::string(f.b + f.a, std::min<size_t>(14, f.len - f.a))), c.names[s][k][q]);  // throws
        continue;
      }
      if (c.zero_is_missing && q <= 1 && v == 0.0) v = NAN;  // 0.000: not observed
      slot[q] = v;
    }
  }
}

/// Whether an epoch at ``t`` (line ``line``) repeats the time of the last epoch kept; counts it in
/// RinexObsTable::n_repeated_epochs (the repeat is skipped whole).
inline bool repeats_last_epoch(RinexObsTable& out, double t, long line) {
  if (out.epoch_t_gps_s.empty() || t != out.epoch_t_gps_s.back()) return false;
  if (out.n_repeated_epochs++ == 0) out.first_repeated_line = line;
  return true;
}

/// The observation types re-declared by the special records of one event (RINEX 3.05 Sec. 5.2.1,
/// RINEX 2.11 Sec. 7.7: epoch flag 4 is followed by header lines).  The records keep being read
/// with the header's columns, so a list that differs from the header's would misread every field
/// after it: refused, naming the event.  A repeat of the header's own list is accepted.
struct EventTypes {
  std::map<char, std::string> lists;  // system -> codes joined by one blank
  char cur = 0;
  long line = 0;  // the first record that declares types
  void add(const LineReader& L, bool rinex2) {
    const std::string label = L.len > 60 ? trimmed(L.field(60, 20)) : std::string();
    if (label != (rinex2 ? "# / TYPES OF OBSERV" : "SYS / # / OBS TYPES")) return;
    if (!line) line = L.lineno;
    const bool first = rinex2 ? !blank(L.b, std::min<size_t>(6, L.len)) : L.len > 0 && L.b[0] != ' ';
    if (first) {
      cur = rinex2 ? 'G' : L.b[0];
      lists[cur].clear();
    }
    if (!cur) return;  // a continuation without its first line: still a change
    std::string& out = lists[cur];
    const size_t a0 = rinex2 ? 10 : 7, step = rinex2 ? 6 : 4, n = rinex2 ? 2 : 3;
    for (size_t k = 0; k < (rinex2 ? 9u : 13u); ++k) {
      const std::string code = trimmed(L.field(a0 + step * k, n));
      if (code.empty()) continue;
      if (!out.empty()) out += ' ';
      out += code;
    }
  }
  void check(const LineReader& L, const ObsColumns& c, long ep_line) const {
    if (!line) return;
    for (const auto& [s, list] : lists)
      if (static_cast<unsigned char>(s) >= 128 || list != c.type_list[static_cast<unsigned char>(s)])
        L.fail_at(line, std::string("the event on line ") + std::to_string(ep_line) + " re-declares the observation types" +
                            (s ? std::string(" of ") + s : std::string()) +
                            " (not supported: the records after it would be misread); split the file before line " +
                            std::to_string(ep_line));
    if (lists.empty() || !cur)
      L.fail_at(line, "the event on line " + std::to_string(ep_line) +
                          " re-declares the observation types without a system or count");
  }
};

}  // namespace detail

/// Parse the records after END OF HEADER: text[offset, size) whose first line is line
/// ``lineno0 + 1`` of the file.  Epochs with flag 0 or 1 are kept, events (2-5) skipped with
/// their special records, flag 6 epochs read and dropped (as the header-driven reader does), and an
/// epoch at the time of the one kept before it skipped (RinexObsTable::n_repeated_epochs).
inline void read_rinex3_obs_body(const char* text, size_t size, const std::string& path, size_t offset,
                                 long lineno0, const ObsColumns& c, RinexObsTable& out) {
  detail::LineReader L{text, size, path};
  L.pos = offset;
  L.lineno = lineno0;
  constexpr int W = kObsSlots * kObsPerSlot;
  while (L.next()) {
    if (L.len == 0 || detail::blank(L.b, L.len)) continue;
    if (L.b[0] != '>') L.fail("bad record: expected an epoch line starting with '>'");
    auto epoch_int = [&](size_t a, size_t n) {
      double v;
      if (a + n > L.len || !detail::parse_num(L.b + a, n, v) || !std::isfinite(v) || v != std::floor(v))
        L.fail("bad record: cannot parse epoch line '" + L.field(0, 35) + "'");
      return static_cast<int>(v);
    };
    const int flag = epoch_int(31, 1), nsat = epoch_int(32, 3);
    // RINEX 3.05 Table A13: the date of an event (flags 2-5) may be blank
    const bool event = flag >= 2 && flag <= 5;
    int y = 1980, mo = 1, d = 6, h = 0, mi = 0;
    double sec = 0.0;
    if (!event) {
      y = epoch_int(2, 4), mo = epoch_int(7, 2), d = epoch_int(10, 2), h = epoch_int(13, 2), mi = epoch_int(16, 2);
      if (L.len < 29 || !detail::parse_num(L.b + 18, 11, sec) || !std::isfinite(sec))
        L.fail("bad record: cannot parse epoch line '" + L.field(0, 35) + "'");
    }
    double clk = NAN;
    if (L.len > 41 && !detail::parse_num(L.b + 41, std::min<size_t>(15, L.len - 41), clk)) {
      std::string f = L.field(41, 15);
      while (!f.empty() && f.front() == ' ') f.erase(f.begin());
      while (!f.empty() && f.back() == ' ') f.pop_back();
      L.fail("bad number '" + f + "' for receiver clock offset");
    }
    if (flag > 6 || nsat < 0)
      L.fail("bad record: epoch flag " + std::to_string(flag) + " / count " + std::to_string(nsat) + " out of range");
    const long ep_line = L.lineno;
    if (event) {  // nsat header lines follow
      detail::EventTypes types;
      for (int i = 0; i < nsat; ++i) {
        if (!L.next())
          L.fail_at(L.lineno + 1, "unexpected end of file while reading the special records of the event on line " +
                                      std::to_string(ep_line));
        types.add(L, false);
      }
      types.check(L, c, ep_line);
      continue;
    }
    if (!(mo >= 1 && mo <= 12 && d >= 1 && d <= 31 && h >= 0 && h <= 23 && mi >= 0 && mi <= 59 && sec >= 0 && sec < 61))
      L.fail("bad record: impossible epoch date/time");
    const double t = (detail::days_from_civil(y, mo, d) - detail::days_from_civil(1980, 1, 6)) * 86400.0 +
                     h * 3600.0 + mi * 60.0 + sec;
    const bool keep = (flag == 0 || flag == 1) && !detail::repeats_last_epoch(out, t, ep_line);
    const int e = static_cast<int>(out.epoch_t_gps_s.size());
    for (int i = 0; i < nsat; ++i) {
      if (!L.next())
        L.fail_at(L.lineno + 1, "unexpected end of file while reading the satellites of the epoch on line " +
                                    std::to_string(ep_line));
      if (L.len > 0 && L.b[0] == '>')
        L.fail("bad record: epoch on line " + std::to_string(ep_line) + " announces " + std::to_string(nsat) +
               " satellites, found fewer");
      const unsigned char s = L.len > 0 ? static_cast<unsigned char>(L.b[0]) : ' ';
      if (s >= 128 || c.n_types[s] < 0)
        L.fail("bad record: satellite '" + L.field(0, 3) + "' of an undeclared system");
      if (!keep || !c.want[s]) continue;
      const int prn = detail::parse_int(L, 1, 2, "satellite number");
      out.row_epoch.push_back(e);
      out.row_sys.push_back(s);
      out.row_prn.push_back(prn);
      const size_t base = out.obs.size();
      out.obs.resize(base + W, NAN);
      detail::read_sat_observations(
          c, s, [&](int cq) { return detail::ObsField{L.b, L.len, 3 + 16 * static_cast<size_t>(cq), L.lineno}; },
          [&](const detail::ObsField&, const std::string& f, const std::string& name) {
            L.fail("bad number '" + f + "' for observation " + name + " of " + L.field(0, 3));
          },
          out.obs.data() + base);
    }
    if (keep) {
      out.epoch_t_gps_s.push_back(t);
      out.epoch_flag.push_back(flag);
      out.epoch_clock_s.push_back(clk);
    }
  }
}

/// The records of a RINEX 2.10/2.11 file after END OF HEADER (Gurtner & Estey 2007, RINEX 2.11
/// Sec. 5 and Table A1): an epoch line (2-digit year, flag in column 29, satellite count and up to
/// 12 satellites, continued on further lines), then per satellite ceil(n/5) lines of 16-character
/// fields.  One list of types for every system: ``c.col`` of each wanted system holds columns of
/// that list for every frequency slot (e.g. C1 L1 D1 S1 on slot 0, P2 L2 D2 S2 on slot 1); a blank
/// system letter means GPS.
inline void read_rinex2_obs_body(const char* text, size_t size, const std::string& path, size_t offset,
                                 long lineno0, int n_types, const ObsColumns& c, RinexObsTable& out) {
  detail::LineReader L{text, size, path};
  L.pos = offset;
  L.lineno = lineno0;
  constexpr int W = kObsSlots * kObsPerSlot;
  const int nlines = std::max(1, (n_types + 4) / 5);
  struct Line { const char* b; size_t len; long lineno; };
  std::vector<Line> obs_lines(static_cast<size_t>(nlines));
  std::vector<std::array<char, 3>> sats;
  sats.reserve(64);
  using detail::trimmed;
  auto int_field = [&](size_t a, size_t n, int& v) {  // a field cut by the end of the line: what is there
    double x;
    if (a >= L.len || !detail::parse_num(L.b + a, std::min(n, L.len - a), x) || !std::isfinite(x) || x != std::floor(x))
      return false;
    v = static_cast<int>(x);
    return true;
  };
  while (L.next()) {
    if (L.len == 0 || detail::blank(L.b, L.len)) continue;
    const long ep_line = L.lineno;
    int flag = 0, nsat = 0;
    if (!int_field(28, 1, flag) || !int_field(29, 3, nsat))
      L.fail("bad record: cannot parse epoch flag / satellite count '" + L.field(26, 6) + "'");
    int y = 1, mo = 1, d = 1, h = 0, mi = 0;
    double sec = 0.0;
    if (!(flag >= 2 && flag <= 5)) {
      if (!int_field(1, 2, y) || !int_field(4, 2, mo) || !int_field(7, 2, d) || !int_field(10, 2, h) ||
          !int_field(13, 2, mi) || L.len <= 15 || !detail::parse_num(L.b + 15, std::min<size_t>(11, L.len - 15), sec) ||
          !std::isfinite(sec))
        L.fail("bad record: cannot parse epoch line '" + L.field(0, 32) + "'");
      y += y < 80 ? 2000 : 1900;
    }
    double clk = NAN;
    if (L.len > 68 && !detail::parse_num(L.b + 68, std::min<size_t>(12, L.len - 68), clk))
      L.fail("bad number '" + trimmed(L.field(68, 12)) + "' for receiver clock offset");
    if (flag > 6 || nsat < 0)
      L.fail("bad record: epoch flag " + std::to_string(flag) + " / count " + std::to_string(nsat) + " out of range");
    if (flag >= 2 && flag <= 5) {  // nsat header lines follow
      detail::EventTypes types;
      for (int i = 0; i < nsat; ++i) {
        if (!L.next())
          L.fail_at(L.lineno + 1, "unexpected end of file while reading the special records of the event on line " +
                                      std::to_string(ep_line));
        types.add(L, true);
      }
      types.check(L, c, ep_line);
      continue;
    }
    if (!(mo >= 1 && mo <= 12 && d >= 1 && d <= 31 && h >= 0 && h <= 23 && mi >= 0 && mi <= 59 && sec >= 0 && sec < 61))
      L.fail("bad record: impossible epoch date/time");
    const double t = (detail::days_from_civil(y, mo, d) - detail::days_from_civil(1980, 1, 6)) * 86400.0 +
                     h * 3600.0 + mi * 60.0 + sec;
    const bool keep = (flag == 0 || flag == 1) && !detail::repeats_last_epoch(out, t, ep_line);
    const int e = static_cast<int>(out.epoch_t_gps_s.size());
    sats.clear();
    while (true) {  // the satellite list: columns 33-68 of the epoch line and of its continuation lines
      for (int k = 0; k < 12; ++k) {
        const size_t a = 32 + 3 * static_cast<size_t>(k);
        if (a >= L.len || a >= 68) break;
        const size_t n = std::min<size_t>({3, L.len - a, 68 - a});
        if (detail::blank(L.b + a, n)) continue;
        std::array<char, 3> sid{' ', ' ', ' '};
        for (size_t q = 0; q < n; ++q) sid[q] = L.b[a + q];
        sats.push_back(sid);
      }
      if (static_cast<int>(sats.size()) >= nsat) break;
      if (!L.next())
        L.fail_at(L.lineno + 1, "unexpected end of file while reading the satellite list of the epoch on line " +
                                    std::to_string(ep_line));
    }
    if (static_cast<int>(sats.size()) != nsat)
      L.fail("bad record: epoch on line " + std::to_string(ep_line) + " announces " + std::to_string(nsat) +
             " satellites, lists " + std::to_string(sats.size()));
    for (const auto& sid : sats) {
      for (int q = 0; q < nlines; ++q) {
        if (!L.next())
          L.fail_at(L.lineno + 1, "unexpected end of file while reading the observations of the epoch on line " +
                                      std::to_string(ep_line));
        obs_lines[q] = Line{L.b, L.len, L.lineno};
      }
      const unsigned char s = sid[0] == ' ' ? 'G' : static_cast<unsigned char>(sid[0]);
      if (!keep || s >= 128 || !c.want[s]) continue;
      double prn_v;
      const std::string prn_txt(sid.data() + 1, 2);
      if (!detail::parse_num(prn_txt.data(), 2, prn_v) || !std::isfinite(prn_v) || prn_v != std::floor(prn_v))
        L.fail("bad integer '" + prn_txt + "' for satellite number");
      out.row_epoch.push_back(e);
      out.row_sys.push_back(s);
      out.row_prn.push_back(static_cast<int>(prn_v));
      const size_t base = out.obs.size();
      out.obs.resize(base + W, NAN);
      detail::read_sat_observations(
          c, s,
          [&](int cq) {
            const Line& ol = obs_lines[static_cast<size_t>(cq / 5)];
            return detail::ObsField{ol.b, ol.len, 16 * static_cast<size_t>(cq % 5), ol.lineno};
          },
          [&](const detail::ObsField& f, const std::string& txt, const std::string& name) {
            L.fail_at(f.lineno, "bad number '" + txt + "' for observation " + name);
          },
          out.obs.data() + base);
    }
    if (keep) {
      out.epoch_t_gps_s.push_back(t);
      out.epoch_flag.push_back(flag);
      out.epoch_clock_s.push_back(clk);
    }
  }
}

/// Read a RINEX 3 observation file.  prefs: system letter -> up to kObsSlots lists of
/// 2-character signal codes ("1C", "2W", ...) in order of preference; systems not in prefs are
/// skipped.  Throws std::runtime_error naming the file and line on malformed input.
inline RinexObsTable read_rinex3_obs(const std::string& path,
                                     const std::map<char, std::vector<std::vector<std::string>>>& prefs) {
  std::unique_ptr<char[]> buf;
  std::size_t n_text = 0;
  {
    // sized once and read in one call (a stringstream copy touches about three times the file), into
    // an uninitialised buffer (std::string::resize would first zero the few megabytes)
    std::ifstream f(path, std::ios::binary | std::ios::ate);
    if (!f) throw std::runtime_error(path + ": cannot read file");
    const std::streamoff size = f.tellg();
    if (size < 0) throw std::runtime_error(path + ": cannot read file");
    n_text = static_cast<std::size_t>(size);
    buf.reset(new char[n_text + 1]);
    f.seekg(0);
    if (size > 0 && !f.read(buf.get(), size)) throw std::runtime_error(path + ": cannot read file");
  }
  const char* text = buf.get();
  RinexObsTable out;
  out.path = path;
  char file_system = ' ';  // RINEX VERSION / TYPE column 41: G, R, E, C, J, I, S or M (mixed)
  detail::LineReader L{text, n_text, path};
  if (!L.next() || L.len < 61 || L.field(60, 20).find("RINEX VERSION / TYPE") == std::string::npos)
    L.fail("malformed header: first line is not 'RINEX VERSION / TYPE'");
  {
    double v;
    if (!detail::parse_num(L.b, 9, v) || !std::isfinite(v)) L.fail("malformed header: bad RINEX version");
    out.version = v;
    if (v < 3.0 || v >= 4.0) L.fail("unsupported RINEX version " + L.field(0, 9) + " (this reader: 3.02-3.05)");
    if (L.field(20, 1) != "O") L.fail("malformed header: not an observation file (type '" + L.field(20, 1) + "')");
    const std::string k = L.field(40, 1);
    file_system = k.empty() ? ' ' : static_cast<char>(std::toupper(static_cast<unsigned char>(k[0])));
  }
  std::map<char, std::vector<std::string>> types;  // system -> list of 3-char obs types
  std::map<char, int> announced;
  char cur = 0;
  bool end_header = false;
  while (L.next()) {
    const std::string label = L.len > 60 ? L.field(60, 20) : std::string();
    auto has = [&](const char* s) { return label.compare(0, std::strlen(s), s) == 0; };
    if (has("END OF HEADER")) { end_header = true; break; }
    if (has("SYS / # / OBS TYPES")) {
      if (L.b[0] != ' ') {
        cur = L.b[0];
        announced[cur] = detail::parse_int(L, 3, 3, "number of observation types");
        types[cur].clear();
      } else if (!cur) {
        L.fail("malformed header: SYS / # / OBS TYPES continuation without a system");
      }
      for (int k = 0; k < 13; ++k) {
        std::string c = L.field(7 + 4 * k, 3);
        while (!c.empty() && c.back() == ' ') c.pop_back();
        if (!c.empty() && static_cast<int>(types[cur].size()) < announced[cur]) types[cur].push_back(c);
      }
    } else if (has("APPROX POSITION XYZ")) {
      for (int k = 0; k < 3; ++k)
        if (!detail::parse_num(L.b + 14 * k, 14, out.approx_r_e[k])) L.fail("bad number in APPROX POSITION XYZ");
      out.has_approx = std::isfinite(out.approx_r_e[0]) && std::isfinite(out.approx_r_e[1]) &&
                       std::isfinite(out.approx_r_e[2]) &&
                       (out.approx_r_e[0] != 0.0 || out.approx_r_e[1] != 0.0 || out.approx_r_e[2] != 0.0);
    } else if (has("ANTENNA: DELTA H/E/N")) {
      for (int k = 0; k < 3; ++k) {
        double v;
        if (!detail::parse_num(L.b + 14 * k, 14, v)) L.fail("bad number in ANTENNA: DELTA H/E/N");
        out.antenna_hen_m[k] = std::isfinite(v) ? v : 0.0;
      }
    } else if (has("MARKER NAME")) {
      out.marker_name = L.field(0, 60);
      while (!out.marker_name.empty() && out.marker_name.back() == ' ') out.marker_name.pop_back();
    } else if (has("TIME OF FIRST OBS")) {
      // RINEX 3.05 Table A2: blank is the default of the file's system (GLO: UTC, BDT: GPS - 14 s);
      // GST and QZSST are steered to GPS time (python: gnss.rinex.DEFAULT_TIME_SYSTEM)
      const std::string ts = detail::trimmed(L.field(48, 3));
      std::string eff = ts;
      if (eff.empty()) {
        const char k = file_system;
        eff = k == 'R' ? "GLO" : k == 'E' ? "GAL" : k == 'C' ? "BDT" : k == 'J' ? "QZS" : k == 'I' ? "IRN" : "GPS";
      }
      if (eff != "GPS" && eff != "GAL" && eff != "QZS")
        L.fail("unsupported time system '" + eff + "'" +
               (ts.empty() ? " (the default of a RINEX file of system '" + std::string(1, file_system) +
                                 "' whose TIME OF FIRST OBS leaves the time system blank)"
                           : std::string()) +
               ": the epochs are read as GPS time (GPS, GAL or QZS); convert the file to GPS time");
    } else if (has("GLONASS SLOT / FRQ #")) {
      for (int k = 0; k < 8; ++k) {
        const size_t a = 4 + 7 * k;
        if (a + 6 > L.len || L.b[a] != 'R') continue;
        const int slot = detail::parse_int(L, a + 1, 2, "GLONASS slot");
        const int fcn = detail::parse_int(L, a + 4, 2, "GLONASS frequency number");
        out.glonass_channels[slot] = fcn;
      }
    }
  }
  if (!end_header) L.fail("malformed header: no END OF HEADER");
  for (const auto& [s, n] : announced)
    if (static_cast<int>(types[s].size()) != n)
      L.fail(std::string("malformed header: SYS / # / OBS TYPES of ") + s + " announces " + std::to_string(n) +
             " types, lists " + std::to_string(types[s].size()));
  ObsColumns c;
  for (const auto& [s, ty] : types)
    if (static_cast<unsigned char>(s) < 128) c.set_types(static_cast<unsigned char>(s), ty);
  for (const auto& [s, slots] : prefs) {
    if (static_cast<unsigned char>(s) >= 128) continue;
    c.want[s] = types.count(s) > 0;
    auto& ch = out.chosen[s];
    const auto& ty = types[s];
    auto index = [&](const std::string& t) {
      for (size_t i = 0; i < ty.size(); ++i)
        if (ty[i] == t) return static_cast<int>(i);
      return -1;
    };
    for (int k = 0; k < kObsSlots && k < static_cast<int>(slots.size()); ++k) {
      std::string pick;
      for (const auto& code : slots[k])
        if (index("L" + code) >= 0) { pick = code; break; }
      if (pick.empty())
        for (const auto& code : slots[k])
          if (index("C" + code) >= 0) { pick = code; break; }
      ch[k] = pick;
      if (pick.empty()) continue;
      const char kinds[4] = {'C', 'L', 'D', 'S'};
      for (int q = 0; q < 4; ++q) {
        c.col[s][k][q] = index(std::string(1, kinds[q]) + pick);
        c.names[s][k][q] = std::string(1, kinds[q]) + pick;
      }
    }
  }
  read_rinex3_obs_body(text, n_text, path, L.pos, L.lineno, c, out);
  return out;
}

}  // namespace insnav::io

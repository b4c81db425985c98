// insnav/io/text_table.hpp -- numeric text tables at memory speed: a writer
// (std::to_chars, row blocks formatted on several threads and written in
// order) and a reader (std::from_chars, split at a line boundary over several
// threads, counting lines as it goes so that the first bad value is reported
// by line and column).  Plain C++17, no Python; the bindings add the
// interrupt check through the `keep_going` hook (bind_textio.cpp).
#pragma once

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

namespace insnav::textio {

// ----------------------------------------------------------------- writer

/// One output column: value(r) = scale * data[r * stride].
struct Column {
  const double* data = nullptr;
  std::ptrdiff_t stride = 1;  // [elements]
  double scale = 1.0;
  int decimals = -1;          // >= 0: fixed with that many decimals; < 0: shortest round-trip
};

struct TextFormat {
  char sep = ',';
  int width = 0;              // > 0: left-justify each value in this many characters (KF-GINS "%-15.9lf ")
  bool trim_zeros = true;     // fixed decimals: drop trailing zeros (and a trailing '.')
  bool trailing_sep = false;  // a separator after the last value of a row too
};

/// Longest text one value can take (shortest round-trip: 24; fixed: guarded below).
constexpr int kMaxValueChars = 48;

/// Fixed notation with `decimals` digits after the point (0..15), exactly as
/// std::to_chars / printf("%.*f") round, without their cost: the value is
/// scaled to an integer m = round(v 10^d) and m's digits are printed.  The
/// residual v 10^d - m (one fma, exact to a few ulp) proves the rounding; when
/// it is within 1e-7 of a half (a possible tie or double rounding), or the
/// scaled value is too large for the integer path, the caller falls back to
/// std::to_chars.  Returns nullptr in that case.
inline char* format_fixed_fast(char* p, double v, int decimals, bool trim) {
  static constexpr double kPow10[16] = {1e0, 1e1, 1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                        1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15};
  if (decimals < 0 || decimals > 15) return nullptr;
  const double scale = kPow10[decimals];
  const double s = v * scale;
  if (!(std::fabs(s) < 1e15)) return nullptr;  // also NaN
  const double m = std::nearbyint(s);
  const double r = std::fma(v, scale, -m);
  if (!(std::fabs(r) < 0.4999999)) return nullptr;
  std::uint64_t u = static_cast<std::uint64_t>(std::fabs(m));
  char digits[24];
  int nd = 0;
  do {
    digits[nd++] = static_cast<char>('0' + u % 10);
    u /= 10;
  } while (u != 0);
  while (nd < decimals + 1) digits[nd++] = '0';  // digits[] is little-endian: pad the integer part with 0
  int lo = 0;                                    // lowest fractional digit printed
  if (trim)
    while (lo < decimals && digits[lo] == '0') ++lo;
  if (std::signbit(v) && !(trim && m == 0.0)) *p++ = '-';
  for (int i = nd - 1; i >= decimals; --i) *p++ = digits[i];
  if (lo < decimals) {
    *p++ = '.';
    for (int i = decimals - 1; i >= lo; --i) *p++ = digits[i];
  }
  return p;
}

/// Append the text of one value at p; returns the new end.
inline char* format_value(char* p, double v, int decimals, bool trim) {
  if (std::isnan(v)) {
    std::memcpy(p, "nan", 3);
    return p + 3;
  }
  if (decimals >= 0) {
    if (char* e = format_fixed_fast(p, v, decimals, trim)) return e;
  }
  // fixed notation only where it is short; huge values (and inf) go shortest
  if (decimals >= 0 && decimals <= 20 && std::fabs(v) < 1e21) {
    char* e = std::to_chars(p, p + kMaxValueChars, v, std::chars_format::fixed, decimals).ptr;
    if (trim) {
      if (decimals > 0) {
        while (e[-1] == '0') --e;
        if (e[-1] == '.') --e;
      }
      if (e - p == 2 && p[0] == '-' && p[1] == '0') {  // "-0" after rounding: "0"
        p[0] = '0';
        e = p + 1;
      }
    }
    return e;
  }
  return std::to_chars(p, p + kMaxValueChars, v).ptr;
}

/// Rows [r0, r1) of the columns as text, appended to buf.
inline void format_rows(const Column* cols, int ncols, std::int64_t r0, std::int64_t r1, const TextFormat& fmt,
                        std::string& buf) {
  const int per_value = std::max(kMaxValueChars, fmt.width) + 1;
  const std::size_t need = static_cast<std::size_t>(r1 - r0) * (static_cast<std::size_t>(ncols) * per_value + 1);
  const std::size_t start = buf.size();
  buf.resize(start + need);
  char* p = buf.data() + start;
  for (std::int64_t r = r0; r < r1; ++r) {
    for (int j = 0; j < ncols; ++j) {
      const Column& c = cols[j];
      char* b = p;
      p = format_value(p, c.scale * c.data[r * c.stride], c.decimals, fmt.trim_zeros);
      if (fmt.width > 0)
        while (p - b < fmt.width) *p++ = ' ';
      if (j + 1 < ncols || fmt.trailing_sep) *p++ = fmt.sep;
    }
    *p++ = '\n';
  }
  buf.resize(static_cast<std::size_t>(p - buf.data()));
}

enum class WriteStatus { kOk = 0, kIoError = 1, kInterrupted = 2 };

struct WriteResult {
  WriteStatus status = WriteStatus::kOk;
  int error = 0;            // errno of a failed write
  std::int64_t bytes = 0;
};

/// Write n rows to f: blocks of `block_rows` are formatted by `threads`
/// threads (block i by thread i % threads) and written in order, each thread
/// writing its block as soon as the previous one is out, so formatting and
/// writing overlap.  `keep_going` (may be empty) is called on the calling
/// thread after each of its blocks; false stops the write (kInterrupted).
inline WriteResult write_rows(std::FILE* f, const Column* cols, int ncols, std::int64_t n, const TextFormat& fmt,
                              int threads = 2, std::int64_t block_rows = 8192,
                              const std::function<bool()>& keep_going = {}) {
  WriteResult res;
  if (n <= 0) return res;
  threads = std::max(1, std::min<int>(threads, static_cast<int>((n + block_rows - 1) / block_rows)));
  const std::int64_t nblocks = (n + block_rows - 1) / block_rows;
  std::mutex m;
  std::condition_variable cv;
  std::int64_t next_write = 0;
  std::atomic<bool> stop{false};

  auto worker = [&](int tid) {
    std::string buf;
    for (std::int64_t b = tid; b < nblocks && !stop.load(); b += threads) {
      buf.clear();
      format_rows(cols, ncols, b * block_rows, std::min(n, (b + 1) * block_rows), fmt, buf);
      if (tid == 0 && keep_going && !keep_going()) {
        std::lock_guard<std::mutex> lk(m);
        if (res.status == WriteStatus::kOk) res.status = WriteStatus::kInterrupted;
        stop = true;
        cv.notify_all();
        return;
      }
      std::unique_lock<std::mutex> lk(m);
      cv.wait(lk, [&] { return next_write == b || stop.load(); });
      if (stop.load()) return;
      lk.unlock();  // only this thread writes now: block b is next
      const std::size_t w = std::fwrite(buf.data(), 1, buf.size(), f);
      lk.lock();
      if (w != buf.size()) {
        res.status = WriteStatus::kIoError;
        res.error = errno ? errno : EIO;
        stop = true;
      } else {
        res.bytes += static_cast<std::int64_t>(w);
        next_write = b + 1;
      }
      cv.notify_all();
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker, t);
  worker(0);
  for (auto& th : pool) th.join();
  return res;
}

// ----------------------------------------------------------------- reader

struct ParseOptions {
  int ncols = 0;          // values a row must have
  int keep = 0;           // the first `keep` of them are stored (<= ncols)
  bool allow_extra = false;  // rows may have more than ncols values (not parsed)
  bool comma = false;     // ',' separates values too (CSV)
};

enum class ParseErrorKind { kNone = 0, kColumns = 1, kNumber = 2 };

/// The first bad row: its line (1-based, relative to the block's first line),
/// the values found (kColumns) or the bad value's column (0-based) and its
/// byte range in the buffer (kNumber), and where that line ends.
struct ParseError {
  ParseErrorKind kind = ParseErrorKind::kNone;
  std::int64_t line = 0;
  int found = 0;
  int column = 0;
  std::size_t token_begin = 0, token_end = 0, line_end = 0;
};

struct ParseBlock {
  std::int64_t rows = 0;     // rows stored
  std::int64_t lines = 0;    // lines seen (a last line without '\n' counts)
  bool blank = false;        // a blank line was skipped
  ParseError error;
};

inline bool is_space(char c, bool comma) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f' || (comma && c == ',');
}

/// One value [b, e) (Python float() syntax for decimal numbers: optional
/// sign, inf, nan); false if it is not a number.
inline bool parse_value(const char* b, const char* e, double& v) {
  const char* p = b;
  if (p < e && *p == '+' && p + 1 < e && p[1] != '-' && p[1] != '+') ++p;
  const auto r = std::from_chars(p, e, v);
  if (r.ec == std::errc() && r.ptr == e) return true;
  if (r.ec == std::errc::result_out_of_range && r.ptr == e && e - b < 400) {  // over/underflow: as strtod
    char tmp[408];
    std::memcpy(tmp, b, static_cast<std::size_t>(e - b));
    tmp[e - b] = '\0';
    char* end = nullptr;
    v = std::strtod(tmp, &end);
    return end == tmp + (e - b);
  }
  return false;
}

/// Parse [b, e) (whole lines) into out (row-major, keep values a row, room
/// for as many rows as the block has lines); line_of (may be null) gets the
/// line of each row, counted from first_line.  Stops at the first bad row.
inline ParseBlock parse_block(const char* base, std::size_t b, std::size_t e, const ParseOptions& opt,
                              std::int64_t first_line, double* out, std::int64_t* line_of) {
  ParseBlock res;
  const char* s = base + b;
  const char* end = base + e;
  std::int64_t line = first_line;
  while (s < end) {
    const char* nl = static_cast<const char*>(std::memchr(s, '\n', static_cast<std::size_t>(end - s)));
    const char* le = nl ? nl : end;
    ++res.lines;
    const char* p = s;
    int col = 0;
    double* row = out + res.rows * opt.keep;
    while (true) {
      while (p < le && is_space(*p, opt.comma)) ++p;
      if (p == le) break;
      const char* tb = p;
      while (p < le && !is_space(*p, opt.comma)) ++p;
      if (col >= opt.ncols) {  // extra values: not parsed, counted for the message
        ++col;
        continue;
      }
      double v;
      if (!parse_value(tb, p, v)) {
        res.error = {ParseErrorKind::kNumber, line, 0, col, static_cast<std::size_t>(tb - base),
                     static_cast<std::size_t>(p - base), static_cast<std::size_t>(le - base)};
        return res;
      }
      if (col < opt.keep) row[col] = v;
      ++col;
    }
    if (col == 0) {
      res.blank = true;
    } else if (col < opt.ncols || (col > opt.ncols && !opt.allow_extra)) {
      res.error = {ParseErrorKind::kColumns, line, col, 0, 0, 0, static_cast<std::size_t>(le - base)};
      return res;
    } else {
      if (line_of) line_of[res.rows] = line;
      ++res.rows;
    }
    ++line;
    s = nl ? nl + 1 : end;
  }
  return res;
}

/// Lines in [b, e): newlines, plus one for a last line without one.
inline std::int64_t count_lines(const char* b, const char* e) {
  std::int64_t n = std::count(b, e, '\n');
  if (e > b && e[-1] != '\n') ++n;
  return n;
}

struct ParseResult {
  std::int64_t rows = 0;
  bool blank = false;
  ParseError error;  // line numbers absolute (from first_line)
};

/// Parse the whole buffer on up to `threads` threads (split at line
/// boundaries).  out must hold count_lines(data, data+size) rows of
/// opt.keep values, line_of as many lines.  Rows are contiguous on return.
inline ParseResult parse_buffer(const char* data, std::size_t size, const ParseOptions& opt, std::int64_t first_line,
                                double* out, std::int64_t* line_of, int threads = 2) {
  ParseResult res;
  threads = (size < (std::size_t(1) << 20)) ? 1 : std::max(1, threads);
  std::vector<std::size_t> cut{0};
  for (int t = 1; t < threads; ++t) {
    std::size_t c = size * static_cast<std::size_t>(t) / static_cast<std::size_t>(threads);
    const void* nl = std::memchr(data + c, '\n', size - c);
    c = nl ? static_cast<std::size_t>(static_cast<const char*>(nl) - data) + 1 : size;
    if (c > cut.back()) cut.push_back(c);
  }
  if (cut.back() < size) cut.push_back(size);
  const int nb = static_cast<int>(cut.size()) - 1;
  if (nb <= 0) return res;
  std::vector<std::int64_t> line0(nb, first_line), row0(nb, 0);
  for (int i = 1; i < nb; ++i) {
    const std::int64_t prev = count_lines(data + cut[i - 1], data + cut[i]);
    line0[i] = line0[i - 1] + prev;
    row0[i] = row0[i - 1] + prev;  // room: one row per line
  }
  std::vector<ParseBlock> blocks(nb);
  auto job = [&](int i) {
    blocks[i] = parse_block(data, cut[i], cut[i + 1], opt, line0[i], out + row0[i] * opt.keep,
                            line_of ? line_of + row0[i] : nullptr);
  };
  std::vector<std::thread> pool;
  for (int i = 1; i < nb; ++i) pool.emplace_back(job, i);
  job(0);
  for (auto& th : pool) th.join();
  for (int i = 0; i < nb; ++i) {
    const ParseBlock& bl = blocks[i];
    if (bl.error.kind != ParseErrorKind::kNone) {
      res.error = bl.error;
      return res;
    }
    if (row0[i] != res.rows) {  // close the gap left by blank lines before this block
      std::memmove(out + res.rows * opt.keep, out + row0[i] * opt.keep,
                   static_cast<std::size_t>(bl.rows * opt.keep) * sizeof(double));
      if (line_of)
        std::memmove(line_of + res.rows, line_of + row0[i], static_cast<std::size_t>(bl.rows) * sizeof(std::int64_t));
    }
    res.rows += bl.rows;
    res.blank = res.blank || bl.blank;
  }
  return res;
}

}  // namespace insnav::textio

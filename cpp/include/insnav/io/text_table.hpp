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
#include <memory>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "insnav/io/direct_file.hpp"

namespace insnav::textio {

// The formatter's pieces are forced inline into format_rows, so that its
// x86-64-v3 copy (format_rows below) compiles them with the FMA and SSE4.1
// rounding instructions instead of calls to libm's fma and nearbyint.
#if defined(__GNUC__) || defined(__clang__)
#define INSNAV_TEXTIO_INLINE __attribute__((always_inline)) inline
#else
#define INSNAV_TEXTIO_INLINE inline
#endif

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

/// x < 10^8 as 8 ASCII digits in one word, the first digit in the lowest byte
/// (SWAR: the four-digit halves, then pairs, then digits split in parallel
/// lanes by multiply-shift division; n * 10486 >> 20 = n / 100 for n < 10^4,
/// n * 103 >> 10 = n / 10 for n < 100).
INSNAV_TEXTIO_INLINE std::uint64_t ascii_8_digits(std::uint32_t x) {
  std::uint64_t v = (x / 10000) | (static_cast<std::uint64_t>(x % 10000) << 32);
  std::uint64_t hi = ((v * 10486) >> 20) & 0x0000007F0000007FULL;
  v = hi | ((v - hi * 100) << 16);
  hi = ((v * 103) >> 10) & 0x000F000F000F000FULL;
  v = hi | ((v - hi * 10) << 8);
  return v + 0x3030303030303030ULL;
}

/// Trailing / leading zero bits of a non-zero word.
INSNAV_TEXTIO_INLINE int ctz64(std::uint64_t x) {
#if defined(__GNUC__) || defined(__clang__)
  return __builtin_ctzll(x);
#else
  int n = 0;
  while (!(x & 1)) x >>= 1, ++n;
  return n;
#endif
}
INSNAV_TEXTIO_INLINE int clz64(std::uint64_t x) {
#if defined(__GNUC__) || defined(__clang__)
  return __builtin_clzll(x);
#else
  int n = 0;
  while (!(x >> 63)) x <<= 1, ++n;
  return n;
#endif
}

/// Bytes [k, k + 16) of the 16 bytes (lo, hi) (little-endian; zeros shifted in) stored at p.
INSNAV_TEXTIO_INLINE void store_from_byte(char* p, std::uint64_t lo, std::uint64_t hi, int k) {
  std::uint64_t a = lo, b = hi;
  if (k >= 8) {
    a = hi >> (8 * (k - 8));
    b = 0;
  } else if (k > 0) {
    a = (lo >> (8 * k)) | (hi << (64 - 8 * k));
    b = hi >> (8 * k);
  }
  std::memcpy(p, &a, 8);
  std::memcpy(p + 8, &b, 8);
}

/// Fixed notation with `decimals` digits after the point (0..15), exactly as
/// std::to_chars / printf("%.*f") round, without their cost: the value is
/// scaled to an integer m = round(v 10^d) whose 16 digits are made in two
/// words (ascii_8_digits) and stored from registers.  The residual
/// v 10^d - m (one fma, exact to a few ulp) proves the rounding; when it is
/// within 1e-7 of a half (a possible tie or double rounding), or the scaled
/// value is too large for the integer path, the caller falls back to
/// std::to_chars.  Returns nullptr in that case.  Writes up to 34 characters
/// at p (the caller reserves kMaxValueChars) and returns the end of the value.
INSNAV_TEXTIO_INLINE char* format_fixed_fast(char* p, double v, int decimals, bool trim) {
  static constexpr double kPow10[16] = {1e0, 1e1, 1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                        1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15};
  if (decimals < 0 || decimals > 15) return nullptr;
  const double scale = kPow10[decimals];
  const double s = v * scale;
  if (!(std::fabs(s) < 1e15)) return nullptr;  // also NaN
  const double m = std::nearbyint(s);
  const double r = std::fma(v, scale, -m);
  if (!(std::fabs(r) < 0.4999999)) return nullptr;
  const std::uint64_t u = static_cast<std::uint64_t>(std::fabs(m));  // < 10^15: 16 digits, the first one 0
  const std::uint64_t lo = ascii_8_digits(static_cast<std::uint32_t>(u / 100000000));  // digits 0..7
  const std::uint64_t hi = ascii_8_digits(static_cast<std::uint32_t>(u % 100000000));  // digits 8..15
  const std::uint64_t zlo = lo - 0x3030303030303030ULL, zhi = hi - 0x3030303030303030ULL;  // digit values
  const int point = 16 - decimals;  // digits [point, 16): the fraction
  // the integer part from the first non-zero digit, at least one digit
  const int lead = zlo ? ctz64(zlo) / 8 : (zhi ? 8 + ctz64(zhi) / 8 : 16);
  const int first = std::min(lead, point - 1);
  int last = 16;  // one past the last fractional digit printed
  if (trim) {
    last = zhi ? 16 - clz64(zhi) / 8 : (zlo ? 8 - clz64(zlo) / 8 : 0);
    last = std::max(last, point);
  }
  if (std::signbit(v) && !(trim && m == 0.0)) *p++ = '-';
  store_from_byte(p, lo, hi, first);
  p += point - first;
  if (last > point) {
    *p = '.';
    store_from_byte(p + 1, lo, hi, point);
    p += 1 + (last - point);
  }
  return p;
}

/// Append the text of one value at p; returns the new end.
INSNAV_TEXTIO_INLINE char* format_value(char* p, double v, int decimals, bool trim) {
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

/// A text buffer that grows without zero-filling: of the room reserved for
/// the longest possible rows only what is formatted is ever touched (and
/// counts in the resident memory).
struct TextBuffer {
  std::unique_ptr<char[]> data;
  std::size_t size = 0, capacity = 0;

  /// Room for n more characters at data + size.
  char* room(std::size_t n) {
    if (size + n > capacity) {
      const std::size_t cap = std::max(size + n, 2 * capacity);
      std::unique_ptr<char[]> grown(new char[cap]);
      if (size) std::memcpy(grown.get(), data.get(), size);
      data = std::move(grown);
      capacity = cap;
    }
    return data.get() + size;
  }
};

/// Rows [r0, r1) of the columns as text, appended to buf (format_rows: the
/// fastest copy this CPU runs).
INSNAV_TEXTIO_INLINE void format_rows_generic(const Column* cols, int ncols, std::int64_t r0, std::int64_t r1,
                                              const TextFormat& fmt, TextBuffer& buf) {
  const int per_value = std::max(kMaxValueChars, fmt.width) + 1;
  const std::size_t need = static_cast<std::size_t>(r1 - r0) * (static_cast<std::size_t>(ncols) * per_value + 1);
  char* const start = buf.room(need);
  char* p = start;
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
  buf.size += static_cast<std::size_t>(p - start);
}

#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__)
/// format_rows_generic compiled for x86-64-v3 (Haswell and later): std::fma
/// and std::nearbyint become single instructions (vfmadd, vroundsd) instead
/// of library calls, about half the time per value.  Both are correctly
/// rounded operations either way, so the text is the same byte for byte
/// (tests/test_text_readers.py, tests/test_direct_io.py).
__attribute__((target("avx2,fma,bmi,bmi2,popcnt"))) inline void format_rows_x86_v3(
    const Column* cols, int ncols, std::int64_t r0, std::int64_t r1, const TextFormat& fmt, TextBuffer& buf) {
  format_rows_generic(cols, ncols, r0, r1, fmt, buf);
}

inline bool cpu_runs_x86_v3() {
  static const bool ok = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
                         __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2") &&
                         __builtin_cpu_supports("popcnt");
  return ok;
}
#endif

/// Rows [r0, r1) of the columns as text, appended to buf.
inline void format_rows(const Column* cols, int ncols, std::int64_t r0, std::int64_t r1, const TextFormat& fmt,
                        TextBuffer& buf) {
#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__)
  if (cpu_runs_x86_v3()) return format_rows_x86_v3(cols, ncols, r0, r1, fmt, buf);
#endif
  format_rows_generic(cols, ncols, r0, r1, fmt, buf);
}

enum class WriteStatus { kOk = 0, kIoError = 1, kInterrupted = 2 };

struct WriteResult {
  WriteStatus status = WriteStatus::kOk;
  int error = 0;            // errno of a failed write
  std::int64_t bytes = 0;
};

/// Write n rows through put(data, size) -> 0 or an errno: blocks of
/// `block_rows` are formatted by `threads` threads (block i by thread
/// i % threads) and put in order, each thread putting its block as soon as
/// the previous one is out, so formatting and writing overlap.  `keep_going`
/// (may be empty) is called on the calling thread after each of its blocks;
/// false stops the write (kInterrupted).  `buffers` (may be null): one
/// TextBuffer per thread kept by a caller that writes many tables (their
/// memory is then touched once, not once per call).
template <class Put>
WriteResult write_rows_to(Put&& put, const Column* cols, int ncols, std::int64_t n, const TextFormat& fmt,
                          int threads = 2, std::int64_t block_rows = 8192,
                          const std::function<bool()>& keep_going = {}, TextBuffer* buffers = nullptr) {
  WriteResult res;
  if (n <= 0) return res;
  threads = std::max(1, std::min<int>(threads, static_cast<int>((n + block_rows - 1) / block_rows)));
  const std::int64_t nblocks = (n + block_rows - 1) / block_rows;
  std::mutex m;
  std::condition_variable cv;
  std::int64_t next_write = 0;
  std::atomic<bool> stop{false};

  auto worker = [&](int tid) {
    TextBuffer own;
    TextBuffer& buf = buffers ? buffers[tid] : own;
    for (std::int64_t b = tid; b < nblocks && !stop.load(); b += threads) {
      buf.size = 0;
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
      const int e = put(static_cast<const char*>(buf.data.get()), buf.size);
      lk.lock();
      if (e != 0) {
        res.status = WriteStatus::kIoError;
        res.error = e;
        stop = true;
      } else {
        res.bytes += static_cast<std::int64_t>(buf.size);
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

/// write_rows_to on a stdio file.
inline WriteResult write_rows(std::FILE* f, const Column* cols, int ncols, std::int64_t n, const TextFormat& fmt,
                              int threads = 2, std::int64_t block_rows = 8192,
                              const std::function<bool()>& keep_going = {}) {
  return write_rows_to(
      [f](const char* p, std::size_t k) { return std::fwrite(p, 1, k, f) == k ? 0 : (errno ? errno : EIO); }, cols,
      ncols, n, fmt, threads, block_rows, keep_going);
}

/// write_rows_to on a DirectFile (direct_file.hpp).
inline WriteResult write_rows(DirectFile& f, const Column* cols, int ncols, std::int64_t n, const TextFormat& fmt,
                              int threads = 2, std::int64_t block_rows = 8192,
                              const std::function<bool()>& keep_going = {}) {
  return write_rows_to([&f](const char* p, std::size_t k) { return f.write(p, k); }, cols, ncols, n, fmt, threads,
                       block_rows, keep_going);
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

/// Where the kept value j of row r goes: data[r * stride] (a column of the
/// caller's arrays, so that one row can be split over several of them).
struct ColumnSink {
  double* data = nullptr;
  std::ptrdiff_t stride = 1;  // [elements]
};

/// One value starting at p, the line ending at le: the end of the value when
/// it is a whole token (followed by a separator or le), else nullptr with the
/// token's end in te.  The fast path parses in place (no scan for the token's
/// end first); anything else (a '+', over/underflow, junk) goes through
/// parse_value on the whole token, exactly as before.
inline const char* parse_token(const char* p, const char* le, bool comma, double& v, const char*& te) {
  const auto r = std::from_chars(p, le, v);
  if (r.ec == std::errc() && (r.ptr == le || is_space(*r.ptr, comma))) return r.ptr;
  te = p;
  while (te < le && !is_space(*te, comma)) ++te;
  return parse_value(p, te, v) ? te : nullptr;
}

/// Parse [b, e) (whole lines): row r (counted from row0) to sinks[j].data[r *
/// stride] for j < opt.keep.  line_of (may be null) gets the line of each row,
/// counted from first_line, but only once a blank line has been skipped (the
/// rows before it are then filled in): a block without one leaves it alone.
/// Stops at the first bad row.
inline ParseBlock parse_block(const char* base, std::size_t b, std::size_t e, const ParseOptions& opt,
                              std::int64_t first_line, const ColumnSink* sinks, std::int64_t row0,
                              std::int64_t* line_of) {
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
    const std::int64_t r = row0 + res.rows;
    while (true) {
      while (p < le && is_space(*p, opt.comma)) ++p;
      if (p == le) break;
      if (col >= opt.ncols) {  // extra values: not parsed, counted for the message
        while (p < le && !is_space(*p, opt.comma)) ++p;
        ++col;
        continue;
      }
      double v;
      const char* te = nullptr;
      const char* q = parse_token(p, le, opt.comma, v, te);
      if (!q) {
        res.error = {ParseErrorKind::kNumber, line, 0, col, static_cast<std::size_t>(p - base),
                     static_cast<std::size_t>(te - base), static_cast<std::size_t>(le - base)};
        return res;
      }
      if (col < opt.keep) sinks[col].data[r * sinks[col].stride] = v;
      ++col;
      p = q;
    }
    if (col == 0) {
      if (line_of && !res.blank)
        for (std::int64_t i = 0; i < res.rows; ++i) line_of[row0 + i] = first_line + i;
      res.blank = true;
    } else if (col < opt.ncols || (col > opt.ncols && !opt.allow_extra)) {
      res.error = {ParseErrorKind::kColumns, line, col, 0, 0, 0, static_cast<std::size_t>(le - base)};
      return res;
    } else {
      if (line_of && res.blank) line_of[r] = line;
      ++res.rows;
    }
    ++line;
    s = nl ? nl + 1 : end;
  }
  return res;
}

/// Lines in [b, e): newlines, plus one for a last line without one.
inline std::int64_t count_lines(const char* b, const char* e) {
  std::int64_t n = (e > b && e[-1] != '\n') ? 1 : 0;
  while (b < e) {  // per-byte counters of at most 255 newlines (a vectorised compare-and-add), summed per chunk
    const std::size_t chunk = std::min<std::size_t>(static_cast<std::size_t>(e - b), 255 * 64);
    std::uint8_t acc[64] = {};
    std::size_t i = 0;
    for (; i + 64 <= chunk; i += 64)
      for (int k = 0; k < 64; ++k) acc[k] = static_cast<std::uint8_t>(acc[k] + (b[i + k] == '\n'));
    for (int k = 0; k < 64; ++k) n += acc[k];
    for (; i < chunk; ++i) n += (b[i] == '\n');
    b += chunk;
  }
  return n;
}

/// The blocks of a parallel parse: [cut[i], cut[i+1]) split at line
/// boundaries, with their line counts (counted on the parse's threads).
struct ParsePlan {
  std::vector<std::size_t> cut{0};
  std::vector<std::int64_t> lines;  // per block
  std::int64_t total_lines = 0;
};

/// Run job(i) for i < n on up to n threads (job 0 on the calling thread).
template <class Job>
void run_parallel(int n, Job&& job) {
  std::vector<std::thread> pool;
  for (int i = 1; i < n; ++i) pool.emplace_back(job, i);
  if (n > 0) job(0);
  for (auto& th : pool) th.join();
}

/// Split the buffer for `threads` threads (one block under 1 MB) and count
/// each block's lines in parallel: the caller sizes its arrays from
/// total_lines (one row a line at most).
inline ParsePlan plan_parse(const char* data, std::size_t size, int threads = 2) {
  ParsePlan plan;
  threads = (size < (std::size_t(1) << 20)) ? 1 : std::max(1, threads);
  for (int t = 1; t < threads; ++t) {
    std::size_t c = size * static_cast<std::size_t>(t) / static_cast<std::size_t>(threads);
    const void* nl = std::memchr(data + c, '\n', size - c);
    c = nl ? static_cast<std::size_t>(static_cast<const char*>(nl) - data) + 1 : size;
    if (c > plan.cut.back()) plan.cut.push_back(c);
  }
  if (plan.cut.back() < size) plan.cut.push_back(size);
  const int nb = static_cast<int>(plan.cut.size()) - 1;
  plan.lines.assign(static_cast<std::size_t>(std::max(nb, 0)), 0);
  run_parallel(nb, [&](int i) { plan.lines[i] = count_lines(data + plan.cut[i], data + plan.cut[i + 1]); });
  for (std::int64_t l : plan.lines) plan.total_lines += l;
  return plan;
}

struct ParseResult {
  std::int64_t rows = 0;
  bool blank = false;  // a blank line was skipped: line_of holds the line of every row
  ParseError error;    // line numbers absolute (from first_line)
};

/// Parse the blocks of `plan` in parallel.  sinks[j] (j < opt.keep) must
/// have room for plan.total_lines rows, line_of (may be null) as many
/// entries.  Rows are contiguous on return; line_of is filled only when a
/// line was blank (ParseResult::blank), else the row of line l is l - first_line.
inline ParseResult parse_planned(const char* data, const ParsePlan& plan, const ParseOptions& opt,
                                 std::int64_t first_line, const ColumnSink* sinks, std::int64_t* line_of) {
  ParseResult res;
  const int nb = static_cast<int>(plan.cut.size()) - 1;
  if (nb <= 0) return res;
  std::vector<std::int64_t> line0(nb, first_line), row0(nb, 0);
  for (int i = 1; i < nb; ++i) {
    line0[i] = line0[i - 1] + plan.lines[i - 1];
    row0[i] = row0[i - 1] + plan.lines[i - 1];  // room: one row per line
  }
  std::vector<ParseBlock> blocks(nb);
  run_parallel(nb, [&](int i) {
    blocks[i] = parse_block(data, plan.cut[i], plan.cut[i + 1], opt, line0[i], sinks, row0[i], line_of);
  });
  bool any_blank = false;
  for (int i = 0; i < nb; ++i) {
    if (blocks[i].error.kind != ParseErrorKind::kNone) {
      res.error = blocks[i].error;
      return res;
    }
    any_blank = any_blank || blocks[i].blank;
  }
  for (int i = 0; i < nb; ++i) {
    const ParseBlock& bl = blocks[i];
    if (any_blank && line_of && !bl.blank)  // this block's rows are on consecutive lines
      for (std::int64_t r = 0; r < bl.rows; ++r) line_of[row0[i] + r] = line0[i] + r;
    if (row0[i] != res.rows) {  // close the gap left by blank lines before this block (moving rows forward)
      for (std::int64_t r = 0; r < bl.rows; ++r) {
        for (int j = 0; j < opt.keep; ++j)
          sinks[j].data[(res.rows + r) * sinks[j].stride] = sinks[j].data[(row0[i] + r) * sinks[j].stride];
        if (line_of && any_blank) line_of[res.rows + r] = line_of[row0[i] + r];
      }
    }
    res.rows += bl.rows;
  }
  res.blank = any_blank;
  return res;
}

/// Parse the whole buffer on up to `threads` threads into out (row-major,
/// opt.keep values a row, room for count_lines(data, data + size) rows);
/// line_of as parse_planned.
inline ParseResult parse_buffer(const char* data, std::size_t size, const ParseOptions& opt, std::int64_t first_line,
                                double* out, std::int64_t* line_of, int threads = 2) {
  const ParsePlan plan = plan_parse(data, size, threads);
  std::vector<ColumnSink> sinks(static_cast<std::size_t>(opt.keep));
  for (int j = 0; j < opt.keep; ++j) sinks[j] = {out + j, opt.keep};
  return parse_planned(data, plan, opt, first_line, sinks.data(), line_of);
}

// ----------------------------------------------------------------- delimited fields (generic IMU CSV)

/// The generic IMU CSV's line grammar (python/insnav/io/imu_csv.py,
/// CsvLineParser): a line stripped of whitespace, then split at every
/// `delim` into exactly `nfields` fields, of which the fields `want` are
/// numbers as Python's float() reads them.  The parser takes only the lines
/// it reads exactly as the Python reader does and stops at any other (the
/// caller reads that one line with the Python reader, which also words every
/// error): blank and '#' lines (ASCII) are skipped.
struct CsvFieldOptions {
  char delim = ',';
  int nfields = 0;
  std::vector<int> want;  // field indices stored per row, in order (each < nfields)
  int time_want = -1;     // index into `want` of the time field also stored split (-1: none)
};

/// Where rows go: values[r * want.size() + k]; line[r] the line index (from
/// the call's first line); the time field (time_want >= 0): t_kind[r] = 1
/// when it is a plain decimal ``digits[.digits]`` whose integer part is
/// t_hi[r] * 10^9 + t_lo[r] and whose fraction ".digits" reads as t_frac[r]
/// (the digits the imu reader keeps exactly), else 0.
struct CsvSinks {
  double* values = nullptr;
  std::int64_t* line = nullptr;
  std::int64_t* t_hi = nullptr;
  std::int64_t* t_lo = nullptr;
  double* t_frac = nullptr;
  std::uint8_t* t_kind = nullptr;
};

struct CsvParsed {
  std::int64_t rows = 0;
  std::int64_t lines = 0;    // lines taken (the stop line is the next one)
  bool stopped = false;      // a line the parser does not take (at line index `lines`)
  std::size_t stop_pos = 0;  // its first byte (the buffer's end when not stopped)
};

/// Python str.strip() / float() whitespace among the bytes this parser takes.
inline bool is_csv_space(unsigned char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

/// The time field [b, e) split as the imu reader's exact time arithmetic
/// needs it (imu_csv._time_after): kind 1 for ``digits[.digits]`` with at most
/// 27 integer digits, else kind 0 (the value as read is used).
inline bool split_time_field(const char* b, const char* e, std::int64_t& hi, std::int64_t& lo, double& frac,
                             std::uint8_t& kind) {
  while (b < e && is_csv_space(static_cast<unsigned char>(*b))) ++b;
  while (e > b && is_csv_space(static_cast<unsigned char>(e[-1]))) --e;
  kind = 0;
  const char* dot = b;
  while (dot < e && *dot >= '0' && *dot <= '9') ++dot;
  if (dot == b) return true;  // no integer digits: not plain
  if (dot < e) {
    if (*dot != '.') return true;
    for (const char* q = dot + 1; q < e; ++q)
      if (*q < '0' || *q > '9') return true;
  }
  if (dot - b > 27) return false;  // the Python reader's exact integers (the caller stops)
  std::int64_t h = 0, l = 0;
  const char* split = dot - b > 9 ? dot - 9 : b;
  for (const char* q = b; q < split; ++q) h = h * 10 + (*q - '0');
  for (const char* q = split; q < dot; ++q) l = l * 10 + (*q - '0');
  frac = 0.0;
  if (dot + 1 < e) {
    const auto r = std::from_chars(dot, e, frac);  // ".digits": as float("0.digits")
    if (r.ec != std::errc() || r.ptr != e) return false;
  }
  hi = h;
  lo = l;
  kind = 1;
  return true;
}

/// Bytes the Python reader takes as they are in a field it does not read: printable ASCII and the
/// whitespace above (not ASCII is its error; str.strip()'s \x1c..\x1f it strips, this parser does not).
inline bool plain_ascii(const char* b, const char* e) {
  unsigned bad = 0;
  for (; b < e; ++b) {
    const unsigned char c = static_cast<unsigned char>(*b);
    bad |= static_cast<unsigned>(c >= 0x7f) | static_cast<unsigned>(c < 0x20 && !is_csv_space(c));
  }
  return !bad;
}

/// Parse the lines of [b, e) (line index 0 at b) into sinks (room for one
/// row per line) up to the first line this parser does not take.  A read
/// field is parsed in place (std::from_chars up to the delimiter, which must
/// not be a character of a number: the caller checks), so that its bytes are
/// checked by the number grammar; an unread field's bytes and a comment are
/// checked by plain_ascii.
inline CsvParsed parse_csv_fields(const char* base, std::size_t b, std::size_t e, const CsvFieldOptions& opt,
                                  const CsvSinks& out) {
  CsvParsed res;
  const int nwant = static_cast<int>(opt.want.size());
  // field -> position in want (-1: not stored)
  std::vector<int> slot(static_cast<std::size_t>(std::max(opt.nfields, 0)), -1);
  for (int k = 0; k < nwant; ++k) slot[static_cast<std::size_t>(opt.want[k])] = k;
  const int tfield = opt.time_want >= 0 ? opt.want[opt.time_want] : -1;
  const char* s = base + b;
  const char* end = base + e;
  const char delim = opt.delim;
  // whitespace inside a field (a whitespace delimiter is none)
  auto field_space = [delim](char c) { return c != delim && is_csv_space(static_cast<unsigned char>(c)); };
  while (s < end) {
    const char* nl = static_cast<const char*>(std::memchr(s, '\n', static_cast<std::size_t>(end - s)));
    const char* le = nl ? nl : end;
    bool ok = true;
    const char* p = s;
    const char* q = le;
    while (p < q && is_csv_space(static_cast<unsigned char>(*p))) ++p;
    while (q > p && is_csv_space(static_cast<unsigned char>(q[-1]))) --q;
    if (p < q && *p == '#') {
      ok = plain_ascii(s, le);
    } else if (p < q) {
      const std::int64_t r = res.rows;
      int f = 0;
      const char* fb = p;
      while (true) {
        if (f >= opt.nfields) {
          ok = false;
          break;
        }
        const int k = slot[static_cast<std::size_t>(f)];
        const char* fe;
        if (k >= 0) {
          const char* nb = fb;
          while (nb < q && field_space(*nb)) ++nb;
          if (nb < q && *nb == '+') {  // float() takes one '+' before the number
            ++nb;
            if (nb == q || *nb == '+' || *nb == '-') {
              ok = false;
              break;
            }
          }
          double v;
          const auto rc = std::from_chars(nb, q, v);
          fe = rc.ptr;
          while (fe < q && field_space(*fe)) ++fe;
          if (rc.ec != std::errc() || !std::isfinite(v) || (fe < q && *fe != delim)) {
            ok = false;
            break;
          }
          out.values[r * nwant + k] = v;
          if (f == tfield && !split_time_field(fb, fe, out.t_hi[r], out.t_lo[r], out.t_frac[r], out.t_kind[r])) {
            ok = false;
            break;
          }
        } else {
          fe = static_cast<const char*>(std::memchr(fb, delim, static_cast<std::size_t>(q - fb)));
          if (!fe) fe = q;
          if (!plain_ascii(fb, fe)) {
            ok = false;
            break;
          }
        }
        ++f;
        if (fe == q) break;
        fb = fe + 1;
      }
      if (ok && f != opt.nfields) ok = false;
      if (ok) {
        out.line[r] = res.lines;
        ++res.rows;
      }
    }
    if (!ok) {
      res.stopped = true;
      res.stop_pos = static_cast<std::size_t>(s - base);
      return res;
    }
    ++res.lines;
    s = nl ? nl + 1 : end;
  }
  res.stop_pos = e;
  return res;
}

}  // namespace insnav::textio

// The text writer without Python (io/text_table.hpp, io/direct_file.hpp), under
// the sanitizers of the C++ suite: the run-time-selected formatter copy gives
// the generic copy's text byte for byte; a DirectFile written in uneven pieces
// (buffers crossed, an unaligned tail, O_DIRECT on and off) holds exactly the
// bytes given, cuts an older longer file to them, and reports a failed open;
// write_rows on two threads equals one thread's text.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <unistd.h>

#include "insnav/io/text_table.hpp"
#include "test_util.hpp"

using namespace insnav::textio;

namespace {

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

std::string temp_path(const char* tag) {
  std::string p = std::string("/tmp/insnav_test_text_io_") + tag + "_XXXXXX";
  const int fd = ::mkstemp(p.data());
  if (fd >= 0) ::close(fd);
  return p;
}

/// Values the formatter has special paths for: signed zeros, rounding ties in
/// binary and near decimal ties, the integer path's limit, huge, tiny, NaN, inf.
std::vector<double> tricky_values(std::mt19937_64& rng, int n_random) {
  std::vector<double> v = {0.0, -0.0, 0.5, -0.5, 1.5, 2.5, 0.125, 0.0005, -0.0005, 1e-300, -1e-300, 999999.9999995,
                           1e15, -1e15, 1e15 - 1, 1e21, -1e22, 1e300, NAN, INFINITY, -INFINITY, 123456.789012345};
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> e(-12, 18);
  for (int i = 0; i < n_random; ++i) v.push_back(u(rng) * std::pow(10.0, e(rng)));
  return v;
}

void test_dispatch_equals_generic() {
  std::mt19937_64 rng(7);
  const std::vector<double> v = tricky_values(rng, 20000);
  for (int dec : {-1, 0, 3, 9, 15}) {
    for (bool trim : {false, true}) {
      const Column col{v.data(), 1, 1.0, dec};
      TextFormat fmt;
      fmt.trim_zeros = trim;
      TextBuffer a, b;
      format_rows(&col, 1, 0, static_cast<std::int64_t>(v.size()), fmt, a);
      format_rows_generic(&col, 1, 0, static_cast<std::int64_t>(v.size()), fmt, b);
      EXPECT_TRUE(a.size == b.size && std::memcmp(a.data.get(), b.data.get(), a.size) == 0);
    }
  }
}

void test_direct_file_bytes() {
  std::mt19937_64 rng(11);
  std::uniform_int_distribution<int> byte(0, 255), piece(0, 20000);
  std::string want;
  for (int i = 0; i < 300000; ++i) want.push_back(static_cast<char>(byte(rng)));
  for (bool direct : {true, false}) {
    for (std::size_t buf : {std::size_t{4096}, std::size_t{12288}, std::size_t{4} << 20}) {
      const std::string path = temp_path("bytes");
      {  // an older, longer file at the path: cut to the new bytes by close()
        std::ofstream old(path, std::ios::binary);
        old << want << want;
      }
      DirectFile f(path, direct, buf);
      EXPECT_TRUE(f.error() == 0);
      if (buf == 4096) std::printf("DirectFile, O_DIRECT asked %d: used %d\n", direct, f.direct());
      std::size_t at = 0;
      while (at < want.size()) {  // uneven pieces, some empty, crossing the buffer
        const std::size_t k = std::min<std::size_t>(static_cast<std::size_t>(piece(rng)), want.size() - at);
        EXPECT_TRUE(f.write(want.data() + at, k) == 0);
        at += k;
      }
      EXPECT_TRUE(f.bytes() == static_cast<std::int64_t>(want.size()));
      EXPECT_TRUE(f.close() == 0);
      EXPECT_TRUE(f.close() == 0);  // idempotent
      EXPECT_TRUE(slurp(path) == want);
      std::remove(path.c_str());
    }
  }
  DirectFile bad("/nonexistent-insnav-dir/x.txt");
  EXPECT_TRUE(bad.error() != 0);
  EXPECT_TRUE(bad.write("x", 1) != 0);
}

void test_write_rows_threads() {
  std::mt19937_64 rng(13);
  const std::int64_t n = 50000;
  std::vector<double> a(n), b(n);
  std::normal_distribution<double> nd(0.0, 100.0);
  for (std::int64_t i = 0; i < n; ++i) a[i] = nd(rng), b[i] = nd(rng) * 1e-6;
  const Column cols[2] = {{a.data(), 1, 1.0, 4}, {b.data(), 1, 1e6, 9}};
  TextFormat fmt;
  std::string text[2];
  for (int threads : {1, 2}) {
    const std::string path = temp_path("rows");
    DirectFile f(path);
    const WriteResult r = write_rows(f, cols, 2, n, fmt, threads, 1000);
    EXPECT_TRUE(r.status == WriteStatus::kOk);
    EXPECT_TRUE(f.close() == 0);
    text[threads - 1] = slurp(path);
    EXPECT_TRUE(r.bytes == static_cast<std::int64_t>(text[threads - 1].size()));
    std::remove(path.c_str());
  }
  EXPECT_TRUE(!text[0].empty() && text[0] == text[1]);
  std::size_t lines = 0;
  for (char c : text[0]) lines += c == '\n';
  EXPECT_TRUE(lines == static_cast<std::size_t>(n));
}

}  // namespace

int main() {
  test_dispatch_equals_generic();
  test_direct_file_bytes();
  test_write_rows_threads();
  TEST_MAIN_END()
}

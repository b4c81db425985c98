// insnav/filter/random.hpp -- deterministic random numbers for the particle
// filters: a counter-based stream per (seed, cycle, particle, purpose)
// (xoshiro256** seeded by splitmix64), so results do not depend on the order
// or thread particles are processed in; normals by Box-Muller (portable: the
// std:: distributions differ between standard libraries).
#pragma once

#include <cmath>
#include <cstdint>

namespace insnav {

// --- deterministic random numbers --------------------------------------------

inline std::uint64_t splitmix64(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

/// xoshiro256** (Blackman & Vigna 2018) with Box-Muller normals.
class Rng {
 public:
  Rng() { seed(0, 0, 0, 0); }
  /// A stream for (seed, cycle, particle, purpose): independent, reproducible.
  void seed(std::uint64_t seed, std::uint64_t cycle, std::uint64_t particle, std::uint64_t purpose) {
    std::uint64_t h = seed;
    h ^= splitmix64(h) + cycle * 0xD1B54A32D192ED03ULL;
    h ^= splitmix64(h) + particle * 0xABC98388FB8FAC03ULL;
    h ^= splitmix64(h) + purpose * 0x8CB92BA72F3D8DD7ULL;
    for (auto& w : s_) w = splitmix64(h);
    have_spare_ = false;
  }
  std::uint64_t next() {
    const std::uint64_t r = rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return r;
  }
  /// Uniform on [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  double normal() {
    if (have_spare_) {
      have_spare_ = false;
      return spare_;
    }
    double u1 = uniform();
    while (u1 <= 0.0) u1 = uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * M_PI * u2);
    have_spare_ = true;
    return r * std::cos(2.0 * M_PI * u2);
  }
  template <class V>
  void fill_normal(V& v) {
    for (int i = 0; i < v.size(); ++i) v[i] = normal();
  }

 private:
  static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  std::uint64_t s_[4];
  double spare_ = 0.0;
  bool have_spare_ = false;
};

/// Stream purposes (any distinct constants).
enum RngPurpose : std::uint64_t {
  kRngInit = 1, kRngProcess = 2, kRngProposal = 3, kRngResample = 4, kRngJitter = 5, kRngTemper = 6, kRngReseed = 7
};

}  // namespace insnav

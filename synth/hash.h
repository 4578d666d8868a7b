#pragma once
// Counter-based randomness for the synthetic drives: every random number is a pure function of
// the seed and of where it is used (an object, a texture cell, a pixel), so the output does not
// depend on the order of evaluation or on the threads.

#include <cmath>
#include <cstdint>

namespace omni::synth {

// SplitMix64's finalizer (Steele, Lea, Flood 2014).
inline uint64_t Mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

inline uint64_t Hash(uint64_t a, uint64_t b) { return Mix64(a ^ Mix64(b ^ 0x632be59bd9b4e019ULL)); }
inline uint64_t Hash(uint64_t a, uint64_t b, uint64_t c) { return Hash(Hash(a, b), c); }
inline uint64_t Hash(uint64_t a, uint64_t b, uint64_t c, uint64_t d) {
  return Hash(Hash(a, b, c), d);
}

// One mixing round for a lattice cell (textures evaluate millions of them): cheaper than
// chaining Hash, and as good once `seed` itself is well mixed.
inline uint64_t CellHash(uint64_t seed, int64_t i, int64_t j) {
  return Mix64(seed + static_cast<uint64_t>(i) * 0x9e3779b97f4a7c15ULL +
               static_cast<uint64_t>(j) * 0xc2b2ae3d27d4eb4fULL);
}

// The k-th 16-bit field of h, as a uniform number in [0, 1).
inline double Field16(uint64_t h, int k) {
  return static_cast<double>((h >> (16 * k)) & 0xFFFF) * (1.0 / 65536.0);
}

// Uniform in [0, 1).
inline double Uniform(uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }
inline double Uniform(uint64_t h, double lo, double hi) { return lo + (hi - lo) * Uniform(h); }

// Approximately standard normal (Irwin-Hall: the sum of four uniforms, centred and scaled to
// unit variance; enough for sensor noise, and cheaper than Box-Muller).
inline double Gaussian(uint64_t h) {
  double sum = 0.0;
  for (int i = 0; i < 4; ++i)
    sum += static_cast<double>((h >> (16 * i)) & 0xFFFF) * (1.0 / 65536.0);
  return (sum - 2.0 + 2.0 / 65536.0) * 1.7320508075688772;
}

// A small deterministic generator for sequential scene layout.
class SplitMix {
 public:
  explicit SplitMix(uint64_t seed) : state_(seed) {}
  uint64_t Next() { return Mix64(state_++ * 0x2545f4914f6cdd1dULL + 1); }
  double Uniform(double lo = 0.0, double hi = 1.0) { return synth::Uniform(Next(), lo, hi); }
  int UniformInt(int lo, int hi) {  // inclusive
    return lo + static_cast<int>(Next() % static_cast<uint64_t>(hi - lo + 1));
  }
  bool Bernoulli(double p) { return Uniform() < p; }

 private:
  uint64_t state_;
};

}  // namespace omni::synth

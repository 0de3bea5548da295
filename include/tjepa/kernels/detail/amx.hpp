#pragma once
// AMX: Intel's tile registers (8 tiles of 16 rows × 64 bytes) and TDPBF16PS, which multiplies a
// 16 × 32 bf16 tile of A by a 32 × 16 bf16 tile of B (16 depth pairs, 16 columns) into a 16 × 16
// fp32 tile of C: 16384 FLOPs per instruction, 256 times a vdpbf16ps's (on model 167 the tiles'
// peak measured 15× the FMA's and 29× vdpbf16ps's: BM_AmxPeak).
//
// The tiles read the operands the bf16 GEMM packs already (bgemm.hpp): a B panel [depth/2][NR]
// of pair words is four B tiles side by side (a row stride of NR words), and row-major A pairs
// [rows][depth/2] are A tiles. block_product runs 32 rows of C × one panel, as two halves of
// 2 × 2 C tiles (four C tiles, two A tiles and two B tiles: all eight registers); depth pairs
// past the last whole 16 (a depth that is no multiple of 32) run on vdpbf16ps.
//
// Compiled where the build has AMX-TILE and AMX-BF16 (-march=native on such a CPU); used at run
// time only where the CPU lists them and Linux grants this process the tile data
// (arch_prctl(ARCH_REQ_XCOMP_PERM), Linux 5.16 and later), and not switched off by TJEPA_AMX=off
// or set_amx(false) (kernels/precision.hpp). Elsewhere the bf16 products run on vdpbf16ps alone.
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>
#include <utility>

#include "tjepa/core/error.hpp"

// g++ names the AMX macros __AMX_TILE__ and __AMX_BF16__, clang++ __AMXTILE__ and __AMXBF16__.
#if defined(__AVX512BF16__) && defined(__AVX512F__) && defined(__AVX512BW__) && defined(__linux__) && \
    (defined(__AMX_TILE__) || defined(__AMXTILE__)) && (defined(__AMX_BF16__) || defined(__AMXBF16__))
#define TJEPA_AMX_NATIVE 1
#include <cpuid.h>
#include <immintrin.h>
#include <sys/syscall.h>
#include <unistd.h>
#else
#define TJEPA_AMX_NATIVE 0
#endif

namespace tjepa::detail::amx {

// Whether this CPU has AMX-TILE and AMX-BF16 and Linux gave this process the tile state (asked
// once, for the whole process: every thread may then use the tiles).
inline bool granted() {
#if TJEPA_AMX_NATIVE
  static const bool ok = [] {
    unsigned a = 0, b = 0, c = 0, d = 0;
    if (!__get_cpuid_count(7, 0, &a, &b, &c, &d)) return false;
    if (!(d & (1u << 24)) || !(d & (1u << 22))) return false;  // AMX-TILE, AMX-BF16
    constexpr long arch_req_xcomp_perm = 0x1023, xfeature_xtiledata = 18;
    return syscall(SYS_arch_prctl, arch_req_xcomp_perm, xfeature_xtiledata) == 0;
  }();
  return ok;
#else
  return false;
#endif
}

// TJEPA_AMX: unset or "on" (use AMX where granted), "off" (vdpbf16ps only); anything else is an
// error that names the variable.
inline bool wanted_by_environment() {
  const char* v = std::getenv("TJEPA_AMX");
  if (!v) return true;
  const std::string_view s(v);
  if (s == "on") return true;
  if (s == "off") return false;
  fail<std::invalid_argument>("TJEPA_AMX=", s, ": expected on or off");
}

inline std::atomic<bool>& switch_state() {
  static std::atomic<bool> on{granted() && wanted_by_environment()};
  return on;
}

#if TJEPA_AMX_NATIVE

inline constexpr int TM = 16;  // rows of a tile
inline constexpr int TK = 16;  // depth pairs of a tile: 64 bytes of bf16 per row
inline constexpr int MB = 2 * TM;  // rows of C per block_product

// Every tile 16 rows × 64 bytes (palette 1), loaded for the calling thread while a Tiles lives,
// released after: the tile state is per thread, and another library on the same thread may load
// another configuration between two products. Nested scopes on one thread load it once (the
// outermost: attention holds one around its many small products).
class Tiles {
 public:
  Tiles() {
    if (depth()++ > 0) return;
    // In static storage: g++ 12 does not see ldtilecfg read its operand, and dropped the zeroing
    // stores of a configuration on the stack (the unused tiles' bytes were then stack garbage, and
    // ldtilecfg faulted on them).
    struct alignas(64) Config {
      std::uint8_t palette, start_row, reserved[14];
      std::uint16_t colsb[16];
      std::uint8_t rows[16];
    };
    alignas(64) static constexpr Config config = {
        1, 0, {}, {64, 64, 64, 64, 64, 64, 64, 64}, {TM, TM, TM, TM, TM, TM, TM, TM}};
    _tile_loadconfig(&config);
  }
  ~Tiles() {
    if (--depth() == 0) _tile_release();
  }
  Tiles(const Tiles&) = delete;
  Tiles& operator=(const Tiles&) = delete;

 private:
  static int& depth() {
    thread_local int d = 0;
    return d;
  }
};

// C [32][16 or 32] = A · B on the tiles: A [32 rows][groups · 16 pairs] (row stride as bytes),
// b(g) the first row of B's group g of 16 pairs and its row stride in bytes (a pair of them); per
// group two A tiles and one B tile (two: a second beside it) into two (four) C tiles, stored to c
// (row stride cs bytes).
template <class BGroup>
inline void tile_block(int groups, const std::uint32_t* a, std::ptrdiff_t as, BGroup b, bool two, float* c,
                       std::ptrdiff_t cs) {
  _tile_zero(0);
  _tile_zero(1);
  _tile_zero(2);
  _tile_zero(3);
  for (int g = 0; g < groups; ++g) {
    const auto [bg, bs] = b(g);
    _tile_loadd(4, a + g * TK, as);
    _tile_loadd(5, reinterpret_cast<const char*>(a + g * TK) + TM * as, as);
    _tile_loadd(6, bg, bs);
    _tile_dpbf16ps(0, 4, 6);
    _tile_dpbf16ps(2, 5, 6);
    if (two) {
      _tile_loadd(7, bg + TM, bs);
      _tile_dpbf16ps(1, 4, 7);
      _tile_dpbf16ps(3, 5, 7);
    }
  }
  _tile_stored(0, c, cs);
  _tile_stored(2, reinterpret_cast<char*>(c) + TM * cs, cs);
  if (two) {
    _tile_stored(1, c + TM, cs);
    _tile_stored(3, reinterpret_cast<char*>(c + TM) + TM * cs, cs);
  }
}

// tile[MB][NR] = A · B over kc2 depth pairs: a [MB][ald] pair words (row-major A, ald a multiple
// of 16: 64-byte rows), b a packed panel [kc2][NR] (bgemm's), of which the first cols ≤ NR
// columns are needed: two halves of 2 × 2 C tiles (the second only where cols > 32). The depth
// pairs past kc2's last whole 16 run on vdpbf16ps (rows < R only).
template <int NR>
void block_product(int kc2, const std::uint32_t* a, std::ptrdiff_t ald, const std::uint32_t* b, int cols, int R,
                   float* tile) {
  static_assert(NR == 4 * TM);
  const int whole = kc2 / TK * TK;
  for (int h = 0; h < (cols > 2 * TM ? 2 : 1); ++h) {
    const std::uint32_t* bh = b + h * 2 * TM;
    tile_block(
        whole / TK, a, ald * 4, [&](int g) { return std::pair{bh + std::ptrdiff_t(g) * TK * NR, std::ptrdiff_t(NR) * 4}; },
        true, tile + h * 2 * TM, NR * 4);
  }
  if (whole == kc2) return;
  const int vectors = (cols + TM - 1) / TM;
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < vectors; ++j) {
      __m512 acc = _mm512_load_ps(tile + i * NR + j * TM);
      for (int q = whole; q < kc2; ++q)
        acc = _mm512_dpbf16_ps(acc, std::bit_cast<__m512bh>(_mm512_set1_epi32(int(a[i * ald + q]))),
                               std::bit_cast<__m512bh>(_mm512_load_si512(b + std::ptrdiff_t(q) * NR + j * TM)));
      _mm512_store_ps(tile + i * NR + j * TM, acc);
    }
}

// FLOPs of one iteration of peak_chains: four TDPBF16PS of 16 × 16 × 32 multiply-adds.
inline constexpr double peak_chain_flops = 4.0 * TM * TM * 2 * TK * 2;

// Four C tiles accumulating A·B, `iterations` times each (tiles of ones: each C entry grows by 32
// a step; the chains are independent, so they run at TDPBF16PS's issue rate); the sum of one
// entry of each, so that none is dropped.
inline float peak_chains(std::int64_t iterations) {
  const Tiles tiles;
  alignas(64) static constexpr std::uint16_t ones[TM * 2 * TK] = {
#define TJEPA_AMX_ONES8 0x3f80, 0x3f80, 0x3f80, 0x3f80, 0x3f80, 0x3f80, 0x3f80, 0x3f80
#define TJEPA_AMX_ONES64 TJEPA_AMX_ONES8, TJEPA_AMX_ONES8, TJEPA_AMX_ONES8, TJEPA_AMX_ONES8, TJEPA_AMX_ONES8, \
                         TJEPA_AMX_ONES8, TJEPA_AMX_ONES8, TJEPA_AMX_ONES8
      TJEPA_AMX_ONES64, TJEPA_AMX_ONES64, TJEPA_AMX_ONES64, TJEPA_AMX_ONES64, TJEPA_AMX_ONES64, TJEPA_AMX_ONES64,
      TJEPA_AMX_ONES64, TJEPA_AMX_ONES64};
#undef TJEPA_AMX_ONES64
#undef TJEPA_AMX_ONES8
  _tile_zero(0);
  _tile_zero(1);
  _tile_zero(2);
  _tile_zero(3);
  _tile_loadd(4, ones, 64);
  _tile_loadd(5, ones, 64);
  _tile_loadd(6, ones, 64);
  _tile_loadd(7, ones, 64);
  for (std::int64_t k = 0; k < iterations; ++k) {
    _tile_dpbf16ps(0, 4, 6);
    _tile_dpbf16ps(1, 4, 7);
    _tile_dpbf16ps(2, 5, 6);
    _tile_dpbf16ps(3, 5, 7);
  }
  alignas(64) float c[4][TM * TM];
  _tile_stored(0, c[0], 64);
  _tile_stored(1, c[1], 64);
  _tile_stored(2, c[2], 64);
  _tile_stored(3, c[3], 64);
  return c[0][0] + c[1][0] + c[2][0] + c[3][0];
}

#endif  // TJEPA_AMX_NATIVE

}  // namespace tjepa::detail::amx

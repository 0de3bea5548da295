#pragma once
// The arithmetic of the forward products (fp32, or bf16 operands with fp32 accumulation) and
// whether this build runs bf16 natively. The bf16 GEMM itself is kernels/detail/bgemm.hpp.
#include <array>
#include <string_view>
#include <utility>

#include "tjepa/core/enum_names.hpp"
#include "tjepa/kernels/detail/amx.hpp"

#if defined(__AVX512BF16__) && defined(__AVX512F__) && defined(__AVX512BW__)
#define TJEPA_BF16_NATIVE 1
#else
#define TJEPA_BF16_NATIVE 0
#endif

namespace tjepa {

// The arithmetic of the forward products: fp32, or bf16 operands with fp32 accumulation (master
// weights, activations between the products and everything else stay fp32).
enum class Precision { fp32, bf16 };

// The names (JSON, text).
constexpr auto json_names(Precision) {
  return std::array{std::pair<std::string_view, Precision>{"fp32", Precision::fp32},
                    std::pair<std::string_view, Precision>{"bf16", Precision::bf16}};
}
inline const char* precision_name(Precision p) { return enum_name(p); }

// Whether this translation unit was compiled with AVX512-BF16 (-mavx512bf16, or a -march that has
// it): only then does Precision::bf16 run bf16 products; elsewhere it runs fp32.
constexpr bool has_native_bf16() { return TJEPA_BF16_NATIVE != 0; }

// The precision that Precision p actually runs in on this build.
constexpr Precision effective_precision(Precision p) {
  return p == Precision::bf16 && has_native_bf16() ? Precision::bf16 : Precision::fp32;
}

// Whether the linear layers' bf16 products (kernels/detail/bgemm.hpp) can run on AMX tiles here:
// the build has AMX (compiled with AMX-TILE and AMX-BF16), the CPU lists it and Linux grants the
// tile data. Attention's bf16 products run on vdpbf16ps either way.
inline bool amx_available() { return detail::amx::granted(); }
// Whether they do (amx_available(), not switched off by TJEPA_AMX=off or set_amx(false)).
inline bool amx_enabled() { return detail::amx::switch_state().load(std::memory_order_relaxed); }
// Switches AMX on or off for those products, for the whole process (the same sums in another
// instruction: results may differ in the last bits). On where amx_available() is false: an error.
inline void set_amx(bool on) {
  if (on && !amx_available()) fail<std::invalid_argument>("set_amx: this build or CPU has no AMX tiles");
  detail::amx::switch_state().store(on, std::memory_order_relaxed);
}

}  // namespace tjepa

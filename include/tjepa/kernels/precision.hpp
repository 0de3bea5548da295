#pragma once
// The arithmetic of the forward products (fp32, or bf16 operands with fp32 accumulation) and
// whether this build runs bf16 natively. The bf16 GEMM itself is kernels/detail/bgemm.hpp.
#include <array>
#include <string_view>
#include <utility>

#include "tjepa/core/enum_names.hpp"

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

}  // namespace tjepa

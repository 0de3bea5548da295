// The libFuzzer binary: every target of targets.hpp, chosen by the environment variable
// TJEPA_FUZZ_TARGET (one binary keeps the sanitizer build to one translation unit):
//   TJEPA_FUZZ_TARGET=npy build/fuzz/tests/fuzz/tjepa_fuzz -max_total_time=60 corpus_copy/ tests/fuzz/corpus/npy
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "targets.hpp"

namespace {
int (*selected)(const std::uint8_t*, std::size_t) = nullptr;
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  const char* name = std::getenv("TJEPA_FUZZ_TARGET");
  for (const auto& t : tjepa::fuzz::targets)
    if (name != nullptr && std::strcmp(name, t.name) == 0) selected = t.run;
  if (selected == nullptr) {
    std::fprintf(stderr, "set TJEPA_FUZZ_TARGET to one of:");
    for (const auto& t : tjepa::fuzz::targets) std::fprintf(stderr, " %s", t.name);
    std::fprintf(stderr, "\n");
    std::exit(2);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) { return selected(data, size); }

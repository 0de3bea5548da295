// The counting allocator of allocation_counter.hpp: global operator new replaced for the whole
// program (it only forwards to malloc), and malloc interposed where no sanitizer owns it.
#if defined(__GNUC__) && !defined(__clang__)
// The replaced operator delete calls free on what the replaced operator new got from malloc.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
#include "allocation_counter.hpp"

#include <cerrno>
#include <cstdlib>
#include <new>

namespace tjepa::alloc {
std::atomic<long> allocations{0};
std::atomic<bool> counting{false};
}  // namespace tjepa::alloc

namespace {
void note_allocation() {
  if (tjepa::alloc::counting.load(std::memory_order_relaxed))
    tjepa::alloc::allocations.fetch_add(1, std::memory_order_relaxed);
}
void* allocation_checked(void* p) {
  if (!p) throw std::bad_alloc();
  return p;
}
}  // namespace

void* operator new(std::size_t n) {
  note_allocation();
  return allocation_checked(std::malloc(n ? n : 1));
}
void* operator new[](std::size_t n) {
  note_allocation();
  return allocation_checked(std::malloc(n ? n : 1));
}
void* operator new(std::size_t n, std::align_val_t a) {
  note_allocation();
  const auto al = static_cast<std::size_t>(a);
  return allocation_checked(std::aligned_alloc(al, (n + al - 1) / al * al));
}
void* operator new[](std::size_t n, std::align_val_t a) { return operator new(n, a); }
// The nothrow forms too: the standard library (e.g. std::stable_sort's temporary buffer) uses
// them, and a replaced delete must never free what a non-replaced new allocated.
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  note_allocation();
  return std::malloc(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t& t) noexcept { return operator new(n, t); }
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  note_allocation();
  const auto al = static_cast<std::size_t>(a);
  return std::aligned_alloc(al, (n + al - 1) / al * al);
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t& t) noexcept {
  return operator new(n, a, t);
}
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

#ifdef TJEPA_COUNTS_MALLOC
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void* malloc(std::size_t n) noexcept {
  note_allocation();
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  note_allocation();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) noexcept {
  note_allocation();
  return __libc_realloc(p, n);
}
void* aligned_alloc(std::size_t al, std::size_t n) noexcept {
  note_allocation();
  return __libc_memalign(al, n);
}
int posix_memalign(void** p, std::size_t al, std::size_t n) noexcept {
  note_allocation();
  *p = __libc_memalign(al, n);
  return *p ? 0 : ENOMEM;
}
}
#endif
